"""Plausibility of an identification before it is printed as an answer.

Equation (3) can fit data that are wrong in ways it cannot see: floor accelerations exported in g
scale into the identified matrices with an exact fit, added masses typed in grams give a 1000x mass
matrix, swapped floor columns give plausible-looking numbers far from any physics.  Two checks that
need no model catch these before the CLI prints a result:

* sensors against each other: every floor's relative acceleration ``a_j - zdd`` must equal the
  second derivative of its measured displacement ``q_j`` (a gain far from 1, or no correlation,
  means units, a swapped column or a broken sensor);
* masses against what the lab states: identified floor masses, and the added masses, within a
  factor of the nominal ones.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.signal

from momentid.core.series import Experiment, RunData

if TYPE_CHECKING:
    from momentid.estimation.identified import Identification
    from momentid.estimation.scaled import ModalIdentification

__all__ = ["implausible", "GAIN_RANGE", "MIN_CORRELATION", "MASS_FACTOR", "ADDED_MASS_FACTOR"]

#: Accepted gain of ``a_j - zdd`` against ``q_j''``.  Real sensor gains are within a few percent;
#: a unit mistake is a factor 9.81 or 1000, so anything outside a factor 2 is a contradiction.
GAIN_RANGE = (0.5, 2.0)
#: Least correlation of ``a_j - zdd`` with ``q_j''`` in the structure's band: sensors that measure
#: the same motion correlate near 1 even at 5 % noise; a swapped or dead channel does not.
MIN_CORRELATION = 0.5
#: Identified floor masses may differ from the stated ones by at most this factor either way: a
#: mis-weighed floor is tens of percent off, a unit mistake orders of magnitude.
MASS_FACTOR = 5.0
#: Added masses larger than this multiple of the whole structure's stated mass are taken as a unit
#: mistake (a lab bolts masses of the order of a floor's, not of a building's ten times over).
ADDED_MASS_FACTOR = 10.0


def _kinematic(run: RunData, d: int, high: float) -> list[str]:
    """Reasons ``run``'s accelerometers and displacement sensors contradict each other."""
    if not (run.has("zdd") and all(run.has(f"{g}{j + 1}") for g in "aq" for j in range(d))):
        return []
    fs = run.sample_rate
    if run.n_samples < 64:
        return []
    sos = scipy.signal.butter(4, min(high, 0.4 * fs), btype="lowpass", fs=fs, output="sos")
    dt = 1.0 / fs
    zdd = run["zdd"]
    out = []
    for j in range(d):
        q = scipy.signal.sosfiltfilt(sos, run[f"q{j + 1}"])
        qdd = np.gradient(np.gradient(q, dt), dt)
        rel = scipy.signal.sosfiltfilt(sos, run[f"a{j + 1}"] - zdd)
        inner = slice(run.n_samples // 20, -run.n_samples // 20)   # filter and derivative edges
        x, y = qdd[inner] - qdd[inner].mean(), rel[inner] - rel[inner].mean()   # a bias is not a unit
        if not np.any(x) or not np.any(y):
            continue
        gain = float(x @ y / (x @ x))
        corr = float(np.corrcoef(x, y)[0, 1])
        if corr < MIN_CORRELATION or not GAIN_RANGE[0] <= gain <= GAIN_RANGE[1]:
            out.append(f"run {run.name!r}: a{j + 1} - zdd reads {gain:.3g} x q{j + 1}'' (correlation "
                       f"{corr:.2f}); expected 1 with correlation near 1: the accelerometers and "
                       f"displacement sensors contradict each other (units in g? swapped columns?)")
    return out


def _stated_masses(experiment: Experiment):
    if experiment.structure is not None:
        return np.asarray(experiment.structure.masses, float)
    if experiment.statement is not None and experiment.statement.masses is not None:
        return np.asarray(experiment.statement.masses, float)
    return None


def implausible(experiment: Experiment, result: Identification | ModalIdentification) -> tuple[str, ...]:
    """Why ``result`` must not be printed as an answer for ``experiment`` (empty: plausible).

    Parameters
    ----------
    experiment : Experiment
        The recording the result was identified from.
    result : Identification or ModalIdentification
        The identification; its top natural frequency sets the band of the sensor check.

    Returns
    -------
    tuple of str
        One sentence per contradiction, naming the run, channel or mass and the factor.
    """
    d = experiment.storeys
    try:
        f_top = float(np.max(result.modes().frequency))
    except Exception:  # noqa: BLE001  (an unusable result: the band falls back to the sample rate)
        f_top = float("nan")
    reasons = []
    for run in experiment.runs:
        high = 3.0 * f_top if np.isfinite(f_top) and f_top > 0 else 0.4 * run.sample_rate
        reasons += _kinematic(run, d, high)
    stated = _stated_masses(experiment)
    if stated is not None and stated.shape == (d,) and np.all(stated > 0):
        added = max(float(np.max(r.added_mass)) for r in experiment.runs)
        if added > ADDED_MASS_FACTOR * float(stated.sum()):
            reasons.append(f"added masses up to {added:.4g} kg exceed {ADDED_MASS_FACTOR:g} x the structure's "
                           f"stated {stated.sum():.4g} kg (added masses typed in grams?)")
        M = getattr(result, "M", None)
        if M is not None:
            ratio = np.diag(np.asarray(M, float)) / stated
            bad = np.flatnonzero(~((ratio >= 1 / MASS_FACTOR) & (ratio <= MASS_FACTOR)))
            if bad.size:
                reasons.append("identified floor masses are " + ", ".join(
                    f"{ratio[i]:.3g} x" for i in bad) + f" the stated ones on floor(s) "
                    f"{', '.join(str(i + 1) for i in bad)}: expected within a factor {MASS_FACTOR:g} "
                    f"(units of the added masses or of the accelerations?)")
    return tuple(reasons)
