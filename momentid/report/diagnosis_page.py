"""The report page of ``momentid diagnose -o DIR`` (:class:`~momentid.report.page.Page`).

The verdict and the physics in words first; then the held-out check (each model's NRMSE beside the
noise alone), the misfit per sensor, every named mechanism's parameters with units and standard
errors, what the diagnosis path weighed (the rig-state check and the fitted twins; the modal training
fit; the residuals against noise and the screened candidates), notes; then the held-out trial recorded
against each model with a zoom on its strongest part, the comparison, where the misfit sits, each
run's modes against its response amplitude, and the path's own figures (where the equation residual
sits, the open search's force).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from momentid.core import html
from momentid.diagnosis.added_mass.words import AddedMassEvidence
from momentid.diagnosis.modal.words import ModalEvidence
from momentid.diagnosis.twin.words import TwinEvidence
from momentid.diagnosis.summary_html import mechanism_words
from momentid.diagnosis.verdict import Verdict
from momentid.mechanisms.place import location_words
from momentid.report import figures
from momentid.report.page import Page, Provenance
from momentid.report.twin_page import OVERLAY_BINS

if TYPE_CHECKING:
    from momentid.diagnosis.result import Diagnosis

__all__ = ["diagnosis_page", "parameter_unit"]

#: Unit suffixes of the parameter names reports use (``stiffness_n_per_m``), longest first.
_SUFFIXES = (("_n_s_per_m", "N s/m"), ("_hz_per_m_s2", "Hz per m/s²"), ("_per_m_s2", "1 per m/s²"),
             ("_n_per_m", "N/m"), ("_m_s2", "m/s²"), ("_mm", "mm"), ("_hz", "Hz"), ("_kg", "kg"), ("_n", "N"),
             ("_s", "s"), ("_m", "m"))


def parameter_unit(mechanism: str, name: str) -> tuple[str, str]:
    """A parameter's name in words and its unit: from the name's suffix (``slip_drift_mm``: ``slip
    drift``, ``mm``), else the mechanism kind's declared unit, else ``1``."""
    for suffix, unit in _SUFFIXES:
        if name.endswith(suffix):
            return name[: -len(suffix)].replace("_", " "), unit
    from momentid import mechanisms
    from momentid.errors import ModelError

    try:
        declared = {p.name: p.unit for p in mechanisms.get(mechanism).params}
    except ModelError:
        declared = {}
    return name.replace("_", " "), declared.get(name) or "1"


def _value(x) -> str:
    if isinstance(x, (list, tuple, np.ndarray)):
        return ", ".join(_value(v) for v in x)
    return f"{x:.4g}" if isinstance(x, (int, float)) and not isinstance(x, bool) else str(x)


def _model_labels(diag) -> dict:
    """The curves' models in words, in order (linear first, the final model last)."""
    twin = isinstance(diag.evidence, TwinEvidence)
    named = ", ".join(sorted({mechanism_words(n.mechanism) for n in diag.mechanisms}))
    augmented = (f"{'twin' if twin else 'model'} with {named}" if named
                 else ("augmented twin (the tried physics)" if twin else "augmented model"))
    labels = {"linear": "linear twin" if twin else "linear model",
              "linear_refit": "linear twin refitted on the training trials", "augmented": augmented}
    return {key: words for key, words in labels.items() if key in diag.curves}


def _checks(diag) -> list:
    """The held-out check: ``(words, NRMSE)`` of each model the diagnosis scored."""
    labels = _model_labels(diag)
    rows = [(labels.get("linear", "linear model"), diag.nrmse_before)]
    if diag.nrmse_linear_refit is not None:
        rows.append((labels.get("linear_refit", "linear model refitted"), diag.nrmse_linear_refit))
    rows.append((labels.get("augmented", "augmented model"), diag.nrmse_after))
    if diag.nrmse_linear_own is not None:
        rows.append(("linear model fitted to the held-out trial itself", diag.nrmse_linear_own))
    reference = getattr(diag.evidence, "reference", {}) or {}
    if "nrmse" in reference:
        rows.append(("amplitude-dependent viscous damping (a reference, not an answer)", reference["nrmse"]))
    return [(w, v) for w, v in rows if v is not None and math.isfinite(v)]


def _group(diag) -> tuple[str, str]:
    measured = diag.curves["measured"]
    return ("q", "m") if "q" in measured else ("a", "m/s²")


def _per_sensor(diag) -> dict:
    """Per floor sensor, each model's held-out NRMSE, from the curves."""
    from momentid.twin.replay import nrmse

    g, _ = _group(diag)
    measured = diag.curves["measured"][g]
    out = {}
    for key, words in _model_labels(diag).items():
        for j, x in enumerate(nrmse(measured, diag.curves[key][g], axis=0)):
            out.setdefault(f"{g}{j + 1}", {})[words] = float(x)
    return out


