"""Table motions: the prescribed base displacement ``z(t)`` and its derivatives.

:func:`ground_motion` turns a scenario's :data:`~momentid.lab.scenario.Excitation`
into a :class:`GroundMotion` that the simulator evaluates at arbitrary times
(RK4 stage times, sensor sample times), vectorised over any array of times.

* :class:`~momentid.lab.scenario.Harmonics` give an exact analytic ``z``, ``z'``
  and ``z''``; ``z(0)`` and ``z'(0)`` need not be zero (the simulator starts
  the base with velocity ``z'(0)``).
* :class:`~momentid.lab.scenario.RecordedMotion` (a PEER AT2 accelerogram, read by
  :func:`read_at2`), :class:`~momentid.lab.scenario.BandLimitedNoise` and
  :class:`~momentid.lab.scenario.Chirp` go through one processing chain, the one a real shake table needs: samples of
  acceleration -> (record only: scale, zero-phase Butterworth high-pass) ->
  cosine tapers at both ends -> baseline correction -> C2 cubic spline.  The
  baseline correction subtracts ``c0 phi0(t) + c1 phi1(t)``, two ``sin^2``
  ramps over the first and the last ``b`` seconds (``b`` = twice the taper, at
  least :data:`BASELINE_RAMP` s, at most ``T / 2``), the coefficients solved so
  that the *exact* integrals of the spline give ``z'(T) = z(T) = 0``.  The
  spline's exact antiderivatives (taken from 0) are ``z'`` and ``z``, so
  ``z(0) = z'(0) = 0``; for ``t >= T`` (and ``t < 0``) the table is at rest and
  ``z = z' = z'' = 0`` exactly.  Noise is a random-phase multisine with flat
  amplitude on the FFT bins ``k / duration`` inside the band, periodic over the
  run, scaled so that this stationary signal has the requested RMS; the tapers
  and the correction then lower the RMS near the ends only.  A chirp is the
  sine ``A sin(phi(t))`` whose frequency ``phi'(t) / 2 pi`` goes from
  ``f_start`` to ``f_end`` over the run, linearly or exponentially in time.

The acceleration the table applies is therefore the processed one, not the raw
record; the simulator's base sensor records what was applied.

Units are SI throughout: s, m, m/s, m/s^2, Hz; AT2 files hold acceleration in g.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike
from scipy.interpolate import CubicSpline, PPoly
from scipy.signal import butter, sosfiltfilt

from momentid.errors import ScenarioError
from momentid.lab.at2 import MAX_RECORD_G, read_at2
from momentid.lab.scenario import BandLimitedNoise, Chirp, Excitation, Harmonics, RecordedMotion

__all__ = ["GroundMotion", "ground_motion", "read_at2", "MAX_RECORD_G", "STANDARD_GRAVITY", "BASELINE_RAMP"]

#: Standard gravity (m/s^2) used to convert records given in g.
STANDARD_GRAVITY = 9.80665


#: Order of the Butterworth high-pass; applied forward and backward
#: (``sosfiltfilt``), so the magnitude response is squared: -6 dB at the corner.
HIGHPASS_ORDER = 4

#: Samples per period of the band's upper edge on the noise synthesis grid; at
#: 20 the cubic spline reproduces the top of the band to about 1e-4 relative.
NOISE_POINTS_PER_PERIOD = 20

#: Shortest length (s) of the baseline-correction ramps at each end; longer
#: ramps need less acceleration but let the drift grow a little further.
BASELINE_RAMP = 2.0

#: Grid points per shortest period when searching a harmonic motion's peak;
#: every local maximum found is then polished by :data:`_PEAK_NEWTON_STEPS`
#: Newton steps on f' = 0, which converge to round-off from a cell this fine.
_PEAK_POINTS_PER_PERIOD = 32
_PEAK_NEWTON_STEPS = 6

#: Zero padding of the two-way high-pass, in corner periods: the Butterworth's
#: transient has decayed well below the record's round-off after three.
_HIGHPASS_PAD_PERIODS = 3.0

#: Slack when deciding which FFT bins k / duration fall inside the noise band,
#: so that a band edge at exactly k / duration (up to round-off) counts as inside.
_BAND_EDGE_SLACK = 1e-9

# ---------------------------------------------------------------------------
# The motion
# ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class GroundMotion:
    """The prescribed table motion ``z(t)``, defined for every time ``t``.

    Exactly one representation is set: a sum of harmonics
    (``amplitudes``/``angular_frequencies``/``phases``) or piecewise
    polynomials (``pieces``) on ``[0, end]`` with the table at rest outside.

    Attributes
    ----------
    description : str
        One line saying what the motion is (for logs and recordings).
    duration : float
        The time window (s) the motion was built for (the scenario duration).
    end : float
        Time (s) from which the table rests: ``z = z' = z'' = 0`` exactly for
        ``t >= end`` (and for ``t < 0``).  ``math.inf`` for harmonics.
    amplitudes, angular_frequencies, phases : ndarray, shape (m,)
        ``z(t) = sum_j A_j sin(w_j t + phi_j)`` in m, rad/s, rad; empty for a
        piecewise motion.
    pieces : tuple of PPoly or None
        ``(z, z', z'')`` on ``[0, end]`` (m, m/s, m/s^2): a C2 cubic spline of
        acceleration and its exact first and second antiderivatives from 0.
    """

    description: str
    duration: float
    end: float = math.inf
    amplitudes: np.ndarray = field(default_factory=lambda: np.zeros(0))
    angular_frequencies: np.ndarray = field(default_factory=lambda: np.zeros(0))
    phases: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pieces: tuple[PPoly, PPoly, PPoly] | None = None

    def __post_init__(self):
        arrays = []
        for name in ("amplitudes", "angular_frequencies", "phases"):
            a = np.array(getattr(self, name), dtype=float).reshape(-1)
            a.setflags(write=False)
            object.__setattr__(self, name, a)
            arrays.append(a)
        if len({a.size for a in arrays}) != 1:
            raise ValueError("amplitudes, angular_frequencies and phases differ in length")
        if (arrays[0].size > 0) == (self.pieces is not None):
            raise ValueError("a GroundMotion is either harmonic or piecewise (exactly one)")
        if self.pieces is not None and not math.isfinite(self.end):
            raise ValueError("a piecewise GroundMotion needs a finite end time")

    # -- evaluation ---------------------------------------------------------
    def displacement(self, t: ArrayLike) -> np.ndarray:
        """Table displacement ``z(t)``.

        Parameters
        ----------
        t : float or array_like, any shape
            Times (s).

        Returns
        -------
        ndarray, same shape as ``t``
            Displacement (m).
        """
        return self._derivative(0, t)

    def velocity(self, t: ArrayLike) -> np.ndarray:
        """Table velocity ``z'(t)`` (m/s), same shape as ``t`` (s)."""
        return self._derivative(1, t)

    def acceleration(self, t: ArrayLike) -> np.ndarray:
        """Table acceleration ``z''(t)`` (m/s^2), same shape as ``t`` (s)."""
        return self._derivative(2, t)

    def _derivative(self, k: int, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        if self.pieces is None:
            return np.asarray(self._harmonic(k, t))
        out = np.zeros(t.shape)
        inside = (t >= 0.0) & (t < self.end)
        out[inside] = self.pieces[k](t[inside])
        return out

    def _harmonic(self, k: int, t: np.ndarray) -> np.ndarray:
        """k-th derivative (k >= 0) of the harmonic sum at ``t`` (any shape)."""
        w = self.angular_frequencies
        # d^k/dt^k sin(x) = sin(x + k pi / 2)
        arg = np.multiply.outer(t, w) + (self.phases + 0.5 * np.pi * k)
        return np.sin(arg) @ (self.amplitudes * w**k)

    # -- peaks --------------------------------------------------------------
    @property
    def support(self) -> tuple[float, float]:
        """The window ``(0, end)`` (s) the peaks are taken over.

        For harmonics, which never stop, it is ``(0, duration)``.
        """
        return 0.0, (self.end if math.isfinite(self.end) else self.duration)

    @cached_property
    def peak_displacement(self) -> float:
        """Largest ``|z|`` (m) over :attr:`support`."""
        return self._peak(0)

    @cached_property
    def peak_velocity(self) -> float:
        """Largest ``|z'|`` (m/s) over :attr:`support`."""
        return self._peak(1)

    @cached_property
    def peak_acceleration(self) -> float:
        """Largest ``|z''|`` (m/s^2) over :attr:`support`."""
        return self._peak(2)

    def _peak(self, k: int) -> float:
        if self.pieces is not None:
            # Exact: the extremes of a piecewise polynomial lie at breakpoints
            # or at roots of its derivative (the next entry, or the spline's
            # own derivative for the acceleration).
            pp = self.pieces[k]
            slope = self.pieces[k + 1] if k < 2 else pp.derivative()
            roots = slope.roots(discontinuity=False, extrapolate=False)
            cand = np.concatenate([pp.x, roots[np.isfinite(roots)]])
            return float(np.max(np.abs(pp(cand))))
        return self._harmonic_peak(k)

    def _harmonic_peak(self, k: int) -> float:
        # Sample the shortest period finely, then polish every local maximum
        # of |f| with Newton steps on f' = 0 kept inside its grid cell.
        lo, hi = self.support
        period = 2.0 * np.pi / float(np.max(self.angular_frequencies))
        n = max(int(math.ceil((hi - lo) * _PEAK_POINTS_PER_PERIOD / period)), 2)
        t = np.linspace(lo, hi, n + 1)
        h = (hi - lo) / n
        a = np.abs(self._harmonic(k, t))
        i = np.flatnonzero((a[1:-1] >= a[:-2]) & (a[1:-1] >= a[2:])) + 1
        tt = t[i]
        left, right = np.maximum(tt - h, lo), np.minimum(tt + h, hi)
        for _ in range(_PEAK_NEWTON_STEPS):
            d1 = self._harmonic(k + 1, tt)
            d2 = self._harmonic(k + 2, tt)
            step = np.divide(d1, d2, out=np.zeros_like(d1), where=d2 != 0.0)
            tt = np.clip(tt - step, left, right)
        best = float(a.max())
        if tt.size:
            best = max(best, float(np.max(np.abs(self._harmonic(k, tt)))))
        return best


# ---------------------------------------------------------------------------
# Building motions from excitations
# ---------------------------------------------------------------------------
def ground_motion(excitation: Excitation, duration: float) -> GroundMotion:
    """The table motion a scenario's excitation prescribes.

    Parameters
    ----------
    excitation : Harmonics, RecordedMotion, BandLimitedNoise or Chirp
        The scenario's excitation.
    duration : float
        Length (s) of a run.  Noise is synthesised for exactly this long; a
        record keeps its own length (it is neither cut nor padded: the table
        rests after the record ends); harmonics take their peaks over it.

    Returns
    -------
    GroundMotion

    Raises
    ------
    ScenarioError
        On invalid parameters or an unreadable record; the message names the
        file (where there is one), the key and the value.
    """
    if not _finite_positive(duration):
        raise ScenarioError(f"key 'scenario.duration' = {duration!r}: expected a positive number of seconds")
    duration = float(duration)
    if isinstance(excitation, Harmonics):
        return _harmonic_motion(excitation, duration)
    if isinstance(excitation, RecordedMotion):
        return _record_motion(excitation, duration)
    if isinstance(excitation, BandLimitedNoise):
        return _noise_motion(excitation, duration)
    if isinstance(excitation, Chirp):
        return _chirp_motion(excitation, duration)
    raise ScenarioError(
        f"key 'excitation' = {excitation!r}: expected Harmonics, RecordedMotion, BandLimitedNoise or Chirp"
    )


def _harmonic_motion(exc: Harmonics, duration: float) -> GroundMotion:
    cols = {}
    for key, values, check, what in (
        ("amplitudes", exc.amplitudes, _finite_positive, "positive amplitudes (m)"),
        ("angular_frequencies", exc.angular_frequencies, _finite_positive, "positive frequencies (rad/s)"),
        ("phases", exc.phases, _finite, "finite phases (rad)"),
    ):
        arr = np.atleast_1d(np.asarray(values, dtype=float)) if _numeric(values) else None
        if arr is None or arr.ndim != 1 or not all(check(x) for x in arr):
            raise ScenarioError(f"key 'excitation.{key}' = {values!r}: expected a list of {what}")
        cols[key] = arr
    sizes = {k: v.size for k, v in cols.items()}
    if len(set(sizes.values())) != 1 or cols["amplitudes"].size == 0:
        raise ScenarioError(
            f"key 'excitation.phases' = {exc.phases!r}: expected amplitudes, angular_frequencies "
            f"and phases of one common, non-zero length (got {sizes})"
        )
    terms = ", ".join(
        f"{a:g} m at {w / (2 * np.pi):g} Hz" for a, w in zip(cols["amplitudes"], cols["angular_frequencies"])
    )
    return GroundMotion(description=f"harmonic: {terms}", duration=duration, **cols)


def _record_motion(exc: RecordedMotion, duration: float) -> GroundMotion:
    path = Path(exc.path)
    dt, acc_g = read_at2(path)
    def key(name: str) -> str:
        return f"{path}: key 'excitation.{name}'"

    if not _finite_positive(exc.scale):
        raise ScenarioError(f"{key('scale')} = {exc.scale!r}: expected a positive factor")
    nyquist = 0.5 / dt
    if not (_finite(exc.highpass) and 0.0 <= exc.highpass < nyquist):
        raise ScenarioError(
            f"{key('highpass')} = {exc.highpass!r}: expected 0 (off) or a corner in Hz below the "
            f"record's Nyquist frequency {nyquist:g} Hz"
        )
    acc = acc_g * (STANDARD_GRAVITY * float(exc.scale))
    if exc.highpass > 0.0:
        acc = _highpass(acc, dt, float(exc.highpass))
    description = (
        f"record {path.name} x{exc.scale:g} (highpass {exc.highpass:g} Hz, taper {exc.taper:g} s, "
        f"{(acc.size - 1) * dt:g} s)"
    )
    return _table_motion(acc, dt, exc.taper, description, duration, key=key("taper"))


def _noise_motion(exc: BandLimitedNoise, duration: float) -> GroundMotion:
    if not _finite_positive(exc.rms):
        raise ScenarioError(f"key 'excitation.rms' = {exc.rms!r}: expected a positive RMS acceleration (m/s^2)")
    band = tuple(exc.band) if _numeric(exc.band) and np.ndim(exc.band) == 1 else ()
    if len(band) != 2 or not all(_finite_positive(f) for f in band) or not band[0] < band[1]:
        raise ScenarioError(f"key 'excitation.band' = {exc.band!r}: expected [low, high] in Hz with 0 < low < high")
    if isinstance(exc.seed, bool) or not isinstance(exc.seed, (int, np.integer)) or exc.seed < 0:
        raise ScenarioError(f"key 'excitation.seed' = {exc.seed!r}: expected a non-negative integer")
    f_lo, f_hi = float(band[0]), float(band[1])
    # A grid of n intervals over one period T = duration; FFT bins are k / T.
    n = 2 * int(math.ceil(0.5 * NOISE_POINTS_PER_PERIOD * f_hi * duration))
    dt = duration / n
    k_lo = int(math.ceil(f_lo * duration - _BAND_EDGE_SLACK))
    k_hi = int(math.floor(f_hi * duration + _BAND_EDGE_SLACK))
    if k_hi < max(k_lo, 1):
        raise ScenarioError(
            f"key 'excitation.band' = {exc.band!r}: expected a band holding at least one frequency "
            f"k / duration = k * {1.0 / duration:g} Hz"
        )
    k_lo = max(k_lo, 1)
    rng = np.random.default_rng(int(exc.seed))
    phases = rng.uniform(0.0, 2.0 * np.pi, size=k_hi - k_lo + 1)
    spectrum = np.zeros(n // 2 + 1, dtype=complex)
    spectrum[k_lo : k_hi + 1] = np.exp(1j * phases)
    periodic = np.fft.irfft(spectrum, n)
    periodic *= float(exc.rms) / math.sqrt(float(np.mean(periodic**2)))
    acc = np.append(periodic, periodic[0])  # samples at t = 0, dt, ..., duration
    description = (
        f"band-limited noise {exc.rms:g} m/s^2 RMS in [{f_lo:g}, {f_hi:g}] Hz, seed {exc.seed}, "
        f"taper {exc.taper:g} s, {duration:g} s"
    )
    return _table_motion(acc, dt, exc.taper, description, duration, key="key 'excitation.taper'")


def _chirp_motion(exc: Chirp, duration: float) -> GroundMotion:
    if not _finite_positive(exc.amplitude):
        raise ScenarioError(f"key 'excitation.amplitude' = {exc.amplitude!r}: expected a positive acceleration "
                            f"amplitude (m/s^2)")
    for key in ("f_start", "f_end"):
        if not _finite_positive(getattr(exc, key)):
            raise ScenarioError(f"key 'excitation.{key}' = {getattr(exc, key)!r}: expected a positive frequency (Hz)")
    if exc.sweep not in ("linear", "log"):
        raise ScenarioError(f"key 'excitation.sweep' = {exc.sweep!r}: expected 'linear' or 'log'")
    f0, f1 = float(exc.f_start), float(exc.f_end)
    n = 2 * int(math.ceil(0.5 * NOISE_POINTS_PER_PERIOD * max(f0, f1) * duration))
    t = np.linspace(0.0, duration, n + 1)
    if exc.sweep == "linear" or f0 == f1:
        phase = 2 * np.pi * (f0 * t + 0.5 * (f1 - f0) * t ** 2 / duration)
    else:
        rate = math.log(f1 / f0) / duration
        phase = 2 * np.pi * f0 * np.expm1(rate * t) / rate
    acc = float(exc.amplitude) * np.sin(phase)
    description = (f"chirp {exc.amplitude:g} m/s^2 from {f0:g} to {f1:g} Hz ({exc.sweep}), taper {exc.taper:g} s, "
                   f"{duration:g} s")
    return _table_motion(acc, duration / n, exc.taper, description, duration, key="key 'excitation.taper'")


def _highpass(acc: np.ndarray, dt: float, corner: float) -> np.ndarray:
    """Zero-phase Butterworth high-pass of ``acc`` (shape (n,)), zero-padded.

    The zero padding (about three corner periods, at most ten record lengths)
    gives the two-way filter room for its acausal transients; the result is cut
    back to the record's own samples (the taper then brings the ends to rest).
    """
    sos = butter(HIGHPASS_ORDER, corner, btype="highpass", fs=1.0 / dt, output="sos")
    pad = min(int(math.ceil(_HIGHPASS_PAD_PERIODS / (corner * dt))), 10 * acc.size + 100)
    padded = np.concatenate([np.zeros(pad), acc, np.zeros(pad)])
    return sosfiltfilt(sos, padded, padtype=None)[pad : pad + acc.size]


def _table_motion(acc, dt: float, taper, description: str, duration: float, *, key: str) -> GroundMotion:
    """Taper, baseline-correct and interpolate sampled table acceleration.

    Parameters
    ----------
    acc : ndarray, shape (n,)
        Acceleration (m/s^2) at ``t = 0, dt, ..., (n - 1) dt``.
    dt : float
        Sample spacing (s).
    taper : float
        Length (s) of the cosine tapers at both ends; 0 disables them.
    description, duration
        Passed to :class:`GroundMotion`.
    key : str
        Prefix naming the taper key in error messages (``"<file>: key '...'"``).
    """
    n = acc.size
    t = np.arange(n) * dt
    T = float(t[-1])
    if not (_finite(taper) and 0.0 <= taper <= 0.5 * T):
        raise ScenarioError(
            f"{key} = {taper!r}: expected a length in s between 0 and half the motion ({0.5 * T:g} s)"
        )
    acc = acc * _cosine_taper(t, float(taper))
    ramp = min(max(2.0 * float(taper), BASELINE_RAMP), 0.5 * T)
    acc = _baseline_corrected(t, acc, ramp)
    spline = CubicSpline(t, acc, bc_type="clamped")
    velocity = spline.antiderivative(1)
    displacement = spline.antiderivative(2)
    return GroundMotion(description=description, duration=duration, end=T,
                        pieces=(displacement, velocity, spline))


def _cosine_taper(t: np.ndarray, length: float) -> np.ndarray:
    """Window, shape of ``t``: rises as ``(1 - cos(pi t / L)) / 2`` over the
    first ``L`` s, mirrored over the last ``L`` s, 1 in between."""
    w = np.ones_like(t)
    if length > 0.0:
        T = t[-1]
        for s in (t, T - t):
            ramp = s < length
            w[ramp] *= 0.5 * (1.0 - np.cos(np.pi * s[ramp] / length))
    return w


def _baseline_corrected(t: np.ndarray, acc: np.ndarray, ramp: float) -> np.ndarray:
    """``acc - c0 phi0 - c1 phi1`` whose clamped cubic spline ends at rest.

    ``phi0 = sin^2(pi t / b)`` on ``[0, b]`` and its mirror image ``phi1`` on
    ``[T - b, T]`` (zero elsewhere) vanish with their slopes at both ends, so
    the taper's zeros survive.  ``phi0`` gives the table, while it ramps in, the
    constant velocity offset that cancels the record's linear displacement
    drift; ``phi1`` removes what velocity is left as it ramps out.  (One smooth
    function over the whole record instead would bend the drift into a bow
    about twice as large: 0.42 m against 0.21 m of stroke for El Centro.)
    The spline is linear in its samples, so the exact end velocity
    ``int_0^T S`` and end displacement ``int_0^T (T - s) S(s) ds`` of the three
    splines (record and two basis functions, one vector-valued spline) give
    ``c0, c1`` from a 2x2 solve (determinant ``(b/2)^2 (b - T)``, non-zero).

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times (s), uniform, starting at 0.
    acc : ndarray, shape (n,)
        Acceleration samples (m/s^2).
    ramp : float
        Length ``b`` (s) of the two basis functions, ``0 < b <= T / 2``.

    Returns
    -------
    ndarray, shape (n,)
        Corrected acceleration samples (m/s^2).
    """
    T = t[-1]
    phi0 = np.where(t < ramp, np.sin(np.pi * np.minimum(t, ramp) / ramp) ** 2, 0.0)
    phi1 = phi0[::-1]
    spline = CubicSpline(t, np.column_stack([acc, phi0, phi1]), bc_type="clamped")
    v_end = spline.antiderivative(1)(T)  # shape (3,)
    z_end = spline.antiderivative(2)(T)
    basis = np.array([[v_end[1], v_end[2]], [z_end[1], z_end[2]]])
    c = np.linalg.solve(basis, [v_end[0], z_end[0]])
    return acc - c[0] * phi0 - c[1] * phi1


# ---------------------------------------------------------------------------
# Small checks
# ---------------------------------------------------------------------------
def _numeric(value) -> bool:
    try:
        np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return False
    return True


def _finite(x) -> bool:
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, bool) and math.isfinite(x)


def _finite_positive(x) -> bool:
    return _finite(x) and x > 0
