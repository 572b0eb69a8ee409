"""Sensor noise levels: the one estimator every identification uses.

The errors-in-variables and output-error fits weight each channel by its noise
level, so the level must come from somewhere that holds noise only.  Three
sources, tried in this order:

``stated``
    The lab states the noise standard deviation per channel group
    (:class:`~momentid.core.structure.LabStatement` ``noise``).
``quiet lead-in``
    Real recordings start before the table moves: the seconds of rest at the
    start hold sensor noise (and, on a floor, perhaps the last ringing of the
    previous trial, a few spectral lines that the median over bins ignores).
``high band``
    A sample rate far above the structure's band (simulated 1 kHz data) leaves
    a band between ``3 f_max`` and 0.8 x Nyquist that holds noise only.

``the data's own scatter``
    A record that shakes from its first sample at 60-200 Hz has neither.  The
    floors' response is then a smooth function of the table's between
    neighbouring DFT bins (the local polynomial method of Pintelon et al.,
    *IEEE Trans. Instrum. Meas.* 59(5), 2010): per bin, each floor's bins
    within +-:data:`LPM_HALF_WIDTH` are fitted by a frequency response and a
    transient, both linear in frequency, and what they scatter beyond that is the
    floor sensor's noise (median over the band: the few bins at a lightly
    damped resonance, where the response is not smooth, do not move it).  The
    table's own noise is not seen this way; it is taken as the floors' median
    (sensors of one kind), and the estimate says so.  On a rig that is not
    linear the scatter also holds its distortion (10-50x the sensor noise on
    the shipped rigs): an upper bound, which weights the fit correctly but
    hides the quietest part of a free decay.

Every estimate says which source it used.

Levels are the standard deviation of white noise in the channel's SI unit,
which is also the RMS of one DFT bin normalised by ``sqrt(N)``.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from enum import Enum

import numpy as np
import scipy.signal
import scipy.stats

from momentid.core.series import RunData
from momentid.errors import IdentificationError

__all__ = ["NoiseSource", "NoiseEstimate", "estimate_noise", "band_level", "windowed_dft", "quiet_lead_in",
           "quietest_level",
           "local_polynomial_noise",
           "high_band_noise", "HIGH_BAND_FACTOR"]


class NoiseSource(Enum):
    """Where a noise level came from."""

    STATED = "stated"
    QUIET_LEAD_IN = "quiet lead-in"
    HIGH_BAND = "high band"
    LOCAL_POLYNOMIAL = "the data's own scatter"


#: The noise-only band starts at this multiple of the top frequency fitted (the
#: response of a lightly damped structure has fallen ~(1/3)^2 x ... below its
#: peak there) ...
HIGH_BAND_FACTOR = 3.0
#: ... and ends at this fraction of Nyquist, below the anti-alias roll-off.
HIGH_BAND_TOP = 0.8
#: Fewer DFT bins than this give a noise level uncertain by more than ~20 %.
MIN_BINS = 20
#: Window (s) of the moving RMS that finds where the table starts to move.
LEAD_IN_WINDOW = 0.25
#: A record has a lead-in when its first :data:`MIN_LEAD_IN` seconds are below
#: this fraction of the record's active level (the 90th percentile of the
#: moving RMS): a shake test drives the table to at least 5x its noise at rest.
LEAD_IN_QUIET_RATIO = 0.2
#: The table has started once its moving RMS exceeds this multiple of the rest
#: level (a 0.25 s window of noise alone scatters by ~15 %, never by 3x).
LEAD_IN_START_FACTOR = 3.0
#: Margin (s) dropped before the detected start: the first motion builds up.
LEAD_IN_MARGIN = 0.25
#: A lead-in shorter than this is not used (too few bins, or no rest at all).
MIN_LEAD_IN = 1.0
#: Half-width (bins) of the local polynomial fits: 9 bins against 4 complex unknowns (frequency
#: response and transient, each with its slope) leave 5 degrees of freedom per bin.
LPM_HALF_WIDTH = 4
#: The local polynomial band, as fractions of the sample rate: above the table's slow drift, below the
#: anti-alias roll-off.
LPM_BAND = (0.02, 0.45)


@dataclass(frozen=True)
class NoiseEstimate:
    """Noise standard deviation of every channel of one run.

    Attributes
    ----------
    sigma : dict of str to float
        Channel name to noise standard deviation (channel's SI unit).
    source : NoiseSource
    detail : str
        Human-readable: which seconds or band, e.g. ``"quiet lead-in 0-9.0 s"``.
    """

    sigma: dict
    source: NoiseSource
    detail: str


def band_level(X: np.ndarray, band: slice | np.ndarray) -> np.ndarray:
    """Noise RMS per column from DFT bins holding noise only.

    Robust to a few spectral lines: the median of ``|X|^2`` over the bins is
    ``sigma^2 ln 2`` for complex Gaussian noise.

    Parameters
    ----------
    X : ndarray, shape (bins, columns), complex
        DFT normalised so that white noise of standard deviation sigma has
        ``E|X|^2 = sigma^2``.
    band : slice or boolean mask over the bins

    Returns
    -------
    ndarray, shape (columns,)
    """
    power = np.abs(X[band]) ** 2
    return np.sqrt(np.median(power, axis=0) / np.log(2.0))


def windowed_dft(values: np.ndarray) -> np.ndarray:
    """Hann-windowed DFT normalised to the noise standard deviation, shape (bins, columns).

    The window keeps the leakage of a segment that does not end at rest out of the noise bins.
    """
    n = values.shape[0]
    w = np.hanning(n)
    return np.fft.rfft(values * w[:, None], axis=0) / np.sqrt(np.sum(w ** 2))


def quietest_level(run: RunData, channel: str, seconds: float = 1.0) -> float:
    """The noise level one channel cannot exceed: its level (:func:`band_level`) in its quietest stretch.

    Sensor noise is there all the time, so no stretch of the record reads less; where the channel
    moves least (a table between bursts, or at rest after the shaking) the level is nearly noise only.

    Parameters
    ----------
    run : RunData
    channel : str
        The channel's name (``"zdd"``, ...).
    seconds : float
        Length (s) of the stretches compared.

    Returns
    -------
    float
        The lowest level (the channel's SI unit) over consecutive stretches; ``inf`` when the record is
        shorter than one stretch.
    """
    n = int(seconds * run.sample_rate)
    x = run[channel]
    if n < MIN_BINS or x.size < n:
        return float("inf")
    chunks = np.stack([x[a:a + n] - np.mean(x[a:a + n]) for a in range(0, x.size - n + 1, n)], axis=1)
    freq = np.fft.rfftfreq(n, 1.0 / run.sample_rate)
    return float(np.min(band_level(windowed_dft(chunks), freq > 2.0 * run.sample_rate / n)))


def high_band_noise(run: RunData, low: float, high: float) -> dict | None:
    """Noise level of every channel from the bins in ``[low, high)`` Hz, or None if too few."""
    freq = np.fft.rfftfreq(run.n_samples, 1.0 / run.sample_rate)
    band = (freq >= low) & (freq < high)
    if np.count_nonzero(band) < MIN_BINS:
        return None
    level = band_level(windowed_dft(run.values), band)
    return dict(zip(run.channels, map(float, level)))


def quiet_lead_in(run: RunData, channel: str = "zdd") -> int:
    """Number of samples at the start of ``run`` before ``channel`` (the table) moves.

    Returns 0 when the record has no quiet start of at least :data:`MIN_LEAD_IN`
    seconds.
    """
    if not run.has(channel):
        return 0
    x = run[channel] - np.median(run[channel][: max(int(MIN_LEAD_IN * run.sample_rate), 1)])
    width = max(int(round(LEAD_IN_WINDOW * run.sample_rate)), 1)
    if run.n_samples < 4 * width:
        return 0
    moving = np.sqrt(np.convolve(x ** 2, np.ones(width) / width, mode="valid"))
    active = float(np.percentile(moving, 90))
    rest = float(np.sqrt(np.mean(x[: int(MIN_LEAD_IN * run.sample_rate)] ** 2)))
    if rest >= LEAD_IN_QUIET_RATIO * active:
        return 0
    loud = np.flatnonzero(moving > LEAD_IN_START_FACTOR * rest)
    if loud.size == 0:
        return 0
    end = int(loud[0]) - int(round(LEAD_IN_MARGIN * run.sample_rate))
    return end if end >= MIN_LEAD_IN * run.sample_rate else 0


def local_polynomial_noise(run: RunData) -> dict | None:
    """Noise level of every floor channel from the scatter between neighbouring DFT bins (see the module
    docstring), and of the table taken as theirs; None when the record is too short or has no floors.

    Returns
    -------
    dict of str to float
        Channel name to noise standard deviation (the channel's SI unit).
    """
    floors = [c for c in run.channels if c != "zdd" and c[:1] == "a"]
    if not run.has("zdd") or not floors:
        return None
    n, fs = run.n_samples, run.sample_rate
    U = np.fft.rfft(run["zdd"]) / np.sqrt(n)
    freq = np.fft.rfftfreq(n, 1.0 / fs)
    centres = np.flatnonzero((freq > LPM_BAND[0] * fs) & (freq < LPM_BAND[1] * fs))
    w = LPM_HALF_WIDTH
    centres = centres[(centres >= w) & (centres < freq.size - w)]
    if centres.size < MIN_BINS:
        return None
    r = np.arange(-w, w + 1)
    rows = centres[:, None] + r[None, :]                   # (bins, 2w+1): each centre's neighbourhood
    A = np.empty((centres.size, r.size, 4), complex)
    A[:, :, 0], A[:, :, 1], A[:, :, 2], A[:, :, 3] = U[rows], r * U[rows], 1.0, r
    Ainv = np.linalg.pinv(A)                               # least squares per bin, all bins at once
    dof = 2 * (r.size - 4)                                 # real degrees of freedom of each bin's scatter
    out = {}
    for c in floors:
        b = (np.fft.rfft(run[c]) / np.sqrt(n))[rows]
        coef = np.einsum("bkj,bj->bk", Ainv, b)
        res = b - np.einsum("bjk,bk->bj", A, coef)
        # the scatter holds the floor's noise and the table's through the response G: with sensors
        # of one kind, sigma^2 (1 + |G|^2)
        level = np.sum(np.abs(res) ** 2, axis=1) / (r.size - A.shape[2]) / (1 + np.abs(coef[:, 0]) ** 2)
        out[c] = float(np.sqrt(np.median(level) / (scipy.stats.chi2.median(dof) / dof)))
    out["zdd"] = float(np.median([out[c] for c in floors]))
    return out


#: A lead-in is rest only when no floor's level there exceeds this multiple of the record's own scatter
#: (:func:`local_polynomial_noise`, an upper bound on the noise: it also holds a rig's distortion; its
#: median over hundreds of bins scatters by a few %) ...
REST_BOUND = 1.5
#: ... and the table and each floor share less than this coherence there (median over frequency): sensor
#: noise is independent from sensor to sensor, motion is not (a lull between two bursts of shaking, where a
#: window of a record may start, is motion; a short rest's median coherence is ~0.1).
REST_COHERENCE = 0.5


def _not_rest(run: RunData, n_quiet: int, level: dict, bound: dict | None) -> str:
    """Why the record's first ``n_quiet`` samples, quiet as they look, hold motion and not sensor noise
    ('' when they are rest): a floor's level above the record's own scatter ``bound``
    (:func:`local_polynomial_noise`, None when the record is too short for it), or table and floor coherent."""
    floors = [c for c in run.channels if c != "zdd" and c[:1] == "a"]
    if not run.has("zdd") or not floors:
        return ""
    for c in floors:
        if bound is not None and level[c] > REST_BOUND * bound[c]:
            return (f" (its first {n_quiet / run.sample_rate:.3g} s are quiet but not at rest: {c} reads "
                    f"{level[c]:.3g} there, {level[c] / bound[c]:.2g}x the record's own scatter)")
        x = run.values[:n_quiet]
        C = scipy.signal.coherence(x[:, run.channels.index("zdd")], x[:, run.channels.index(c)],
                                   nperseg=max(min(64, n_quiet // 4), 8))[1]
        share = float(np.median(C[1:]))
        if share > REST_COHERENCE:
            return (f" (its first {n_quiet / run.sample_rate:.3g} s are quiet but not at rest: the table and {c} "
                    f"move together there, coherence {share:.2f})")
    return ""


def estimate_noise(run: RunData, *, f_max: float | None = None,
                   stated: Iterable[tuple[str, float]] | dict | None = None,
                   noise_floor: tuple[float, float] | None = None) -> NoiseEstimate:
    """Noise standard deviation of every channel of ``run``, and where it came from.

    Parameters
    ----------
    run : RunData
    f_max : float, optional
        Top of the band the fit uses (Hz); the high band starts at
        :data:`HIGH_BAND_FACTOR` x ``f_max``.  Without it the high band is
        0.25-0.45 of the sample rate.
    stated : sequence of (group, sigma) or dict, optional
        The lab's stated levels per channel group (``"zdd"``, ``"a"``, ...) or
        channel (``"a1"``); used when every channel is covered.
    noise_floor : (low, high), optional
        Force the high band to these frequencies (Hz).

    Raises
    ------
    IdentificationError
        No source applies: no stated level, no quiet lead-in and no band above
        the structure's response (say a 120 Hz record that starts shaking at once).
    """
    stated = dict(stated or {})
    if stated:
        sigma = {c: stated.get(c, stated.get(c.rstrip("0123456789"))) for c in run.channels}
        if all(s is not None for s in sigma.values()):
            return NoiseEstimate({c: float(s) for c, s in sigma.items()}, NoiseSource.STATED,
                                 "stated by the lab")
    fs = run.sample_rate
    not_rest, scatter = "", None
    if noise_floor is None:
        n_quiet = quiet_lead_in(run)
        if n_quiet:
            X = windowed_dft(run.values[:n_quiet] - np.mean(run.values[:n_quiet], axis=0))
            freq = np.fft.rfftfreq(n_quiet, 1.0 / fs)
            # Skip the lowest bins: drift and the mean removed there are not white noise.
            band = freq > 2.0 * fs / n_quiet
            level = dict(zip(run.channels, map(float, band_level(X, band))))
            scatter = local_polynomial_noise(run)           # the bound a rest may not exceed
            not_rest = _not_rest(run, n_quiet, level, scatter)
            if not not_rest:
                return NoiseEstimate(level, NoiseSource.QUIET_LEAD_IN, f"quiet lead-in 0-{n_quiet / fs:.3g} s")
    low, high = noise_floor or ((HIGH_BAND_FACTOR * f_max, HIGH_BAND_TOP * fs / 2) if f_max
                                else (0.25 * fs, 0.45 * fs))
    sigma = high_band_noise(run, low, high)
    if sigma is None and noise_floor is None:
        scatter = scatter if scatter is not None else local_polynomial_noise(run)
        if scatter is not None:
            return NoiseEstimate(scatter, NoiseSource.LOCAL_POLYNOMIAL,
                                 f"no quiet lead-in{not_rest}, no band above the structure: the floors' scatter "
                                 "between neighbouring frequencies (local polynomial; with any distortion of a rig "
                                 "that is not linear), the table taken as noisy as the floors")
    if sigma is None:
        band = (f"fewer than {MIN_BINS} DFT bins between {low:.3g} and {high:.3g} Hz" if low < high else
                f"no band above the structure's response ({low:.3g} Hz, {HIGH_BAND_FACTOR:g} x its highest "
                f"mode) below {high:.3g} Hz")
        raise IdentificationError(
            f"run {run.name!r}: no source for the sensor noise level: no stated level (experiment.toml "
            f"[noise]), no quiet lead-in of at least {MIN_LEAD_IN:g} s before the table moves, and {band} "
            f"at {fs:.4g} Hz sampling: expected one of them (record a few seconds of rest before shaking)")
    return NoiseEstimate(sigma, NoiseSource.HIGH_BAND, f"high band {low:.3g}-{high:.3g} Hz")