def _mechanism_rows(diag) -> list:
    rows = []
    for n in diag.mechanisms:
        for name, value in n.parameters.items():
            words, unit = parameter_unit(n.mechanism, name)
            std = n.std.get(name) if n.std else None
            rows.append([mechanism_words(n.mechanism), location_words(n.location), words, _value(value),
                         "" if std is None else _value(std), unit])
    return rows


def _training(nrmse) -> str:
    """Training NRMSE (%) in words: one number, or per trial."""
    if isinstance(nrmse, dict):
        return ", ".join(f"{run} {100 * v:.1f}" for run, v in nrmse.items())
    return "" if nrmse is None else f"{100 * nrmse:.2f}"


def _twin_tables(page: Page, diag, evidence: TwinEvidence) -> None:
    state = evidence.state
    if state.tested:
        page.table("Rig state", html.table(
            ["trial", "off the others' trend (standard errors)", "furthest mode", "at (Hz)", "expected (Hz)",
             "one rig state"],
            [[run, f"{state.sigmas[run]:.1f}", f"mode {state.worst[run]['mode']}",
              f"{state.worst[run]['frequency_hz']:.3f}", f"{state.worst[run]['expected_hz']:.3f} ± "
              f"{state.worst[run]['std_hz']:.3f}", "no: set apart" if run in state.outliers else "yes"]
             for run in state.runs if run in state.sigmas]),
            note="Each trial's own modes against the line the other trials' modes follow against mode 1.")
    rows = []
    for key, words in (("linear_refit", "linear twin refitted"), ("augmented", _model_labels(diag).get("augmented")),
                       ("own", "linear twin of the held-out trial")):
        fit = evidence.fits.get(key) or {}
        if "damping_ratio" in fit:
            rows.append([words, ", ".join(f"{100 * z:.3f}" for z in fit["damping_ratio"]),
                         ", ".join(f"{g:.4f}" for g in fit.get("sensor_gain", [])),
                         ", ".join(f"{1e3 * t:+.2f}" for t in fit.get("sensor_offset_s", [])),
                         _training(evidence.fits.get("training_nrmse", {}).get(key))])
    if rows:
        page.table("The fitted twins", html.table(
            ["twin", "damping ratio per mode (%)", "floor sensor gains (1)", "clock offsets (ms)",
             "training NRMSE (%)"], rows, words=[4]),
            note="Fitted by re-simulation over the training trials " + ", ".join(evidence.training) + ".")
    page.lines("Trials set apart", [f"Rig state: {s}." for s in evidence.excluded])


def _modal_tables(page: Page, evidence: ModalEvidence) -> None:
    t = evidence.training
    if "frequency_hz" in t:
        page.table("The training fit", html.table(
            ["mode", "frequency (Hz)", "damping ratio (%)"],
            [[f"{i + 1}", f"{f:.4f}", f"{100 * z:.3f}"] for i, (f, z) in enumerate(zip(t["frequency_hz"],
                                                                                   t["damping_ratio"]))]),
            note=f"The linear modal model of the training runs {', '.join(t.get('runs', []))}; residual variance "
                 f"{t.get('residual_variance_factor', float('nan')):.3g} x noise.")
    page.lines("Findings", [f"Finding: {f}" for f in evidence.findings])


def _added_mass_tables(page: Page, evidence: AddedMassEvidence) -> None:
    page.table("Residuals against noise", html.table(
        ["where", "equation residual / noise", "replay residual / noise"],
        [[k, f"{evidence.excess_equation[k]:.2f}", ""] for k in evidence.excess_equation]
        + [[k, "", f"{v:.2f}"] for k, v in evidence.excess_replay.items()]),
        note="1 is the sensor noise level; the diagnosis looks for physics where the residual stands above it.")
    if evidence.candidates:
        page.table("Candidates screened", html.table(
            ["mechanism", "place", "share of the excess residual explained (%)", "parameters"],
            [[mechanism_words(c.mechanism), c.place.words, f"{100 * c.explained:.0f}",
              "; ".join(f"{k} {_value(v)}" for k, v in c.parameters.items())] for c in evidence.candidates], names=2),
            note="Each fitted on its own; the share is of the residual above noise on held-out blocks.")


