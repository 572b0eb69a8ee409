"""The table motions a scenario can ask for, as frozen dataclasses (``[excitation]``).

:mod:`momentid.lab.scenario` parses them (and re-exports them); :mod:`momentid.lab.excitation`
turns them into the prescribed table displacement.  SI units: m, s, Hz, rad/s, m/s^2.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

__all__ = ["Harmonics", "RecordedMotion", "BandLimitedNoise", "Chirp", "Tracking", "Excitation"]


@dataclass(frozen=True)
class Harmonics:
    """``z(t) = sum_j A_j sin(w_j t + phi_j)`` (m, rad/s, rad)."""

    amplitudes: tuple[float, ...]
    angular_frequencies: tuple[float, ...]
    phases: tuple[float, ...]


@dataclass(frozen=True)
class RecordedMotion:
    """A recorded accelerogram turned into a table motion.

    Attributes
    ----------
    path : Path
        The record file (PEER AT2, acceleration in g).
    scale : float
        Factor applied to the recorded acceleration.
    highpass : float
        Corner (Hz) of the zero-phase high-pass that keeps the table stroke
        bounded; 0 disables it.
    taper : float
        Length (s) of the cosine tapers at both ends.
    """

    path: Path
    scale: float = 1.0
    highpass: float = 0.1
    taper: float = 1.0


@dataclass(frozen=True)
class BandLimitedNoise:
    """Seeded band-limited random table acceleration.

    ``rms`` is the RMS acceleration (m/s^2) over the band ``band`` (Hz).
    """

    rms: float
    band: tuple[float, float]
    seed: int
    taper: float = 1.0


@dataclass(frozen=True)
class Chirp:
    """A swept sine of table acceleration: ``amplitude`` (m/s^2), its frequency swept from ``f_start``
    to ``f_end`` (Hz) over the run, ``"linear"`` or ``"log"`` in time, with cosine tapers of ``taper``
    (s) at both ends."""

    amplitude: float
    f_start: float
    f_end: float
    sweep: str = "linear"
    taper: float = 1.0


Excitation = Harmonics | RecordedMotion | BandLimitedNoise | Chirp


@dataclass(frozen=True)
class Tracking:
    """Run-to-run table error: the servo never repeats a motion exactly.

    Every run's table acceleration is the nominal one plus its own seeded
    band-limited random error of RMS ``error`` x (nominal RMS acceleration)
    in ``band`` (Hz).
    """

    error: float
    band: tuple[float, float] = (0.5, 20.0)
