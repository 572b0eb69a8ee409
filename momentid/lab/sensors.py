"""Sensor models: what a lab's instruments make of the rig's true motion.

The simulator produces every channel exactly at the simulation rate;
:func:`measure` turns that into what the scenario's instruments record:

1. per-channel clock offset (the channel reads the true signal at ``t - offset``);
2. the anti-alias filter (a causal 4th-order Butterworth, the same on every
   channel, so linear equations between channels still hold exactly);
3. sampling at the sensor rate;
4. gain and bias;
5. white noise (absolute RMS, noise density over the sampled band, or a
   fraction of the channel's own RMS, added in quadrature), seeded per run and
   channel so results do not depend on the order runs are simulated in;
6. quantisation and clipping at full scale.

:func:`check_run` is the other side: it inspects recorded data before
identification and refuses, or repairs and reports, what it cannot use.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.signal

from momentid.core.series import RunData
from momentid.errors import SensorDataError
from momentid.lab.scenario import Instrument, Sensors

__all__ = ["measure", "noise_std", "check_run", "check_clipping", "MAX_REPAIR_GAP", "ANTIALIAS_ORDER"]

#: Longest run of missing (NaN) samples that :func:`check_run` interpolates over.
MAX_REPAIR_GAP = 5

#: Order of the causal Butterworth anti-alias filter (``[sensors] antialias``):
#: 24 dB/octave, the usual analogue front end of a data logger.
ANTIALIAS_ORDER = 4

#: Largest deviation of one sample interval from the median, as a fraction of
#: it, that :func:`check_run` still calls even sampling (logger clock jitter).
_TIME_STEP_TOLERANCE = 1e-3

#: A flat run at a channel's peak entered or left by a step larger than this
#: many quantisation steps is clipping; a quantised smooth peak is entered by one.
_CLIP_STEP_QUANTA = 2.5

#: Relative tolerance for "at the peak value" (floating-point round-off only).
_PEAK_TOLERANCE = 1e-12


def noise_std(instrument: Instrument, x: np.ndarray, sample_rate: float) -> float:
    """RMS of the white noise ``instrument`` adds to the channel ``x``.

    The three noise terms of :class:`~momentid.lab.scenario.Instrument` add in
    quadrature: the absolute ``noise``, the ``noise_density`` integrated over
    the sampled band (0 to the Nyquist frequency ``sample_rate / 2``), and
    ``relative_noise`` times the channel's own RMS.  :func:`measure` draws
    this noise; the Cramér-Rao bound (:mod:`momentid.estimation.design`)
    assumes it.

    Parameters
    ----------
    instrument : Instrument
        The transducer kind of the channel.
    x : ndarray, shape (n_samples,)
        The channel as sampled, before noise (its SI unit).
    sample_rate : float
        Sensor sample rate (Hz).

    Returns
    -------
    float
        Noise standard deviation, in the channel's unit.
    """
    nyquist = sample_rate / 2
    return float(np.sqrt(instrument.noise ** 2 + instrument.noise_density ** 2 * nyquist
                         + (instrument.relative_noise * np.sqrt(np.mean(x ** 2))) ** 2))


def _shift(t: np.ndarray, x: np.ndarray, offset: float) -> np.ndarray:
    """``x`` read ``offset`` seconds late (cubic interpolation, held before t0)."""
    if offset == 0:
        return x
    from scipy.interpolate import CubicSpline
    spline = CubicSpline(t, x)
    tq = np.clip(t - offset, t[0], t[-1])
    return spline(tq)


def measure(run: RunData, sensors: Sensors, *, seed: int, run_index: int) -> RunData:
    """Apply the sensor model to a run of true channels.

    Parameters
    ----------
    run : RunData
        Every channel the rig defines, exact, at the simulation rate.
    sensors : Sensors
        The scenario's sensor description.
    seed, run_index : int
        Noise is drawn from ``SeedSequence([seed, run_index, channel number])``.

    Returns
    -------
    RunData
        The recorded channels (``sensors.channels(d)``) at the sensor rate.
    """
    d = run.added_mass.shape[0]
    names = sensors.channels(d)
    everything = Sensors().channels(d)
    if sensors.ideal:
        idx = [run.channels.index(c) for c in names]
        return replace(run, channels=names, values=run.values[:, idx])
    rate = run.sample_rate
    step = 1 if sensors.sample_rate is None else int(round(rate / sensors.sample_rate))
    fs = rate / step
    sos = (scipy.signal.butter(ANTIALIAS_ORDER, sensors.antialias, fs=rate, output="sos")
           if sensors.antialias else None)
    out = np.empty((len(run.time[::step]), len(names)))
    for j, name in enumerate(names):
        inst = sensors.instrument(name)
        fault = sensors.fault(name)
        x = _shift(run.time, run[name], fault.clock_offset)
        if sos is not None:
            x = scipy.signal.sosfilt(sos, x)
        x = fault.gain * x[::step] + inst.bias + fault.bias
        sigma = noise_std(inst, x, fs)
        if sigma > 0:
            rng = np.random.default_rng(np.random.SeedSequence([seed, run_index, everything.index(name)]))
            x = x + sigma * rng.standard_normal(x.shape)
        if inst.resolution:
            x = inst.resolution * np.round(x / inst.resolution)
        if inst.range:
            x = np.clip(x, -inst.range, inst.range)
        out[:, j] = x
    return replace(run, time=run.time[::step].copy(), channels=names, values=out)


def _runs_of(mask: np.ndarray):
    """(start, stop) of every run of True in a boolean vector."""
    padded = np.concatenate([[False], mask, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return list(zip(edges[::2], edges[1::2]))


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
            for a, b in _runs_of(missing):
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
    """A flat run at the channel's extreme, entered or left by a step larger
    than the channel's quantisation, is clipping (a quantised smooth peak is
    entered by one quantum)."""
    peak = float(np.max(np.abs(x)))
    if peak == 0:
        return
    levels = np.unique(x)
    quantum = float(np.min(np.diff(levels))) if levels.size > 1 else peak
    at_peak = np.abs(np.abs(x) - peak) <= _PEAK_TOLERANCE * peak
    for a, b in _runs_of(at_peak):
        if b - a < clip_samples:
            continue
        steps = [abs(x[a] - x[a - 1])] if a > 0 else []
        steps += [abs(x[b] - x[b - 1])] if b < x.size else []
        if steps and max(steps) > _CLIP_STEP_QUANTA * quantum:
            raise SensorDataError(
                f"{where}: channel {name} is clipped: {b - a} consecutive samples at {x[a]:.6g} "
                f"{_unit(name)} from t-index {a}; expected a transducer range above the signal (drop "
                f"the channel or re-record)"
            )


def _unit(name: str) -> str:
    from momentid.core.series import channel_unit
    return channel_unit(name)