def _trend_figure(page: Page, diag) -> None:
    evidence = diag.evidence
    if isinstance(evidence, TwinEvidence) and len(evidence.per_run) > 1:
        page.figure("Each trial's own modes against its response amplitude (the held-out trial hollow and red, "
                    "trials of another rig state as crosses).",
                    lambda: figures.amplitude_figure(figures.trend_points(evidence.per_run), held=diag.held_out,
                                                     set_apart=evidence.state.outliers))
    elif isinstance(evidence, ModalEvidence) and evidence.trend is not None:
        trend = evidence.trend
        page.figure("Each training run's modes against its response amplitude, with the amplitude model's lines.",
                    lambda: figures.amplitude_figure(figures.trend_points(trend.runs), lines={
                        "frequency": trend.frequency_coef, "damping_ratio": trend.damping_coef}))


def diagnosis_page(diag: Diagnosis, made: Provenance, source: str = "") -> Page:
    """The page of ``diag`` (a :class:`~momentid.diagnosis.result.Diagnosis` of the recording ``source``;
    module docstring)."""
    from momentid.twin.plots import overlay_figure

    evidence = diag.evidence
    page = Page(f"Diagnosis of {Path(source).name if source else 'a recording'}",
                f"{source}: held-out {diag.held_out}; what physics the linear model lacks, and where.", made)
    page.answer(diag._repr_html_())
    checks = _checks(diag)
    page.table("The held-out check", html.table(
        ["model", "held-out NRMSE (%)", "x the noise alone"],
        [[w, f"{100 * v:.2f}", f"{v / diag.noise_nrmse:.1f}" if diag.noise_nrmse > 0 else ""] for w, v in checks]
        + ([["sensor noise alone", f"{100 * diag.noise_nrmse:.2f}", "1.0"]] if math.isfinite(diag.noise_nrmse)
           else [])),
        note="Floor-acceleration (or displacement) NRMSE of the held-out run after its quiet lead-in.")
    if diag.curves:
        page.section("Per sensor", lambda: html.table(
            ["sensor", *_model_labels(diag).values()],
            [[html.channel_words(s), *(f"{100 * v:.2f}" for v in row.values())]
             for s, row in _per_sensor(diag).items()],
            caption="Held-out NRMSE (%) of each floor sensor"))
    rows = _mechanism_rows(diag)
    if rows:
        page.table("Named physics", html.table(["mechanism", "place", "parameter", "value", "standard error", "unit"],
                                               rows, names=3))
    if isinstance(evidence, TwinEvidence):
        _twin_tables(page, diag, evidence)
    elif isinstance(evidence, ModalEvidence):
        _modal_tables(page, evidence)
    elif isinstance(evidence, AddedMassEvidence):
        _added_mass_tables(page, evidence)
    page.lines("Notes", [f"note: {n}" for n in diag.notes])
    if diag.curves:
        g, unit = _group(diag)
        c = diag.curves
        colours = {"linear": "tab:blue", "linear_refit": "tab:purple", "augmented": "tab:red"}
        models = {words: (c[key][g], colours[key]) for key, words in _model_labels(diag).items()}
        page.figure(f"Held-out {diag.held_out}: recorded and replayed by each model (left: the whole run after its "
                    f"quiet lead-in; right: the seconds around its largest response).",
                    lambda: overlay_figure(np.asarray(c["time"]), c["measured"][g], models, 0, unit=unit,
                                           label="floor {j} sensor" if g == "a" else "floor {j} displacement",
                                           title=f"held-out {diag.held_out}: recorded and replayed",
                                           bins=OVERLAY_BINS))
        page.figure("The held-out check: each model's NRMSE, the sensor noise alone dashed.",
                    lambda: figures.comparison_figure(checks, diag.noise_nrmse, diag.held_out))
        page.figure("Where the held-out misfit sits: per sensor, and the spectrum of what the final model leaves.",
                    lambda: figures.mismatch_figure(
                        np.asarray(c["time"]), c["measured"][g],
                        {w: c[k][g] for k, w in _model_labels(diag).items()}, _per_sensor(diag),
                        band=(diag.location or {}).get("band_hz") if diag.verdict is not Verdict.NONE else None,
                        unit=unit))
    _trend_figure(page, diag)
    if isinstance(evidence, AddedMassEvidence):
        from momentid.diagnosis.added_mass.locate import localisation_figure
        page.figure("Where the equation residual stands above noise: by storey, run, time and drift amplitude.",
                    lambda: localisation_figure(evidence.localisation.to_dict()))
    if diag.discovered is not None:
        from momentid.diagnosis.added_mass.open_search import discovered_figure
        from momentid.diagnosis.modal.open_search import ModalDiscovery, modal_discovered_figure
        draw = modal_discovered_figure if isinstance(diag.discovered, ModalDiscovery) else discovered_figure
        page.figure("The open search's force, from the data and from the law it found (a data-driven model, not a "
                    "named mechanism).", lambda: draw(diag.discovered))
    return page
