"""Sensor models: what a lab's instruments make of the rig's true motion.

The simulator produces every channel exactly at the simulation rate;
:func:`measure` turns that into what the scenario's instruments record:

1. the channel's faults on the true signal (a clock offset: the channel reads it at ``t - offset``);
2. the anti-alias filter (a causal 4th-order Butterworth, the same on every
   channel, so linear equations between channels still hold exactly);
3. sampling at the sensor rate;
4. the channel's gain fault, the instrument's bias, the channel's offset faults;
5. white noise (absolute RMS, noise density over the sampled band, or a
   fraction of the channel's own RMS, added in quadrature), seeded per run and
   channel so results do not depend on the order runs are simulated in;
6. quantisation and clipping at the instrument's full scale, then the channel's range faults (a
   saturation).

A channel's faults are the registered sensor-fault kinds a scenario's ``[sensors.channel.X]`` states
(:class:`~momentid.lab.scenario.ChannelFault`), each applied by its kind's own ``distort`` at its stage:
the one model of a sensor fault, which the diagnosis names.

The other side, inspecting recorded data before identification, is
:func:`momentid.io.run_checks.check_run`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike
import scipy.fft
import scipy.signal

from momentid.core.series import RunData
from momentid.mechanisms.base import SensorStage
from momentid.lab.scenario import Instrument, Sensors

__all__ = ["measure", "noise_std", "gain_and_delay", "padded_length", "ANTIALIAS_ORDER"]

#: Order of the causal Butterworth anti-alias filter (``[sensors] antialias``):
#: 24 dB/octave, the usual analogue front end of a data logger.
ANTIALIAS_ORDER = 4


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
        x = fault.apply(SensorStage.SIGNAL, run.time, run[name])
        if sos is not None:
            x = scipy.signal.sosfilt(sos, x)
        time = run.time[::step]
        x = fault.apply(SensorStage.GAIN, time, x[::step]) + inst.bias
        x = fault.apply(SensorStage.OFFSET, time, x)
        sigma = noise_std(inst, x, fs)
        if sigma > 0:
            rng = np.random.default_rng(np.random.SeedSequence([seed, run_index, everything.index(name)]))
            x = x + sigma * rng.standard_normal(x.shape)
        if inst.resolution:
            x = inst.resolution * np.round(x / inst.resolution)
        if inst.range:
            x = np.clip(x, -inst.range, inst.range)
        out[:, j] = fault.apply(SensorStage.RANGE, time, x)
    return replace(run, time=run.time[::step].copy(), channels=names, values=out)


def gain_and_delay(a: np.ndarray, gain: ArrayLike, offset: ArrayLike, dt: float, *, undo: bool = False
                   ) -> np.ndarray:
    """Floor accelerations ``a`` (n, d) as the floor sensors read them: each channel times its gain and
    delayed by its clock offset (fractional, in the frequency domain, zero-padded so that the delay does
    not wrap around); ``undo=True`` is the inverse (a recording with its sensors' gains and offsets undone).

    Parameters
    ----------
    a : ndarray, shape (..., n, d)
        Accelerations (m/s^2); leading axes are a batch (several simulations read by the same sensors:
        one transform for all of them).
    gain, offset : array_like, shape (d,)
        Gain (1) and clock offset (s, positive: lags) of each channel.
    dt : float
        Sample interval (s).
    undo : bool
        Undo the gains and offsets instead.

    Returns
    -------
    ndarray, shape (..., n, d)
        The readings (m/s^2).
    """
    n = a.shape[-2]
    length = padded_length(n)
    spectrum = scipy.fft.rfft(a, length, axis=-2)
    w_bins = 2 * np.pi * scipy.fft.rfftfreq(length, dt)
    gain, offset = np.asarray(gain, float)[None, :], np.asarray(offset, float)[None, :]
    spectrum *= np.exp(1j * w_bins[:, None] * offset) / gain if undo else gain * np.exp(-1j * w_bins[:, None] * offset)
    return scipy.fft.irfft(spectrum, length, axis=-2)[..., :n, :]


def padded_length(n: int) -> int:
    """The FFT length :func:`gain_and_delay` pads ``n`` samples to: at least ``2 n`` (a delay does not wrap
    around) and a product of small primes (``2 n`` itself can hold a large prime factor: 3x slower).

    Parameters
    ----------
    n : int
        Samples.

    Returns
    -------
    int
    """
    return scipy.fft.next_fast_len(2 * n, real=True)
