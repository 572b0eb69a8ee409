"""The report page of ``momentid identify -o DIR`` (:class:`~momentid.report.page.Page`).

- a **modal identification** (runs without added mass): the modes with standard errors and which
  damping ratios are not answers; K and C (or M^-1 K, M^-1 C) with standard errors, the sensors'
  gains and clock offsets per run, the fit, notes; the mode shapes and the transfer functions,
  recorded and identified;
- one **fit per run** (``--per-run``): each run's mode 1 against its response amplitude, the trend;
  each run's modes and warnings; the trend figure and the recorded transfer functions;
- an **added-mass identification**: modes, Rayleigh coefficients, M, C, K with standard errors, the
  comparison with the recording's analytic model when it has one; the transfer functions and shapes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from momentid.core import html
from momentid.core.html import pm
from momentid.report import figures
from momentid.report.page import Page, Provenance

if TYPE_CHECKING:
    from momentid.core.series import Experiment
    from momentid.estimation.comparison import Comparison
    from momentid.estimation.identified import Identification
    from momentid.estimation.scaled import AmplitudeTrend, ModalIdentification

__all__ = ["identification_page"]


def _runs_table(result) -> str:
    d = result.storeys
    rows = []
    for r, name in enumerate(result.runs):
        rows.append([name, f"{result.amplitude[r]:.3g}",
                     *(pm(result.sensor_gain[r, j], result.sensor_gain_std[r, j]) for j in range(d)),
                     *(pm(1e3 * result.sensor_offset[r, j], 1e3 * result.sensor_offset_std[r, j], 2) for j in range(d)),
                     result.noise[r] if r < len(result.noise) else ""])
    return html.table(["run", "RMS response (m/s²)", *(f"floor {j + 1} sensor gain (1)" for j in range(d)),
                       *(f"floor {j + 1} clock offset (ms)" for j in range(d)), "noise level from"],
                      rows, caption="Floor sensors against the table sensor, per run (± one standard error)",
                      words=[2 * d + 2])


def _modal_tables(page: Page, result) -> None:
    if result.K is not None:
        page.table("Stiffness and damping", html.matrix_table(result.K, result.K_std, caption="K (N/m)")
                   + html.matrix_table(result.C, result.C_std, caption="C (N s/m)"),
                   note=f"From the stated floor masses {', '.join(f'{m:g}' for m in result.masses)} kg and the "
                        f"identified modes (± one standard error).")
    else:
        page.table("Stiffness and damping over mass",
                   html.matrix_table(result.stiffness_over_mass, result.stiffness_over_mass_std, caption="M⁻¹K (1/s²)")
                   + html.matrix_table(result.damping_over_mass, result.damping_over_mass_std, caption="M⁻¹C (1/s)"),
                   note="No floor masses stated: mass-normalised results (± one standard error).")
    page.table("Sensors", _runs_table(result))
    page.table("The fit", html.table(["quantity", "value"], [
        ["residual RMS (1: the model explains the data to the noise level)", f"{result.residual_rms:.3g} x noise"],
        ["fitted band", f"0-{result.f_max:.3g} Hz"], ["model evaluations", f"{result.nfev}"],
        ["estimator", result.estimator]]))
    page.lines("Notes", [f"note: {n}" for n in result.notes])


def _modal_figures(page: Page, result, experiment) -> None:
    from momentid.twin.parameters import from_identification
    from momentid.twin.plots import transfer_figure

    page.figure("Mode shapes: each floor sensor's reading, 1 at the top floor.",
                lambda: figures.shapes_figure(result.shapes, result.frequency, result.damping_ratio))
    top = max([*result.frequency, *(m.frequency for m in result.extra_modes)])
    page.figure("Table-to-floor transfer functions: each run's H1 estimate where the coherence reaches 0.8, and the "
                "identified model's (with the runs' mean sensor gains and clock offsets).",
                lambda: transfer_figure(from_identification(result, experiment), experiment, result.runs, top,
                                        model="identified model",
                                        title="table-to-floor transfer functions: recorded (coherence >= {c:g}) "
                                              "and identified"))


def _added_mass(page: Page, result, experiment, comparison) -> None:
    from momentid.twin.parameters import from_identification
    from momentid.twin.plots import transfer_figure

    page.answer(result._repr_html_())
    std = result.std() or {}
    page.table("Mass, damping and stiffness", "".join(
        html.matrix_table(getattr(result, name), std.get(name), caption=f"{name} ({unit}, ± one standard error)")
        for name, unit in (("M", "kg"), ("C", "N s/m"), ("K", "N/m"))))
    if comparison is not None:
        page.table("Against the recording's analytic model", html.table(
            ["parameter", "unit", "identified", "analytic", "relative error", "z-score"],
            [[e.name, e.unit, f"{e.identified:.5g}", f"{e.analytic:.5g}", f"{e.rel_error:.2e}",
              "" if e.z_score is None else f"{e.z_score:+.2f}"] for e in comparison.entries], names=2))
    page.table("The fit", html.table(["quantity", "value"], [
        ["equations x unknowns", f"{result.n_equations} x {result.n_unknowns} (rank {result.rank})"],
        ["condition number", f"{result.condition:.3g}"], ["residual RMS", f"{result.residual_rms:.3g}"]]))
    page.lines("Notes", [f"note: {n}" for n in result.notes])
    modes = result.modes()
    page.figure("Mode shapes of the identified M, C, K (mass-normalised).",
                lambda: figures.shapes_figure(modes.shapes, modes.frequency, modes.damping_ratio))
    if all(r.has("zdd") and r.has("a1") for r in experiment.runs):
        page.figure("Table-to-floor transfer functions: each run's H1 estimate where the coherence reaches 0.8, "
                    "and the identified M, C, K's.",
                    lambda: transfer_figure(from_identification(result, experiment), experiment, result.runs,
                                            float(np.max(modes.frequency)), model="identified M, C, K",
                                            title="table-to-floor transfer functions: recorded (coherence >= "
                                                  "{c:g}) and identified"))


def identification_page(result: Identification | ModalIdentification | tuple[ModalIdentification, ...],
                        experiment: Experiment, made: Provenance, *,
                        comparison: Comparison | None = None, trend: AmplitudeTrend | None = None) -> Page:
    """The page of an identification of ``experiment`` (module docstring).

    Parameters
    ----------
    result : ModalIdentification, Identification, or a tuple of ModalIdentification (one per run)
    experiment : Experiment
    made : Provenance
    comparison : Comparison, optional
        Against the recording's analytic model (added mass).
    trend : AmplitudeTrend, optional
        Of the per-run fits.

    Returns
    -------
    Page
    """
    from momentid.estimation.scaled import ModalIdentification

    results = result if isinstance(result, tuple) else None
    if results is not None and len(results) == 1:
        result, results = results[0], None
    runs = [r.runs[0] for r in results] if results is not None else list(result.runs)
    page = Page(f"Identification of {experiment.name}",
                f"{experiment.source}: {html.count(experiment.storeys, 'storey')}, {html.count(len(runs), 'run')} "
                f"({', '.join(runs)}).", made)
    if results is not None:
        if trend is not None:
            page.answer(trend._repr_html_())
        for r in results:
            page.section(f"Run {r.runs[0]}", lambda r=r: r._repr_html_())
        if trend is not None:
            page.figure("Each run's modes against its response amplitude: a linear rig shows none.",
                        lambda: figures.amplitude_figure(figures.trend_points(trend.results)))
        from momentid.twin.plots import transfer_figure
        top = max(float(np.max(r.frequency)) for r in results)
        page.figure("Table-to-floor transfer functions: each run's H1 estimate where the coherence reaches 0.8.",
                    lambda: transfer_figure(None, experiment, runs, top,
                                            title="table-to-floor transfer functions: recorded (coherence >= {c:g})"))
        return page
    if isinstance(result, ModalIdentification):
        page.answer(result._repr_html_())
        _modal_tables(page, result)
        _modal_figures(page, result, experiment)
    else:
        _added_mass(page, result, experiment, comparison)
    return page
