"""The answer of an identification in HTML: a notebook's ``_repr_html_`` and the report page's first
section (:mod:`momentid.report`), the same words in both.

- :func:`modal_html`: a :class:`~momentid.estimation.scaled.ModalIdentification` (runs without added
  mass): its modes with standard errors, which damping ratios are not answers, its warnings;
- :func:`identification_html`: an :class:`~momentid.estimation.identified.Identification` (added
  mass): its modes, the Rayleigh coefficients with standard errors, its warnings;
- :func:`trend_html`: an :class:`~momentid.estimation.scaled.AmplitudeTrend` (one fit per run).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from momentid.core import html
from momentid.core.html import REFUSED, pm, percent_pm

__all__ = ["modal_html", "identification_html", "trend_html", "modal_headline", "modes_table", "refused_modes"]


def refused_modes(result: Any) -> list[int]:
    """The (1-based) modes whose damping ratio is not an answer (none for a result that does not say)."""
    answer = getattr(result, "damping_is_answer", None)
    return [] if answer is None else [i + 1 for i, a in enumerate(answer) if not a]


def _runs(runs) -> str:
    return f"{html.count(len(runs), 'run')} ({', '.join(runs)})"


def modal_headline(result: Any) -> str:
    """One sentence of a :class:`~momentid.estimation.scaled.ModalIdentification`: how many modes, from which
    runs, which damping ratios are not answers."""
    d = result.storeys
    scale = ("K and C from the stated floor masses" if result.K is not None
             else "mass-normalised (no floor masses stated)")
    words = f"{html.count(d, 'mode')} of {_runs(result.runs)} without added mass; {scale}"
    refused = refused_modes(result)
    if refused:
        words += (f"; the damping ratio of mode{'s' if len(refused) > 1 else ''} "
                  f"{', '.join(map(str, refused))} is {REFUSED} (see the warnings)")
    return words + "."


def modes_table(result: Any) -> str:
    """The modes of a :class:`~momentid.estimation.scaled.ModalIdentification` as an HTML table: frequency and
    damping ratio with standard errors, the subspace estimate, whether the damping ratio is an answer, the
    shape."""
    d = result.storeys
    independent = (np.full(d, np.nan) if result.damping_ratio_subspace is None
                   else np.asarray(result.damping_ratio_subspace, float))
    answer = np.ones(d, bool) if result.damping_is_answer is None else np.asarray(result.damping_is_answer)
    rows = []
    for i in range(d):
        source = result.damping[i].source if result.damping else "linear fit"
        z = (percent_pm(result.damping_ratio[i], result.damping_ratio_std[i])
             if np.isfinite(result.damping_ratio_std[i]) else "–")
        f = (pm(result.frequency[i], result.frequency_std[i]) if result.frequency_answered(i)
             else html.Raw(f'<strong class="refused">{REFUSED}</strong> (see the warnings)'))
        rows.append([f"{i + 1}", f, z, source,
                     f"{100 * result.linear_damping_ratio[i]:.3f}",
                     "none stable" if np.isnan(independent[i]) else f"{100 * independent[i]:.3f}",
                     html.Raw('<span class="answer">answer</span>') if answer[i]
                     else html.Raw(f'<strong class="refused">{REFUSED}</strong>'),
                     " ".join(f"{x:+.3f}" for x in result.shapes[:, i])])
    return html.table(["mode", "frequency (Hz)", "damping at small amplitude (%)", "from",
                       "equivalent linear damping (%)", "subspace estimate (%)", "damping",
                       "shape (floor 1 … top)"], rows, caption="Modes (± one standard error)", words=[3])


def modal_html(result: Any) -> str:
    """The answer of a :class:`~momentid.estimation.scaled.ModalIdentification` (module docstring)."""
    body = modes_table(result)
    if result.extra_modes:
        body += html.table(["", "frequency (Hz)", "damping ratio (%)", "seen by"],
                           [["extra", pm(m.frequency, m.frequency_std),
                             percent_pm(m.damping_ratio, m.damping_ratio_std),
                             ", ".join(map(html.channel_words, m.seen_by)) or "no sensor beyond 3 standard errors"]
                            for m in result.extra_modes],
                           caption=f"Resonances beyond the {html.count(result.storeys, 'storey mode')} "
                                   f"(fitted so that they do not distort them)", words=[3])
    return html.summary(modal_headline(result), body + html.warnings_list(result.warnings))


def identification_html(result: Any) -> str:
    """The answer of an :class:`~momentid.estimation.identified.Identification` (module docstring)."""
    modes = result.modes()
    std = result.std()
    headline = (f"M, C and K of {_runs(result.runs)} with added mass ({result.estimator}, {result.mass} mass "
                f"matrix).")
    body = html.table(["mode", "frequency (Hz)", "damping ratio (%)"],
                      [[f"{i + 1}", f"{f:.4f}", f"{100 * z:.3f}"]
                       for i, (f, z) in enumerate(zip(modes.frequency, modes.damping_ratio))],
                      caption="Modes of the identified M, C, K")
    body += html.table(["coefficient", "value", "unit"],
                       [["mass-proportional damping mu", pm(result.mu, std and std["mu"], 5), "1/s"],
                        ["stiffness-proportional damping kappa", f"{result.kappa:.4g}" if std is None else
                         f"{result.kappa:.4g} ± {std['kappa']:.2g}", "s"],
                        ["damping misfit of C = mu M + kappa K", f"{result.damping_misfit:.3g}", "1"]],
                       caption="Rayleigh damping (± one standard error)")
    return html.summary(headline, body + html.warnings_list(result.warnings))


def trend_html(trend: Any) -> str:
    """The answer of an :class:`~momentid.estimation.scaled.AmplitudeTrend`: each run's mode 1 against its
    response amplitude, and the trend's verdict."""
    rows = [[r.runs[0], f"{r.amplitude[0]:.3g}",
             pm(r.frequency[0], r.frequency_std[0]) if r.frequency_answered(0) else f"{REFUSED} (see the warnings)",
             percent_pm(r.damping_ratio[0], r.damping_ratio_std[0]) if np.isfinite(r.damping_ratio_std[0]) else "–",
             REFUSED if refused_modes(r)[:1] == [1] else "answer", f"{100 * r.linear_damping_ratio[0]:.3f}"]
            for r in trend.results]
    body = html.table(["run", "RMS response (m/s²)", "mode-1 frequency (Hz)", "mode-1 damping at small amplitude (%)",
                       "damping", "equivalent linear damping (%)"],
                      rows, caption="One fit per run, by response amplitude (± one standard error)")
    body += (f"<p>Trend: frequency {trend.frequency_slope:+.3g} ± {trend.frequency_slope_std:.2g} Hz per m/s², "
             f"equivalent linear damping ratio {100 * trend.damping_slope:+.3g} ± {100 * trend.damping_slope_std:.2g} "
             f"% per m/s².</p>\n")
    for r in trend.results:
        body += html.warnings_list(r.warnings, r.runs[0])
    return html.summary(f"Mode 1 over {len(trend.results)} runs: {trend.verdict()}.", body)
