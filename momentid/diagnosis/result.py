"""The result of a diagnosis, one type for every kind of recording.

:class:`Diagnosis` holds what every diagnosis reports, whatever the rig model behind it (the report
contract, ``report.json`` and ``--json``):

- the **verdict** (:class:`~momentid.diagnosis.verdict.Verdict`) and, when it names physics, every
  named mechanism in the lab's terms (``mechanisms``, the primary one first, also as ``mechanism``,
  ``location``, ``parameters``, ``std``);
- the **held-out check**: the run held out (``held_out``), its NRMSE through the linear model
  (``nrmse_before``) and the augmented one (``nrmse_after``), what sensor noise alone leaves
  (``noise_nrmse``), and, where the path computes them, the linear model refitted on the training
  runs the way the augmented one was (``nrmse_linear_refit``) and a linear model fitted to the held-out
  run itself (``nrmse_linear_own``: the best a model without the missing physics can do on it);
- the open search's law (``discovered``), the augmented MJCF, the curves of the held-out run, and
  what reading the recording recovered (``notes``);
- the **evidence** of the path that produced it: :class:`AddedMassEvidence` (a rig identified with
  added masses: residuals, screening, selection, localisation) or :class:`ModalEvidence`
  (accelerometers only: the modal model's per-channel misfit, its training fits, the amplitude
  model) or :class:`TwinEvidence` (accelerometers only, on the rig's calibrated MuJoCo twin: the
  rig-state check, the training trials, the fitted twins, the reference figure, ``twin.xml``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Union

from momentid.diagnosis.verdict import Named, Verdict

if TYPE_CHECKING:
    from momentid.diagnosis.discovery import Discovery
    from momentid.diagnosis.locate import Localisation
    from momentid.diagnosis.modal_check import AmplitudeModel
    from momentid.diagnosis.modal_discovery import ModalDiscovery
    from momentid.diagnosis.rig_state import StateCheck
    from momentid.diagnosis.screening import Candidate
    from momentid.diagnosis.selection import Selection

__all__ = ["Diagnosis", "AddedMassEvidence", "ModalEvidence", "TwinEvidence", "Evidence"]


@dataclass(frozen=True)
class AddedMassEvidence:
    """What a diagnosis on an identified M, C, K (runs with added mass) shows beside its verdict.

    Attributes
    ----------
    run : str
        The run the before/after replay is shown on.
    held : bool
        Whether ``run`` was held out (with two runs there is none to hold out: the last is shown).
    excess_equation, excess_replay : dict
        Per floor: equation residual RMS over the noise-only RMS; per channel: replay residual over noise.
    candidates : tuple of Candidate
        The best screened candidates, best first.
    parameter_pattern : dict
        The damping-pattern fits of the identified C.
    sensor_check : dict
        The kinematic check ``a_j = zdd + q_j''``: excess per floor, the best fits.
    selection : Selection
        What stage 6 (and a compound diagnosis) re-simulated and why it decided.
    localisation : Localisation
        Where the mismatch is: storey, runs, time windows, amplitude, bands, shape, in words.
    """

    run: str
    held: bool
    excess_equation: dict
    excess_replay: dict
    candidates: tuple[Candidate, ...]
    parameter_pattern: dict
    sensor_check: dict
    selection: Selection
    localisation: Localisation

    def to_dict(self) -> dict:
        return {"excess_equation": self.excess_equation, "excess_replay": self.excess_replay,
                "parameter_pattern": self.parameter_pattern, "sensor_check": self.sensor_check,
                "selection": self.selection.to_dict(), "localisation": self.localisation.to_dict(),
                "candidates": [c.to_dict() for c in self.candidates], "path": "added mass"}


@dataclass(frozen=True)
class ModalEvidence:
    """What a diagnosis of accelerometer-only recordings (no added mass) shows beside its verdict.

    Attributes
    ----------
    channel_nrmse : dict
        Per floor sensor: held-out NRMSE before and after.
    training : dict
        The pooled modal model of the training runs: modes, damping, sensor gains and clock offsets.
    candidate : dict
        The amplitude model tried: its trend, its prediction for the held-out run, the share explained.
    findings : tuple of str
        Sensor findings and the recording's stated limits.
    trend : AmplitudeModel or None
        The fitted amplitude model (None when it could not be fitted).
    amplitude : float or None
        The held-out run's response amplitude (m/s^2).
    searched : bool
        Whether the open search ran (a run held out, a mismatch, at least two training runs).
    """

    channel_nrmse: dict
    training: dict
    candidate: dict
    findings: tuple[str, ...]
    trend: AmplitudeModel | None = None
    amplitude: float | None = None
    searched: bool = False

    def to_dict(self) -> dict:
        return {"channel_nrmse": self.channel_nrmse, "training": self.training, "candidate": self.candidate,
                "findings": list(self.findings), "path": "modal (no added mass)"}


@dataclass(frozen=True)
class TwinEvidence:
    """What a diagnosis of accelerometer-only recordings on the rig's MuJoCo twin shows beside its
    verdict (:func:`momentid.diagnosis.twin_diagnose.diagnose_twin`).

    Attributes
    ----------
    training : tuple of str
        The training trials (of the held-out trial's rig state unless it was named from another).
    state : StateCheck
        Which trials belong to one rig state (:mod:`momentid.diagnosis.rig_state`).
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
        The three fitted twins and their NRMSE (:class:`~momentid.diagnosis.twin_folds.Fold`).
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
        return {"training": list(self.training), "reference": self.reference, "rig_state": self.state.to_dict(),
                "excluded": list(self.excluded), "channel_nrmse": self.channel_nrmse, "fits": self.fits,
                "seconds": self.seconds, "path": "twin (no added mass)"}


#: The evidence types of the diagnosis paths.
Evidence = Union[AddedMassEvidence, ModalEvidence, TwinEvidence]


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`~momentid.diagnosis.pipeline.diagnose` for every kind of recording
    (``report.json`` is :meth:`to_dict`; see the module docstring).

    Attributes
    ----------
    verdict : Verdict
    mechanism : str
        The verdict in words: ``none``, ``unexplained`` or the primary mechanism's name.
    location, parameters, std : dict
        The primary mechanism's place and its parameters in the lab's terms, or where an
        ``unexplained`` mismatch is.  On the twin path, ``location`` is where the held-out misfit
        left is largest whatever the verdict (the joints' places and parameters are in
        ``mechanisms``) and ``parameters``, ``std`` are empty.
    mechanisms : tuple of Named
        Every named mechanism, primary first; empty for ``none`` and ``unexplained``.
    held_out : str
        The held-out run (with a note when none could be held out).
    nrmse_before, nrmse_after, noise_nrmse : float
        The held-out run's NRMSE through the linear and the augmented model, and of sensor noise alone.
    evidence : AddedMassEvidence, ModalEvidence or TwinEvidence
    nrmse_linear_refit, nrmse_linear_own : float or None
        Held-out NRMSE of the linear model refitted on the training runs as the augmented one was,
        and of a linear model fitted to the held-out run itself; None where the path does not
        compute them.
    discovered : Discovery, ModalDiscovery or None
        The open search's law (a data-driven model, not a named mechanism).
    augmented_xml : str
        The augmented MuJoCo model (MJCF), when one was built.
    curves : dict
        ``time``, and ``measured``/``linear``/``augmented`` channel groups of the held-out run (plots).
    notes : tuple of str
        What reading the recording recovered (lost runs).
    """

    verdict: Verdict
    mechanism: str
    location: dict
    parameters: dict
    std: dict
    mechanisms: tuple[Named, ...]
    held_out: str
    nrmse_before: float
    nrmse_after: float
    noise_nrmse: float
    evidence: Evidence
    nrmse_linear_refit: float | None = None
    nrmse_linear_own: float | None = None
    discovered: Discovery | ModalDiscovery | None = None
    augmented_xml: str = ""
    curves: dict = field(default_factory=dict, repr=False)
    notes: tuple[str, ...] = ()

    @property
    def summary(self) -> str:
        """The report's text (:func:`momentid.diagnosis.report.summary`)."""
        from momentid.diagnosis.report import summary
        return summary(self)

    def _repr_html_(self) -> str:
        """A notebook's summary: the words of the report page's answer
        (:func:`momentid.diagnosis.summary_html.diagnosis_html`)."""
        from momentid.diagnosis.summary_html import diagnosis_html
        return diagnosis_html(self)

    def to_dict(self) -> dict:
        return {"mechanism": self.mechanism, "location": self.location, "parameters": self.parameters,
                "std": self.std, "summary": self.summary, "held_out": self.held_out, "holdout": self.held_out,
                "nrmse_before": self.nrmse_before, "nrmse_after": self.nrmse_after, "noise_nrmse": self.noise_nrmse,
                "nrmse_linear_refit": self.nrmse_linear_refit, "nrmse_linear_own": self.nrmse_linear_own,
                "mechanisms": [m.to_dict() for m in self.mechanisms], "notes": list(self.notes),
                "discovered": self.discovered.to_dict() if self.discovered is not None else None,
                **self.evidence.to_dict()}
