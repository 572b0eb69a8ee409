"""Free decays: where a mode rings on its own, its damping is read from how fast its envelope falls.

A shake-table record seldom forces a lightly damped mode steadily: an earthquake record comes in
bursts, a sine test stops, and after each burst the structure rings down while the table is all but
still.  In a ring-down no model of the table's input, of the rig's nonlinearity under strong forcing or
of a forced harmonic stands between the data and the damping: the envelope ``E`` of the mode's
acceleration falls by ``d ln E = -zeta(E) d phi`` per radian ``phi`` of its own phase (Hilbert
transform of the band-passed record: the free-vibration method of Feldman's FREEVIB), so the
damping at each amplitude, and its limit at small amplitude, follow from the envelope against the
accumulated phase, whatever the frequency does meanwhile.

:func:`ring_downs` finds the stretches where a mode rings free: the table's power near the mode
(within :data:`BAND` of it, net of the table sensor's noise) supplies less than :data:`FREE_FORCING` of
what the mode dissipates, and the mode stands :data:`MIN_SNR` times above the noise in that band.
:func:`fit_decay` fits ``zeta(E) = zeta_0`` or ``zeta_0 + zeta_1 E`` (by evidence) to all of them, each
ring-down with its own starting amplitude, with a standard error that holds the envelope's correlated
wobble (beats with a weaker neighbour, leakage of the band-pass): Newey-West over
:func:`correlation_time`.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.signal

__all__ = ["RingDown", "DecayFit", "advance", "band_for", "envelope", "ring_downs", "fit_decay", "correlation_time",
           "BAND", "FREE_FORCING", "MIN_SNR", "MIN_CYCLES", "SLOPE_SIGMAS"]

#: Relative half-width of the band-pass around a mode (narrowed to half the gap to another storey mode):
#: wide against a lightly damped mode's half-power band (0.1-1 %), narrow enough to leave other modes out.
BAND = 0.10
#: A stretch rings free when the table's power in the band supplies less than this share of what the
#: mode dissipates at its amplitude (a steady random forcing supplies all of it, share 1): the decay
#: it leaves is at most that much too slow, on average (correcting for it adds the table noise's
#: fluctuation to the envelope, and a synthetic constant damping then reads as amplitude-dependent).
FREE_FORCING = 0.1
#: ... and the mode's envelope stands this many times above the noise in the band (at 5x the log
#: envelope's noise bias is 2 %, and the noise floor is subtracted).
MIN_SNR = 5.0
#: A free decay rings at the mode's own frequency: its instantaneous frequency stays within this share
#: of the mode's (the shipped rigs drift by up to 4 % with amplitude; a table line elsewhere in the band
#: is a forced response, not the mode's) ...
NEAR_MODE = 0.05
#: ... and it decays: its envelope falls by at least this much in ln (10 %) over the stretch.
MIN_FALL = 0.1
#: A ring-down must hold this many cycles of the mode (after the filter's transients are cut).
MIN_CYCLES = 12
#: Exponents ``p`` of the amplitude-dependent laws ``zeta0 + zeta1 E^p`` tried.
POWERS = (0.5, 1.0)
#: The power law is tried when a ring-down's envelope spans more than this in ln (a factor 1.2).
MIN_LOG_SPAN = 0.2
#: An amplitude term is kept when it exceeds this many standard errors.
SLOPE_SIGMAS = 2.0
#: The moving average that smooths the forcing criterion spans this many cycles of the mode, and at
#: least this many time constants ``1 / (pi B)`` of the band (a narrow band's noise power averaged over
#: fewer scatters by several times its mean and would cut a free decay in pieces).
SMOOTH_CYCLES = 3
SMOOTH_CONSTANTS = 8
#: Cut at each end of a stretch, in time constants ``1 / (pi B)`` of the band-pass (B its width, Hz).
EDGE_CONSTANTS = 3.0


@dataclass(frozen=True)
class RingDown:
    """One stretch of free decay of one mode.

    Attributes
    ----------
    run : str
    start, stop : int
        Samples ``[start, stop)`` of the run.
    envelope : ndarray, shape (m,)
        The mode's acceleration envelope (m/s^2, noise floor removed) at its strongest floor.
    phase : ndarray, shape (m,)
        Its unwrapped phase (rad), from 0.
    frequency : ndarray, shape (m,)
        Its instantaneous frequency (Hz).
    sample_rate : float
    supplied : ndarray, shape (m,)
        The damping ratio the table's remaining forcing supplies back on average (its power near the mode
        over the mode's response power, times ``pi / (8 h)``): below :data:`FREE_FORCING` x the mode's.
    noise : float
        The sensors' noise in the envelope (m/s^2, its RMS in the band): the decay is cut where the
        envelope falls to :data:`MIN_SNR` times it.
    """

    run: str
    start: int
    stop: int
    envelope: np.ndarray
    phase: np.ndarray
    frequency: np.ndarray
    sample_rate: float
    supplied: np.ndarray | None = None
    noise: float = 0.0

    @property
    def seconds(self) -> tuple[float, float]:
        """Start and stop of the stretch in the run (s)."""
        return self.start / self.sample_rate, self.stop / self.sample_rate

    @property
    def cycles(self) -> float:
        """Number of cycles of the mode the stretch holds."""
        return float(self.phase[-1] / (2 * np.pi))


@dataclass(frozen=True)
class DecayFit:
    """:func:`fit_decay`'s result for one mode.

    Attributes
    ----------
    zeta0, zeta0_std : float
        Damping ratio at small amplitude and its standard error.
    slope, slope_std : float
        ``zeta_1`` of ``zeta0 + zeta_1 E^p`` (0 for a constant law).
    exponent : float
        ``p`` (0 for a constant law).
    amplitude_dependent : bool
        The slope is kept (beyond ``slope_sigmas`` standard errors).
    evidence : float
        The largest ``|zeta1|`` in standard errors over the laws tried (0: no law tried).
    dof : int
        Degrees of freedom of the error: independent stretches (correlation times) less the parameters.
    frequency0, frequency_slope, frequency_slope_std : float
        Instantaneous frequency at small amplitude (Hz) and its change per m/s^2.
    amplitude_range : tuple of float
        10th and 90th percentiles of the envelope fitted (m/s^2).
    cycles : float
        Cycles of free decay fitted.
    span : float
        How far the envelopes fall: their largest value over their smallest.
    rest : float
        How near the sensors' noise the quietest decay came: its smallest envelope over the noise in it
        (about :data:`MIN_SNR` when a decay rang until the noise cut it, more when the record's end or
        the table's forcing cut it first; inf when the noise is not known).
    """

    zeta0: float
    zeta0_std: float
    slope: float
    slope_std: float
    exponent: float
    amplitude_dependent: bool
    dof: int
    evidence: float
    frequency0: float
    frequency_slope: float
    frequency_slope_std: float
    amplitude_range: tuple
    cycles: float
    span: float = np.inf
    rest: float = np.inf


def advance(tau: float, x: np.ndarray, sample_rate: float) -> np.ndarray:
    """``x`` (N,) moved earlier by ``tau`` seconds (a late sensor's delay undone), band-limited: a phase
    ramp on the zero-padded DFT (no wrap-around)."""
    x = np.asarray(x, float)
    n = x.shape[0]
    f = np.fft.rfftfreq(2 * n, 1.0 / sample_rate)
    return np.fft.irfft(np.fft.rfft(x, 2 * n) * np.exp(2j * np.pi * f * tau), 2 * n)[:n]


def band_for(frequency: float, others: Iterable[float], sample_rate: float) -> tuple[float, float]:
    """The band-pass (Hz) around a mode at ``frequency``: +-:data:`BAND`, narrowed to half the gap to the
    nearest of ``others`` (Hz) and kept below 0.49 x the sample rate."""
    half = BAND
    for f in others:
        if f != frequency:
            half = min(half, 0.5 * abs(f / frequency - 1))
    return frequency * (1 - half), min(frequency * (1 + half), 0.49 * sample_rate)


def envelope(x: np.ndarray, band: tuple[float, float], sample_rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Envelope (same unit as ``x``), unwrapped phase (rad) and instantaneous frequency (Hz) of ``x``
    band-passed to ``band`` (zero phase, 4th-order Butterworth)."""
    sos = scipy.signal.butter(4, band, btype="band", fs=sample_rate, output="sos")
    analytic = scipy.signal.hilbert(scipy.signal.sosfiltfilt(sos, x))
    phase = np.unwrap(np.angle(analytic))
    return np.abs(analytic), phase, np.gradient(phase) * sample_rate / (2 * np.pi)


def correlation_time(band: tuple[float, float], frequency: float) -> float:
    """Seconds over which a ring-down's log-envelope residual stays correlated: the band-pass's time
    constant, and at least a few cycles of the mode (beats with a neighbour inside the band)."""
    return max(EDGE_CONSTANTS / (np.pi * (band[1] - band[0])), 3.0 / frequency)


def ring_downs(run_name: str, table: np.ndarray, relative: np.ndarray, sample_rate: float, frequency: float,
               zeta: float, residue: float, band: tuple[float, float], sigma_table: float, sigma_relative: float
               ) -> list[RingDown]:
    """The free decays of one mode in one run.

    Parameters
    ----------
    run_name : str
    table : ndarray, shape (N,)
        Table acceleration (m/s^2).
    relative : ndarray, shape (N,)
        Table minus floor acceleration on the mode's strongest floor (m/s^2).
    sample_rate : float
    frequency, zeta : float
        The mode's frequency (Hz) and a damping ratio for it (the linear fit's) to judge the forcing by.
    residue : float
        The mode's residue on that floor (its relative acceleration per unit modal acceleration).
    band : (float, float)
        The band-pass (Hz), see :func:`band_for`.
    sigma_table, sigma_relative : float
        Noise standard deviations (m/s^2) of the table channel and of ``relative``.

    Returns
    -------
    list of RingDown
    """
    fs = sample_rate
    E, phase, inst = envelope(relative, band, fs)
    # the table's motion is read over twice the band: a strong line just outside the band-pass (a sine
    # test's harmonic) leaks into the mode's envelope through its skirts, and is forcing too
    wide = (max(frequency - 2 * (frequency - band[0]), 0.05 * frequency), min(frequency + 2 * (band[1] - frequency),
                                                                               0.49 * fs))
    e, _, _ = envelope(table, wide, fs)
    share = (wide[1] - wide[0]) / (fs / 2)
    # white noise of variance sigma^2 leaves sigma^2 x share in the band, and twice that in |analytic|^2
    noise_t, noise_r = 2 * sigma_table ** 2 * share, 2 * sigma_relative ** 2 * share * (band[1] - band[0]) / (
        wide[1] - wide[0])
    width = max(int(round(max(SMOOTH_CYCLES / frequency, SMOOTH_CONSTANTS / (np.pi * (band[1] - band[0]))) * fs)), 1)
    kernel = np.ones(width) / width
    # the table's power beyond its noise, less two standard deviations of the noise's own scatter over the
    # window (about width x B independent values): a stretch is forced only when the forcing is real
    independent = max(width / fs * (wide[1] - wide[0]), 1.0)
    e2 = np.convolve(e ** 2, kernel, "same") - noise_t * (1 + 2 / np.sqrt(independent))
    E2 = np.maximum(np.convolve(E ** 2, kernel, "same") - noise_r, 1e-300)
    # Steady random forcing: the band's power 2 S0 dw drives E[x''^2] = pi S0 w / (2 zeta): their ratio is
    # (8 h / pi) zeta for a band of half-width h (relative); E holds residue x x''.
    half = 0.5 * (wide[1] - wide[0]) / frequency
    supplied = e2 * residue ** 2 / ((8 * half / np.pi) * E2)
    near = np.abs(np.convolve(inst, kernel, "same") / frequency - 1) < NEAR_MODE
    ok = (supplied < FREE_FORCING * max(zeta, 1e-4)) & (E2 > (MIN_SNR ** 2 - 1) * noise_r) & near
    edge = int(np.ceil(EDGE_CONSTANTS / (np.pi * (band[1] - band[0])) * fs))
    out = []
    idx = np.flatnonzero(ok)
    for piece in (np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1) if idx.size else []):
        a, b = int(piece[0]) + edge, int(piece[-1]) + 1 - edge
        if a <= edge or b >= len(relative) - edge:      # the record's own ends: the filter's transients
            a, b = max(a, 2 * edge), min(b, len(relative) - 2 * edge)
        if b - a < MIN_CYCLES * fs / frequency:
            continue
        env = np.sqrt(np.maximum(E[a:b] ** 2 - noise_r, 1e-300))
        if np.log(env[0] / env[-1]) < MIN_FALL:          # a steady response to a line, not a decay
            continue
        out.append(RingDown(run_name, a, b, env, phase[a:b] - phase[a], inst[a:b], fs, supplied[a:b],
                            float(np.sqrt(noise_r))))
    return out


def _decay_model(params, rings, power: float):
    """Log envelope predicted per ring-down.  ``params``: ``zeta0``, then (``power`` > 0) ``zeta1``, then
    ``ln E0`` per ring-down.  ``d ln E / d phi = -(zeta0 + zeta1 E^p)`` gives
    ``E^-p = (E0^-p + zeta1 / zeta0) exp(p zeta0 phi) - zeta1 / zeta0``."""
    z0 = params[0]
    start = 2 if power else 1
    out = []
    for k, ring in enumerate(rings):
        ln_e0 = params[start + k]
        if not power:
            out.append(ln_e0 - z0 * ring.phase)
            continue
        z1 = params[1]
        if abs(z0) < 1e-9:                               # the limit zeta0 -> 0: E^-p = E0^-p + p zeta1 phi
            w = np.exp(-power * ln_e0) + power * z1 * ring.phase
        else:
            c = z1 / z0
            w = (np.exp(-power * ln_e0) + c) * np.exp(power * z0 * ring.phase) - c
        out.append(-np.log(np.maximum(w, 1e-300)) / power)
    return out


def _fit(rings, power: float, x0):
    targets = [np.log(r.envelope) for r in rings]

    def residual(q):
        return np.concatenate([m - t for m, t in zip(_decay_model(q, rings, power), targets)])

    return scipy.optimize.least_squares(residual, x0, method="lm", x_scale="jac")


def _newey_west(J: np.ndarray, r: np.ndarray, pieces, bandwidth: int) -> np.ndarray:
    bread = np.linalg.pinv(J.T @ J)
    scores = J * r[:, None]
    S = np.zeros((J.shape[1],) * 2)
    for piece in pieces:
        s = scores[piece]
        S += s.T @ s
        for lag in range(1, min(bandwidth, len(piece))):
            g = s[lag:].T @ s[:-lag]
            S += (1 - lag / bandwidth) * (g + g.T)
    return bread @ S @ bread


def fit_decay(rings: Iterable[RingDown], correlation_samples: int, slope_sigmas: float = SLOPE_SIGMAS) -> DecayFit:
    """``zeta(E)`` of one mode from its ring-downs (see the module docstring).

    The constant law ``zeta0`` and the laws ``zeta0 + zeta1 E^p`` for each ``p`` of :data:`POWERS` (joint
    micro-slip adds damping as ``E^(chi + 1)``, ``chi`` in (-1, 0]) are fitted.  The laws whose ``zeta1``
    is positive beyond ``slope_sigmas`` (Newey-West) standard errors are the evidence of an
    amplitude-dependent damping (a damping that falls with amplitude is not believed: on a linear rig
    that is what leakage of the band-pass and beats with another mode fake); ``zeta0`` is then their
    mean, and its variance their mean variance plus the variance between them (a ring-down that never
    reaches small amplitudes leaves the laws' extrapolations apart, and ``zeta0`` as uncertain).  When
    none is, the damping is constant.

    Parameters
    ----------
    rings : sequence of RingDown
        At least one.
    correlation_samples : int
        The Newey-West bandwidth (samples): :func:`correlation_time` x the sample rate.
    slope_sigmas : float
        How many standard errors a law's ``zeta1`` must clear to count as evidence.

    Returns
    -------
    DecayFit
    """
    rings = list(rings)
    ln_e0 = [float(np.log(r.envelope[0])) for r in rings]
    pieces, offset = [], 0
    for r in rings:
        pieces.append(offset + np.arange(r.envelope.size))
        offset += r.envelope.size
    stretches = max(int(offset / correlation_samples), 2)
    z_start = float(np.median([-np.polyfit(r.phase, np.log(r.envelope), 1)[0] for r in rings]))
    const = _fit(rings, 0.0, np.array([z_start] + ln_e0))
    cov = _newey_west(const.jac, const.fun, pieces, correlation_samples)
    zeta0, var0, slopes, evidence = float(const.x[0]), float(cov[0, 0]), [], 0.0
    E = np.concatenate([r.envelope for r in rings])
    reach = float(np.percentile(E, 10))           # the smallest amplitude the decays hold well
    left_open = []                                 # what each growing law leaves open at zero amplitude
    if max(float(np.ptp(np.log(r.envelope))) for r in rings) > MIN_LOG_SPAN:
        for p in POWERS:
            scale = float(np.exp(p * np.mean(ln_e0)))
            fit = _fit(rings, p, np.array([0.5 * z_start, 0.5 * z_start / scale] + ln_e0))
            c = _newey_west(fit.jac, fit.fun, pieces, correlation_samples)
            sd = float(np.sqrt(max(c[1, 1], 0.0)))
            if fit.success and sd > 0:          # a damping that grows with amplitude: joints slipping more
                evidence = max(evidence, float(fit.x[1]) / sd)
                left_open.append(sd * reach ** p)
            if fit.success and sd > 0 and fit.x[1] > slope_sigmas * sd:
                slopes.append((p, fit.x, c))
    if not slopes:
        # a constant damping at small amplitude is an extrapolation from the amplitudes the decays reach:
        # as uncertain as a damping growing with amplitude by any law of POWERS, within its own error, would
        # leave it (the square-root law, micro-slip's, leaves the most open at small amplitudes)
        var0 += min(max(left_open, default=np.inf), abs(zeta0)) ** 2
    if slopes:
        z = np.array([x[0] for _, x, _ in slopes])
        zeta0 = float(np.mean(z))
        var0 = float(np.mean([c[0, 0] for _, _, c in slopes]) + (np.var(z, ddof=1) if z.size > 1 else 0.0))
        p, x, c = min(slopes, key=lambda q: abs(q[1][0] - zeta0))
    f = np.concatenate([r.frequency for r in rings])
    A = np.column_stack([np.ones_like(E), E])
    coef, *_ = np.linalg.lstsq(A, f, rcond=None)
    fcov = _newey_west(A, f - A @ coef, pieces, correlation_samples)
    return DecayFit(
        zeta0=zeta0, zeta0_std=float(np.sqrt(max(var0, 0.0))),
        slope=float(x[1]) if slopes else 0.0, slope_std=float(np.sqrt(max(c[1, 1], 0.0))) if slopes else 0.0,
        exponent=float(p) if slopes else 0.0, amplitude_dependent=bool(slopes),
        dof=max(stretches - (2 if slopes else 1), 1), evidence=evidence, frequency0=float(coef[0]),
        frequency_slope=float(coef[1]),
        frequency_slope_std=float(np.sqrt(max(fcov[1, 1], 0.0))),
        amplitude_range=tuple(float(x) for x in np.percentile(E, [10, 90])),
        cycles=float(sum(r.cycles for r in rings)), span=float(np.max(E) / max(float(np.min(E)), 1e-300)),
        rest=min((float(np.min(r.envelope)) / r.noise if r.noise > 0 else np.inf) for r in rings))
