"""One delay per floor sensor across the runs of an experiment: the lag of its data behind its stamps
that the runs agree on (:func:`common_delays`), applied by :func:`momentid.io.align.align_sensors`."""

from __future__ import annotations

import numpy as np

from momentid.io.align import CLOCK_AGREEMENT, AlignedRun

__all__ = ["common_delays", "MIN_DELAY_RUNS"]

#: Fewest runs whose data align a floor sensor against its stamps with one delay for that delay to
#: be applied to every run (:func:`common_delays`): one run's delay may be its own accident.
MIN_DELAY_RUNS = 2


def common_delays(runs: list[AlignedRun], names: list[str]) -> dict:
    """The delay of each floor sensor's data behind its stamps that the runs agree on.

    A sensor whose stamps share the table's origin but whose data lag them (a device latency, a
    clock set late) shows the same delay in every trial.  Where the data align it, each run reads
    that delay; where a run's data cannot (a disturbance, a periodic table motion whose half period
    fits as well), the others' delay is the better clock.  The delay is taken when at least
    :data:`MIN_DELAY_RUNS` runs and a majority of those that read one agree within
    :data:`CLOCK_AGREEMENT` samples of their median, and it is more than :data:`CLOCK_AGREEMENT`
    from the stamps (smaller ones the stamps already give to a sample).

    Parameters
    ----------
    runs : list of AlignedRun
        Each run's first alignment (with its ``stamp_delays``).
    names : list of str
        The runs' names, for the note.

    Returns
    -------
    dict
        Channel -> ``(samples, note)``, for :func:`~momentid.io.align.align_sensors`'s ``delays``.
    """
    out = {}
    channels = sorted({ch for run in runs for ch in run.stamp_delays})
    for ch in channels:
        read = {name: run.stamp_delays[ch] for name, run in zip(names, runs) if ch in run.stamp_delays}
        if len(read) < MIN_DELAY_RUNS:
            continue
        median = float(np.median(list(read.values())))
        agree = {n: v for n, v in read.items() if abs(v - median) <= CLOCK_AGREEMENT}
        if len(agree) < MIN_DELAY_RUNS or 2 * len(agree) <= len(read) or abs(median) <= CLOCK_AGREEMENT:
            continue
        delay = float(np.median(list(agree.values())))
        step = float(runs[0].time[1] - runs[0].time[0])
        values = list(agree.values())
        note = (f"its data lag its stamps by {delay * step * 1e3:+.1f} ms ({delay:+.2f} samples) against the "
                f"table's, read alike in {len(agree)} of the {len(runs)} runs ({min(values):+.2f} to "
                f"{max(values):+.2f} samples): one delay, applied to its stamps in every run")
        out[ch] = (delay, note)
    return out
