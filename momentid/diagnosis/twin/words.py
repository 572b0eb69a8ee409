"""What a twin diagnosis (:mod:`~momentid.diagnosis.twin.path`) shows beside its verdict, says and
draws: its evidence, the summary in words and the replay plot (:func:`momentid.diagnosis.report.write_report`
writes them with ``twin.xml`` and ``model_augmented.xml``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from momentid.core.series import channel_unit
from momentid.diagnosis.result import Diagnosis, Evidence
from momentid.diagnosis.thresholds import EXCESS, EXPLAINED, LINEAR_ROOM, removed_share
from momentid.diagnosis.verdict import Verdict
from momentid.mechanisms import registry

if TYPE_CHECKING:
    from momentid.estimation.rig_state import StateCheck

__all__ = ["TwinEvidence", "summary", "plot_replay"]

@dataclass(frozen=True)
class TwinEvidence(Evidence):
    """What a diagnosis of accelerometer-only recordings on the rig's MuJoCo twin shows beside its
    verdict (:func:`momentid.diagnosis.twin.path.diagnose_twin`).

    Attributes
    ----------
    training : tuple of str
        The training trials (of the held-out trial's rig state unless it was named from another).
    state : StateCheck
        Which trials belong to one rig state (:mod:`momentid.estimation.rig_state`).
    excluded : tuple of str
        One sentence per trial left out as another rig state.
    channel_nrmse : dict
        Per floor sensor: held-out NRMSE of the linear twin, the linear refit and the augmented twin.
    fits : dict
        The fitted twins (linear refit, augmented, the held-out trial's own) and their training NRMSE.
    reference : dict
        Amplitude-dependent viscous damping: its held-out NRMSE and slopes (a figure, not an answer).
    twin_xml : str
        The linear twin's MJCF (``twin.xml``; loads in stock MuJoCo).
    seconds : dict
        Wall-clock seconds per stage, and the CPU seconds of the whole.
    fold : Fold
        The three fitted twins and their NRMSE (:class:`~momentid.diagnosis.twin.folds.Fold`).
    per_run : tuple of ModalIdentification
        Each trial's own modal identification (the rig-state check's and the amplitude reference's
        points), in recording order.
    """

    training: tuple[str, ...]
    state: StateCheck
    excluded: tuple[str, ...]
    channel_nrmse: dict
    fits: dict
    reference: dict
    twin_xml: str
    seconds: dict = field(default_factory=dict)
    fold: object = field(default=None, repr=False, compare=False)
    per_run: tuple = field(default=(), repr=False, compare=False)

    def to_dict(self) -> dict:
        """The twin path's entries of ``report.json``: trials, rig state, exclusions, channel NRMSE, fits, seconds."""
        return {"training": list(self.training), "reference": self.reference, "rig_state": self.state.to_dict(),
                "excluded": list(self.excluded), "channel_nrmse": self.channel_nrmse, "fits": self.fits,
                "seconds": self.seconds, "path": "twin (no added mass)"}

    def words(self, diag: Diagnosis) -> str:
        """The report's text: :func:`summary` of ``diag``."""
        return summary(diag)

    def plot_replay(self, diag: Diagnosis, path: Path) -> None:
        """``replay.png``: the held-out trial recorded and as the twins replay it."""
        plot_replay(diag, path)

    def models(self) -> dict[str, str]:
        """``twin.xml``: the linear twin's MJCF."""
        return {"twin.xml": self.twin_xml}


_ROWS = (("nrmse_before", "linear twin (`momentid twin` on the training trials)"),
         ("nrmse_linear_refit", "linear twin refitted to the training trials by re-simulation"),
         ("nrmse_after", "twin with the physics the training trials chose, fitted the same way"),
         ("nrmse_linear_own", "linear twin fitted to the held-out trial itself"),
         ("noise_nrmse", "sensor noise alone"))


def summary(diag: Diagnosis) -> str:
    """The report's lines (places in words, never JSON)."""
    evidence = diag.evidence
    lines = [f"Held-out trial {diag.held_out} (training trials: {', '.join(evidence.training)}); floor-acceleration "
             f"NRMSE after its quiet lead-in:"]
    for key, words in _ROWS:
        lines.append(f"  {100 * getattr(diag, key):7.2f} %  {words}")
    ref = evidence.reference
    if "nrmse" in ref:
        lines.append(f"  {100 * ref['nrmse']:7.2f} %  amplitude-dependent viscous damping (a reference, not an answer: "
                     f"modes set by the held-out trial's own amplitude, {ref['held_out_amplitude_m_s2']:.3g} m/s^2)")
    refit, after, noise = diag.nrmse_linear_refit, diag.nrmse_after, diag.noise_nrmse
    share = removed_share(refit, after, noise)
    lines += _selection_lines(diag)
    physics = _physics_words(diag)
    if diag.verdict is Verdict.NONE and min(diag.nrmse_before, refit) > EXCESS * noise:
        lines.append(f"No missing physics: the rig is linear within its trials. The linear refit's held-out NRMSE is "
                     f"{refit / diag.nrmse_linear_own:.2f} x that of a linear twin fitted to the trial itself (within "
                     f"{LINEAR_ROOM:g} x: no room for amplitude-dependent physics), and no candidate predicts a "
                     f"held-out training trial better than the linear twin.")
    elif diag.verdict is Verdict.NONE:
        lines.append(f"No missing physics: a linear twin explains the held-out trial to within {EXCESS:g} x the noise.")
    elif diag.verdict is Verdict.MECHANISM:
        lines += _mechanism_lines(diag, share)
    elif diag.verdict is Verdict.ANOTHER_RIG_STATE:
        lines.append(f"Verdict: the held-out trial is from another rig state, so its misfit is not evidence of "
                     f"missing physics (largest at the {diag.location['words']}); hold out a trial recorded with the "
                     f"others to test the physics.")
    else:
        lines.append(f"Verdict: unexplained mismatch at the {diag.location['words']}: {physics} removes "
                     f"{100 * share:.0f} % of the linear refit's held-out misfit above noise ({100 * EXPLAINED:.0f} % "
                     f"needed).")
        lines += _motion_lines(diag.evidence.fold.augmented.model)
    lines += [f"Rig state: {s}." for s in evidence.excluded]
    if evidence.state.tested and not evidence.excluded:
        lines.append(f"Rig state: every trial's modes lie on the others' trend (within {evidence.state.spread():.1f} "
                     f"standard errors): one rig state.")
    lines += [f"note: {n}" for n in diag.notes if "twin" in n]
    return "\n".join(lines)


def _physics_words(diag: Diagnosis) -> str:
    """The chosen physics in words ("joint friction at every storey, each its own"; "no physics")."""
    fold = diag.evidence.fold
    chosen = getattr(fold, "chosen", None)
    return chosen.words(diag.evidence.fold.linear.model.storeys) if chosen is not None else "joint friction"


def _selection_lines(diag: Diagnosis) -> list[str]:
    """How the training trials alone chose the physics: each candidate's NRMSE on the training trial held out
    inside the fit, as a multiple of the linear refit's there."""
    fold = diag.evidence.fold
    table = getattr(fold, "selection", None) or {}
    if not table:
        return []
    d = fold.linear.model.storeys
    from momentid.diagnosis.twin.folds import candidates

    words = {c.name: c.words(d) for c in candidates(d) + candidates(d, motion=True)}
    ranked = sorted(table, key=lambda n: table[n]["inner_nrmse"])
    parts = "; ".join(f"{words.get(n, n)} {table[n]['ratio_to_linear']:.2f} x" for n in ranked if n != "linear")
    return [f"Physics chosen on the training trials alone (each candidate fitted on the others, NRMSE on "
            f"{fold.inner_held_out} as a multiple of the linear refit's): {parts}; chosen: {_physics_words(diag)}."]


def _mechanism_lines(diag: Diagnosis, share: float) -> list[str]:
    """The verdict's lines when the augmented twin explains the held-out misfit: each joint by its kind's
    own sentence at its place, the stiffness it loses to slip, a WARNING on what is left."""
    refit, after, noise = diag.nrmse_linear_refit, diag.nrmse_after, diag.noise_nrmse
    lines = [f"Verdict: {_physics_words(diag)}: it removes {100 * share:.0f} % of "
             f"the linear refit's held-out misfit above noise ({100 * EXPLAINED:.0f} % needed); "
             f"{after / refit:.2f} x the linear refit, {after / diag.nrmse_linear_own:.2f} x the trial's own "
             f"linear fit."]
    for record, named in zip(diag.evidence.fold.augmented.model.friction, diag.mechanisms):
        kind = registry.get(record.type)
        lost = named.parameters.get("stiffness_lost_at_1mm_n_per_m")
        lines.append("  " + kind.describe(kind.place(record.location), dict(record.parameters), {})
                     + ("" if lost is None else
                        f" Stiffness lost to slip: {lost:.3g} N/m at 1 mm, "
                        f"{named.parameters['stiffness_lost_at_5mm_n_per_m']:.3g} N/m at 5 mm of drift."))
    lines += _motion_lines(diag.evidence.fold.augmented.model)
    if after > EXCESS * noise:
        lines.append(f"WARNING: {_physics_words(diag)} explains only part of the mismatch: the held-out NRMSE is still "
                     f"{100 * after:.2f} % ({after / noise:.1f} x noise); the rest is largest at the "
                     f"{diag.location['words']}.")
    return lines


def _motion_lines(model) -> list[str]:
    """The gains by which the table's other motions drive the chosen twin, in words (none: no lines)."""
    if not model.table_motion:
        return []
    unit = {c: channel_unit(c) for c in model.table_motion}
    gains = ", ".join(f"{c} {g:+.3g}" + ("" if unit[c] == "m/s^2" else " m/s per rad/s")
                      for c, g in zip(model.table_motion, model.table_gains))
    return [f"  The table's other motions (its sway and rocking under the structure) drive the twin beside its "
            f"shaking axis, gains into the table acceleration the twin feels: {gains}."]


def plot_replay(diag: Diagnosis, path: Path) -> Path:
    """Per floor sensor, the held-out trial recorded and as the three twins replay it."""
    from momentid.twin.plots import pyplot

    plt = pyplot()
    c = diag.curves
    t, d = c["time"], c["measured"]["a"].shape[1]
    fig, axes = plt.subplots(d, 1, figsize=(12, 2.4 * d), sharex=True, squeeze=False)
    for j, ax in enumerate(axes[:, 0]):
        ax.plot(t, c["measured"]["a"][:, j], "k", lw=0.6, label="recorded")
        ax.plot(t, c["linear_refit"]["a"][:, j], color="tab:blue", lw=0.5, alpha=0.7,
                label=f"linear twin refitted ({100 * diag.evidence.channel_nrmse[f'a{j + 1}']['linear_refit']:.1f} %)")
        ax.plot(t, c["augmented"]["a"][:, j], color="tab:red", lw=0.5, alpha=0.8,
                label=f"twin with the chosen physics ({100 * diag.evidence.channel_nrmse[f'a{j + 1}']['after']:.1f} %)")
        ax.set_ylabel(f"floor-{j + 1} sensor\n(m/s^2)", fontsize=8)
        ax.legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("time (s)")
    where = f"\nmisfit left largest at the {diag.location['words']}" if diag.location else ""
    fig.suptitle(f"Held-out trial {diag.held_out}: {diag.mechanism.replace('_', ' ')}; NRMSE linear twin "
                 f"{100 * diag.nrmse_before:.1f} %, refitted {100 * diag.nrmse_linear_refit:.1f} %, "
                 f"with the chosen physics {100 * diag.nrmse_after:.1f} %{where}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path
