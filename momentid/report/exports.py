"""An identification in the files modal-analysis tools read: ``modes.uff`` and ``frf.uff`` (UFF,
:mod:`momentid.io.uff`).

Nodes: ``0`` is the shake table, ``j`` floor ``j`` (dataset 15 places them at the stated storey
heights when the recording states them); every value is along +X, the shaking axis, in SI units
(dataset 164).

- ``modes.uff``: one dataset 55 per mode: its shape at the floors, its frequency (Hz) and viscous
  damping ratio; ID lines give the runs, the standard errors and whether the damping ratio is an
  answer.  A modal identification's shapes are the floor sensors' readings, 1 at the top floor (the
  modal mass is given when floor masses are stated); an added-mass identification's are
  mass-normalised (modal mass 1 kg).
- ``frf.uff``: per run and floor sensor, the measured table-to-floor transfer function (H1 after the
  run's quiet lead-in, :func:`momentid.estimation.frf.measured_transfer`; dataset 58, function
  type 4, complex) and its coherence (function type 6).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from momentid.core.html import REFUSED
from momentid.estimation.noise import quiet_lead_in
from momentid.estimation.frf import MeasuredTransfer, measured_transfer
from momentid.io import uff

if TYPE_CHECKING:
    from momentid.core.series import Experiment
    from momentid.estimation.identified import Identification
    from momentid.estimation.scaled import ModalIdentification

__all__ = ["modes_uff", "frf_uff", "transfers"]


def _geometry(experiment, d: int) -> str:
    """Dataset 15 of the table and floors at the stated storey heights ('' when none are stated)."""
    for source in (experiment.structure, experiment.statement):
        heights = getattr(source, "storey_heights", None) if source is not None else None
        if heights is not None and len(heights) == d:
            z = np.concatenate([[0.0], np.cumsum(np.asarray(heights, float))])
            return uff.nodes(list(range(d + 1)), np.column_stack([np.zeros(d + 1), np.zeros(d + 1), z]))
    return ""


def _answered(what: str, answer: bool) -> str:
    return f"{what}: an answer" if answer else f"{what}: {REFUSED} (see the warnings)"


def _modal_sets(result, experiment, load_case: int) -> list[str]:
    d = result.storeys
    answer = np.ones(d, bool) if result.damping_is_answer is None else np.asarray(result.damping_is_answer)
    out = []
    for i in range(d):
        shape = np.asarray(result.shapes[:, i], float)
        modal_mass = float(np.sum(np.asarray(result.masses, float) * shape ** 2)) if result.masses is not None else 0.0
        ids = [f"momentid modal identification of {experiment.name}: mode {i + 1}",
               f"runs: {', '.join(result.runs)}",
               f"f = {result.frequency[i]:.6g} +- {result.frequency_std[i]:.2g} Hz; damping ratio "
               f"{result.damping_ratio[i]:.6g} +- {result.damping_ratio_std[i]:.2g}",
               _answered("damping ratio", answer[i]) + "; " + _answered("frequency", result.frequency_answered(i)),
               "shape: floor sensor readings, 1 at the top floor; node 0 table, node j floor j"]
        out.append(uff.mode(i + 1, float(result.frequency[i]), float(result.damping_ratio[i]), range(1, d + 1),
                            shape, ids, modal_mass=modal_mass, load_case=load_case))
    return out


def _added_mass_sets(result, experiment) -> list[str]:
    modes = result.modes()
    out = []
    for i in range(result.storeys):
        ids = [f"momentid added-mass identification of {experiment.name}: mode {i + 1}",
               f"runs: {', '.join(result.runs)}",
               f"f = {modes.frequency[i]:.6g} Hz; damping ratio {modes.damping_ratio[i]:.6g} "
               f"(of the identified M, C, K; {result.estimator})",
               "shape: mass-normalised (modal mass 1 kg); node 0 table, node j floor j"]
        out.append(uff.mode(i + 1, float(modes.frequency[i]), float(modes.damping_ratio[i]),
                            range(1, result.storeys + 1), modes.shapes[:, i], ids, modal_mass=1.0))
    return out


def modes_uff(results: Identification | ModalIdentification | Sequence[ModalIdentification], experiment: Experiment
              ) -> str:
    """``modes.uff`` of an identification of ``experiment`` (module docstring).

    Parameters
    ----------
    results : ModalIdentification, Identification, or a sequence of ModalIdentification
        A sequence (one fit per run, ``identify --per-run``) gives each run its own load case (1, 2, ...).
    experiment : Experiment

    Returns
    -------
    str
    """
    from momentid.estimation.scaled import ModalIdentification

    many = isinstance(results, (list, tuple))
    sets = [uff.units(), _geometry(experiment, experiment.storeys)]
    for case, result in enumerate(results if many else [results], start=1):
        sets += (_modal_sets(result, experiment, case) if isinstance(result, ModalIdentification)
                 else _added_mass_sets(result, experiment))
    return "".join(sets)


def transfers(experiment: Experiment, runs: Iterable[str]) -> list[MeasuredTransfer]:
    """The measured transfer functions of ``runs`` (names) of ``experiment``, each after its quiet
    lead-in (:class:`~momentid.estimation.frf.MeasuredTransfer`, in order)."""
    out = []
    for name in runs:
        run = experiment.run(name)
        out.append(measured_transfer(run, experiment.storeys, quiet_lead_in(run)))
    return out


def frf_uff(experiment: Experiment, runs: Iterable[str]) -> str:
    """``frf.uff`` of ``runs`` (names) of ``experiment`` (module docstring)."""
    d = experiment.storeys
    sets = [uff.units(), _geometry(experiment, d)]
    number = 0
    for measured in transfers(experiment, runs):
        run = experiment.run(measured.run)
        step = float(measured.frequency[1] - measured.frequency[0])
        lead = f"after the quiet lead-in ({measured.start / run.sample_rate:.3g} s)" if measured.start else "whole run"
        for j in range(d):
            for kind, values, what in ((uff.FRF, measured.h[:, j], "H1 transfer function"),
                                       (uff.COHERENCE, measured.coherence[:, j], "coherence")):
                number += 1
                ids = [f"momentid: {experiment.name}: floor {j + 1} sensor / table sensor, {what}",
                       f"run {measured.run}",
                       f"Welch, Hann segments of {measured.segment} samples, {lead}",
                       "node 0 table, node j floor j; acceleration over acceleration (1)"]
                ordinate = f"floor {j + 1} / table" if kind == uff.FRF else "coherence"
                sets.append(uff.function(kind, number, step, values, response_node=j + 1, reference_node=0,
                                         ids=ids, ordinate=ordinate))
    return "".join(sets)
