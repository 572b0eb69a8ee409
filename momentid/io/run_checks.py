"""Recorded data checked before identification: refused, or repaired and reported.

:func:`check_run` is what every estimator (:mod:`~momentid.estimation.identification`,
:mod:`~momentid.estimation.scaled`) and the modal diagnosis (:mod:`momentid.diagnosis.modal.check`)
run on a recorded run first.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from momentid.core.clipping import find_clipping, runs_of
from momentid.core.series import RunData, channel_unit
from momentid.errors import SensorDataError

__all__ = ["check_run", "check_clipping", "MAX_REPAIR_GAP"]

#: Longest run of missing (NaN) samples that :func:`check_run` interpolates over.
MAX_REPAIR_GAP = 5

#: Largest deviation of one sample interval from the median, as a fraction of
#: it, that :func:`check_run` still calls even sampling (logger clock jitter).
_TIME_STEP_TOLERANCE = 1e-3


def check_run(run: RunData, source: str = "<memory>", *, clip_samples: int = 3) -> tuple[RunData, tuple[str, ...]]:
    """Refuse unusable sensor data, repair what can be repaired, and say so.

    * time stamps must increase with one sample interval (a gap is an error);
    * missing samples (NaN/inf) in runs of at most :data:`MAX_REPAIR_GAP` are
      interpolated linearly and reported; longer runs are an error;
    * a channel that sits at its extreme value for ``clip_samples`` or more
      consecutive samples at both or one end is clipped: an error.

    Returns
    -------
    run : RunData
        The run, repaired where reported.
    notes : tuple of str
        One note per repair.
    """
    where = f"{source}: run {run.name!r}"
    t = run.time
    if t.size < 3:
        raise SensorDataError(f"{where}: {t.size} samples: expected at least 3")
    dt = np.diff(t)
    h = float(np.median(dt))
    bad = np.flatnonzero(np.abs(dt - h) > _TIME_STEP_TOLERANCE * h)
    if bad.size:
        k = int(bad[0])
        raise SensorDataError(
            f"{where}: samples are not evenly spaced: t jumps from {t[k]:.6g} s to {t[k + 1]:.6g} s "
            f"(expected steps of {h:.6g} s); a gap in the recording cannot be identified across"
        )
    values = run.values.copy()
    notes = []
    for j, name in enumerate(run.channels):
        x = values[:, j]
        missing = ~np.isfinite(x)
        if missing.any():
            if missing.all():
                raise SensorDataError(f"{where}: channel {name} has no finite sample")
            for a, b in runs_of(missing):
                if b - a > MAX_REPAIR_GAP or a == 0 or b == x.size:
                    raise SensorDataError(
                        f"{where}: channel {name} is missing {b - a} samples from t = {t[a]:.6g} s: "
                        f"expected at most {MAX_REPAIR_GAP} consecutive missing samples inside the record"
                    )
            ok = ~missing
            x[missing] = np.interp(t[missing], t[ok], x[ok])
            notes.append(f"{where}: channel {name}: interpolated {int(missing.sum())} missing samples")
        check_clipping(where, name, x, clip_samples)
    return replace(run, values=values), tuple(notes)


def check_clipping(where: str, name: str, x: np.ndarray, clip_samples: int = 3) -> None:
    """Refuse a clipped channel (:func:`find_clipping`): its shape at the clipped peaks is not the
    structure's.  (The diagnosis reads the same finding as a candidate, a sensor saturation.)"""
    found = find_clipping(x, clip_samples)
    if found is not None:
        raise SensorDataError(
            f"{where}: channel {name} is clipped: {found.first_run} consecutive samples at {found.first_value:.6g} "
            f"{channel_unit(name)} from t-index {found.first}; expected a transducer range above the signal (drop "
            f"the channel or re-record)"
        )
