"""Stage 7 of the diagnosis: the :class:`Diagnosis` record, its summary and its report folder."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from momentid.core.series import json_safe
from momentid import mechanisms
from momentid.diagnosis.discovery import Discovery, plot_discovered
from momentid.diagnosis.modal_discovery import ModalDiscovery, plot_modal_discovered
from momentid.diagnosis.screening import Candidate
from momentid.diagnosis.thresholds import EXCESS, EXPLAINED

__all__ = ["Diagnosis", "summary", "write_report"]


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`~momentid.diagnosis.pipeline.diagnose` (``report.json`` is its serialised form)."""

    mechanism: str
    location: dict
    parameters: dict
    std: dict
    nrmse_before: float
    nrmse_after: float
    excess_equation: dict      # per floor: residual RMS / noise-only RMS
    excess_replay: dict        # per channel: replay NRMSE / noise-only NRMSE
    candidates: tuple[Candidate, ...]
    summary: str
    holdout: str
    parameter_pattern: dict = field(default_factory=dict)
    sensor_check: dict = field(default_factory=dict)   # a_j = zdd + q_j'': excess per floor, best fits
    selection: dict = field(default_factory=dict)      # training-run NRMSE of each re-simulated candidate
    localisation: dict = field(default_factory=dict)   # storey, runs, time windows, amplitude, bands, shape
    augmented_xml: str = ""
    curves: dict = field(default_factory=dict, repr=False)
    notes: tuple[str, ...] = ()                        # what reading the recording recovered (lost runs)
    discovered: Discovery | None = None              # the open search's force (verdict "unexplained")
    #: every named mechanism (:class:`~momentid.diagnosis.compound.Named`), primary first; empty for
    #: ``none`` and ``unexplained``
    mechanisms: tuple = ()

    def to_dict(self) -> dict:
        return {
            "mechanism": self.mechanism, "location": self.location, "parameters": self.parameters,
            "std": self.std, "nrmse_before": self.nrmse_before, "nrmse_after": self.nrmse_after,
            "summary": self.summary, "holdout": self.holdout,
            "excess_equation": self.excess_equation, "excess_replay": self.excess_replay,
            "parameter_pattern": self.parameter_pattern, "sensor_check": self.sensor_check,
            "selection": self.selection, "localisation": self.localisation,
            "candidates": [asdict(c) for c in self.candidates],
            "notes": list(self.notes),
            "discovered": self.discovered.to_dict() if self.discovered is not None else None,
            "mechanisms": [m.to_dict() for m in self.mechanisms],
        }


def summary(mech, loc, params, std, excess_eq, excess_rep, before, after, run_name, held_out, sensor_check,
            selection, where, named=(), discovered: Discovery | None = None) -> str:
    """The report's text: residuals vs. noise, where, the sensor check, the verdict, the replay, and
    the open search's discovered force.

    ``named``: every mechanism of a compound diagnosis (:class:`~momentid.diagnosis.compound.Named`),
    one sentence each when there are several.
    """
    worst = max(excess_eq, key=excess_eq.get)
    lines = ["Equation residual vs. noise: " + ", ".join(f"{k} {v:.2f}x" for k, v in excess_eq.items()) + ".",
             "Replay residual vs. noise: " + ", ".join(f"{k} {v:.2f}x" for k, v in excess_rep.items()) + "."]
    if max(excess_eq.values()) > EXCESS:
        lines.append(where)
    if sensor_check:
        verdict = "consistent" if sensor_check["consistent"] else "INCONSISTENT"
        lines.append("Sensors against each other (a = zdd + q''): " + ", ".join(
            f"{k} {v:.2f}x" for k, v in sensor_check["excess"].items()) + f" of noise ({verdict}).")
    if mech == "none":
        lines.append("No missing physics: the linear model explains the recordings to the noise level.")
    elif mech == "unexplained" and "outside_library" in selection:
        out = selection["outside_library"]
        lines.append(f"Unexplained by the library at {json.dumps(loc)}: its best model, "
                     f"{out['named'][0].replace('_', ' ')} at {json.dumps(out['named'][1])}, leaves training NRMSE "
                     f"{100 * out['training_nrmse_named']:.2f} % (noise alone {100 * out['training_nrmse_noise']:.2f} %);"
                     f" the force below, outside the library, {100 * out['training_nrmse_discovered']:.2f} %.")
    elif mech == "unexplained" and "partial" in selection:
        part = selection["partial"]
        lines.append(f"Unexplained mismatch at {json.dumps(loc)}: the best candidate, "
                     f"{part['mechanism'].replace('_', ' ')} at {json.dumps(part['location'])}, removes only "
                     f"{100 * max(selection['explained'], 0):.0f} % of the training runs' misfit above noise "
                     f"(NRMSE {100 * selection['training_nrmse_linear']:.2f} % -> "
                     f"{100 * selection['training_nrmse_augmented']:.2f} %, noise alone "
                     f"{100 * selection['training_nrmse_noise']:.2f} %); the model is left linear.")
    elif mech == "unexplained":
        lines.append(f"Unexplained mismatch at {json.dumps(loc)} (largest at {worst}); no candidate mechanism "
                     f"explains at least {int(EXPLAINED * 100)} % of it.")
    elif len(named) > 1:
        lines.append(f"{len(named)} mechanisms together, refitted jointly in one model (the primary first):")
        lines += ["  " + mechanisms.get(n.mechanism).describe(n.location, n.parameters, n.std) for n in named]
    else:
        lines.append(mechanisms.get(mech).describe(loc, params, std))
    if math.isfinite(before):
        which = f"held-out run {run_name}" if held_out else f"run {run_name}"
        lines.append(f"{which} NRMSE {100 * before:.2f} % -> {100 * after:.2f} %.")
    if discovered is not None:
        lines.append(f"{discovered.description} With it, {which} NRMSE {100 * discovered.nrmse_before:.2f} % -> "
                     f"{100 * discovered.nrmse_after:.2f} % (a data-driven model, not a named mechanism).")
    elif mech == "unexplained" and math.isfinite(before):
        lines.append("Open search: no force from the function library lowers the held-out misfit enough to report.")
    return "\n".join(lines)


