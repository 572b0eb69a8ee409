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
- the **evidence** of the path that produced it (an :class:`Evidence`, which words and draws it):
  :class:`~momentid.diagnosis.added_mass.words.AddedMassEvidence` (a rig identified with added masses:
  residuals, screening, selection, localisation) or :class:`~momentid.diagnosis.modal.words.ModalEvidence`
  (accelerometers only: the modal model's per-channel misfit, its training fits, the amplitude model) or
  :class:`~momentid.diagnosis.twin.words.TwinEvidence` (accelerometers only, on the rig's calibrated MuJoCo
  twin: the rig-state check, the training trials, the fitted twins, the reference figure, ``twin.xml``).
"""

from __future__ import annotations

import abc
from dataclasses import dataclass, field
from pathlib import Path

from momentid.diagnosis.verdict import Named, Verdict

__all__ = ["Diagnosis", "Evidence"]


class Evidence(abc.ABC):
    """What a diagnosis path shows beside its verdict: each path's own type (a frozen dataclass) says it
    in words, draws it and lists it in ``report.json``; the report folder asks it, never its type."""

    @abc.abstractmethod
    def words(self, diag: Diagnosis) -> str:
        """The report's text (``summary.txt``, ``--json``'s ``summary``) of ``diag``, which holds this evidence."""

    @abc.abstractmethod
    def plot_replay(self, diag: Diagnosis, path: Path) -> None:
        """``replay.png``: the held-out run recorded and as the linear and augmented models replay it."""

    @abc.abstractmethod
    def to_dict(self) -> dict:
        """This evidence's entries of ``report.json`` (with ``path``: which diagnosis produced it)."""

    def models(self) -> dict[str, str]:
        """MuJoCo models (file name -> MJCF) the report holds beside ``model_augmented.xml``; none by default."""
        return {}

    def figures(self, diag: Diagnosis, folder: Path) -> list[str]:
        """Draw this path's own figures into ``folder``; returns their file names (none by default)."""
        return []


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`~momentid.diagnosis.dispatch.diagnose` for every kind of recording
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
    evidence : Evidence
        The path's own (added mass, modal or twin), which words the summary.
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
    discovered: object | None = None
    augmented_xml: str = ""
    curves: dict = field(default_factory=dict, repr=False)
    notes: tuple[str, ...] = ()

    @property
    def summary(self) -> str:
        """The report's text, in its path's words (:meth:`Evidence.words`)."""
        return self.evidence.words(self)

    def _repr_html_(self) -> str:
        """A notebook's summary: the words of the report page's answer
        (:func:`momentid.diagnosis.summary_html.diagnosis_html`)."""
        from momentid.diagnosis.summary_html import diagnosis_html
        return diagnosis_html(self)

    def to_dict(self) -> dict:
        """``report.json``: the verdict, the held-out check's numbers, each path's evidence (module docstring)."""
        return {"mechanism": self.mechanism, "location": self.location, "parameters": self.parameters,
                "std": self.std, "summary": self.summary, "held_out": self.held_out, "holdout": self.held_out,
                "nrmse_before": self.nrmse_before, "nrmse_after": self.nrmse_after, "noise_nrmse": self.noise_nrmse,
                "nrmse_linear_refit": self.nrmse_linear_refit, "nrmse_linear_own": self.nrmse_linear_own,
                "mechanisms": [m.to_dict() for m in self.mechanisms], "notes": list(self.notes),
                "discovered": self.discovered.to_dict() if self.discovered is not None else None,
                **self.evidence.to_dict()}
