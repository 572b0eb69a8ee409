"""The viewer's text panels as markdown: the identified parameters (against the analytic ones when
the recording holds a nominal structure), the modes, and the experiment with its notes."""

from __future__ import annotations

import math

from momentid.report.scene import Scene, is_modal

__all__ = ["parameters_markdown", "modes_markdown", "experiment_markdown"]


def _fmt(x: float) -> str:
    return f"{x:.6g}" if math.isfinite(x) else "n/a"


def parameters_markdown(scene: Scene) -> str:
    """The identification panel: the estimator, its problem size and the parameters (identified
    against analytic, with relative errors, or alone); the modal table of a fit without added mass."""
    r = scene.result
    if r is None:
        return "# Identification\n\n" + "\n\n".join(n for n in scene.notes if n.startswith("not identified"))
    if is_modal(r):  # no added mass: modes, and K, C only when the lab states its masses
        return f"# Identification of {scene.experiment.name}\n\n```\n{r.table()}\n```"
    lines = [f"# Identification of {scene.experiment.name}", "",
             f"estimator **{r.estimator}**, runs {', '.join(r.runs)}: {r.n_equations} equations, "
             f"{r.n_unknowns} unknowns, rank {r.rank}, condition {r.condition:.3g}, residual RMS "
             f"{r.residual_rms:.3g} N, Rayleigh misfit of C {r.damping_misfit:.2e}", ""]
    c = scene.comparison
    if c is None:
        lines += ["| parameter | identified |", "|---|---:|"]
        lines += [f"| {k} | {_fmt(float(v))} |" for k, v in (("mu (1/s)", r.mu), ("kappa (s)", r.kappa))]
        lines += [f"| {m}[{i + 1},{j + 1}] | {_fmt(float(getattr(r, m)[i, j]))} |"
                  for m in "MCK" for i in range(r.storeys) for j in range(i, r.storeys)]
        return "\n".join(lines)
    worst = max(c.entries, key=lambda e: e.rel_error)
    lines += ["| # | parameter | unit | identified | analytic | rel. error |", "|---:|---|---|---:|---:|---:|"]
    lines += [f"| {k + 1} | {e.name} | {e.unit} | {_fmt(e.identified)} | {_fmt(e.analytic)} | {e.rel_error:.2e} |"
              for k, e in enumerate(c.entries)]
    lines += ["", f"largest relative error: **{worst.rel_error:.2e}** ({worst.name})"]
    return "\n".join(lines)


def modes_markdown(scene: Scene) -> str:
    """The modes panel: natural frequencies (Hz) and damping ratios, identified and analytic (n/a
    without a nominal structure)."""
    ident = scene.result.modes()
    an = scene.comparison.analytic_modes if scene.comparison is not None else None
    lines = ["| mode | f identified (Hz) | f analytic (Hz) | zeta identified | zeta analytic |",
             "|---:|---:|---:|---:|---:|"]
    for k in range(len(ident.frequency)):
        fa, za = (an.frequency[k], an.damping_ratio[k]) if an is not None else (math.nan, math.nan)
        lines.append(f"| {k + 1} | {ident.frequency[k]:.5f} | {fa:.5f} | {ident.damping_ratio[k]:.5f} | {za:.5f} |")
    return "\n".join(lines).replace("nan", "n/a")


def experiment_markdown(scene: Scene) -> str:
    """The experiment panel: scenario, runs (added mass, samples, duration), the exaggeration and
    every note."""
    e = scene.experiment
    s = e.scenario
    lines = [f"# {e.name}", "", str(s.get("description", "")), "",
             f"recording `{e.source}`; {len(e.runs)} runs, {e.storeys} storeys",
             "", f"**3D views: every displacement is drawn x{scene.exaggeration:g}** (table and floors); "
             "the arrow in front of the table is the true displacement of its label, drawn at that scale.", "",
             "| run | added mass per floor (kg) | samples | duration (s) |", "|---|---|---:|---:|"]
    lines += [f"| {r.name} | {', '.join(f'{m:g}' for m in r.added_mass)} | {r.n_samples} | "
              f"{r.time[-1] - r.time[0]:g} |" for r in e.runs]
    notes = list(e.notes) + scene.notes
    if notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in notes]
    return "\n".join(lines)