def write_report(diag: Diagnosis, folder) -> Path:
    """``report.json``, ``summary.txt``, ``model_augmented.xml``, ``diagnosis.rrd`` and the PNG plots
    ``replay.png`` (recorded vs. linear vs. augmented), ``locate.png`` (where the mismatch is) and, when
    the open search found a force, ``discovered.png`` (its force against the drift or displacement)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "report.json").write_text(json.dumps(json_safe(diag.to_dict()), indent=2))
    (folder / "summary.txt").write_text(diag.summary + "\n")
    if diag.augmented_xml:
        (folder / "model_augmented.xml").write_text(diag.augmented_xml)
    if diag.curves:
        _plots(diag, folder)
        _rerun(diag, folder / "diagnosis.rrd")
    if diag.localisation:
        from momentid.diagnosis.locate import plot_localisation
        plot_localisation(diag.localisation, folder / "locate.png")
    if diag.discovered is not None:
        plot = plot_modal_discovered if isinstance(diag.discovered, ModalDiscovery) else plot_discovered
        plot(diag.discovered, folder / "discovered.png")
    return folder


def _rerun(diag: Diagnosis, path: Path) -> None:
    """Recorded, linear-model and augmented-model responses overlaid, for ``rerun diagnosis.rrd``."""
    import rerun as rr
    import rerun.blueprint as rrb

    c = diag.curves
    rec = rr.RecordingStream("momentid_diagnosis")
    views = []
    time = rr.TimeColumn("time", duration=np.asarray(c["time"], float))
    styles = {"recorded": [20, 20, 20], "linear": [31, 119, 180], "augmented": [214, 39, 40]}
    for g, unit in (("a", "m/s^2"), ("q", "m")):
        if g not in c["measured"]:
            continue
        for j in range(c["measured"][g].shape[1]):
            base = f"/{g}{j + 1}"
            for label, data in (("recorded", c["measured"]), ("linear", c["linear"]), ("augmented", c["augmented"])):
                entity = f"{base}/{label}"
                rec.log(entity, rr.SeriesLines(colors=[styles[label]], names=[f"{g}{j + 1} {label} ({unit})"]),
                        static=True)
                rec.send_columns(entity, indexes=[time], columns=rr.Scalars.columns(scalars=data[g][:, j]))
            views.append(rrb.TimeSeriesView(origin=base, name=f"{g}{j + 1} ({unit})"))
    rec.log("/report", rr.TextDocument(diag.summary.replace("\n", "\n\n"), media_type=rr.MediaType.MARKDOWN), static=True)
    layout = rrb.Horizontal(rrb.Grid(*views), rrb.TextDocumentView(origin="/report", name="diagnosis"),
                            column_shares=[3, 1])
    rec.save(str(path), default_blueprint=rrb.Blueprint(layout))
    rec.flush()


def _plots(diag: Diagnosis, folder: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    c = diag.curves
    t = c["time"]
    g = "q" if "q" in c["measured"] else "a"
    d = c["measured"][g].shape[1]
    fig, axes = plt.subplots(d, 2, figsize=(12, 2.4 * d), squeeze=False, sharex=True)
    unit = "m" if g == "q" else "m/s^2"
    for j in range(d):
        m, lin, aug = c["measured"][g][:, j], c["linear"][g][:, j], c["augmented"][g][:, j]
        ax = axes[j, 0]
        ax.plot(t, m, "k", lw=0.8, label="recorded")
        ax.plot(t, lin, "C0", lw=0.8, label="linear model")
        ax.plot(t, aug, "C3--", lw=0.8, label="augmented model")
        ax.set_ylabel(f"{g}{j + 1} ({unit})")
        ax = axes[j, 1]
        ax.plot(t, m - lin, "C0", lw=0.6, label="residual, linear")
        ax.plot(t, m - aug, "C3", lw=0.6, label="residual, augmented")
        ax.set_ylabel(f"{g}{j + 1} residual ({unit})")
    axes[0, 0].legend(fontsize=7)
    axes[0, 1].legend(fontsize=7)
    axes[-1, 0].set_xlabel("time (s)")
    axes[-1, 1].set_xlabel("time (s)")
    fig.suptitle(f"{diag.mechanism} {json.dumps(diag.location)}: held-out NRMSE "
                 f"{100 * diag.nrmse_before:.2f} % -> {100 * diag.nrmse_after:.2f} %")
    fig.tight_layout()
    fig.savefig(folder / "replay.png", dpi=90)
    plt.close(fig)
