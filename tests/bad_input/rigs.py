"""Simulated accelerometer records of shake-table rigs, for tests of the import path.

A rig is a shear building (masses, storey stiffnesses, one damping ratio for every mode) on a table
whose acceleration is band-limited noise; optionally with one extra mode (torsion or out-of-plane
motion leaking into the shaking axis) that the storeys do not explain.  Floor ``j``'s absolute
acceleration is ``zdd + sum_i R_ij eta_i''`` with ``eta_i'' + 2 zeta_i w_i eta_i' + w_i^2 eta_i = -zdd``
(``R_ij = Gamma_i phi_ji``), evaluated by ``scipy.signal.lsim`` (first-order hold).  Sensors add
white noise, a gain and an offset of their own.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
from scipy import signal


@dataclass(frozen=True)
class Rig:
    """A shear building on a shake table.

    ``extra`` is ``(frequency Hz, damping ratio, residues per floor)`` of a mode beyond the storeys.
    """

    masses: tuple[float, ...]
    stiffness: tuple[float, ...]
    damping: float = 0.01
    extra: tuple[float, float, tuple[float, ...]] | None = None

    @property
    def storeys(self) -> int:
        return len(self.masses)

    def modes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(frequencies Hz (m,), damping ratios (m,), residues R (m, d)), storey modes first."""
        M = np.diag(self.masses)
        k = np.asarray(self.stiffness, float)
        d = k.size
        K = np.diag(k + np.append(k[1:], 0.0)) - np.diag(k[1:], 1) - np.diag(k[1:], -1)
        w2, phi = scipy.linalg.eigh(K, M)
        gamma = phi.T @ M @ np.ones(d)  # mass-normalised shapes: Gamma_i = phi_i^T M 1
        freq = np.sqrt(w2) / (2 * np.pi)
        zeta = np.full(d, self.damping)
        R = gamma[:, None] * phi.T
        if self.extra is not None:
            f, z, r = self.extra
            freq, zeta, R = np.append(freq, f), np.append(zeta, z), np.vstack([R, r])
        return freq, zeta, R


@dataclass(frozen=True)
class Sensors:
    """What the accelerometers add: noise std (m/s^2), per-floor gains and offsets (table first)."""

    noise: float = 0.005
    gains: tuple[float, ...] = ()
    offsets: tuple[float, ...] = ()
    seed: int = 0
    extra_noise: dict = field(default_factory=dict)


def table_motion(n: int, rate: float, rms: float = 0.5, seed: int = 0, band=(0.3, None)) -> np.ndarray:
    """Band-limited noise (m/s^2) from ``band[0]`` Hz to 0.4 x the sample rate, ramped in and out."""
    rng = np.random.default_rng(seed)
    high = band[1] or 0.4 * rate
    sos = signal.butter(4, (band[0], high), btype="band", fs=rate, output="sos")
    x = signal.sosfilt(sos, rng.standard_normal(n + 2000))[2000:]
    ramp = np.minimum(1.0, np.minimum(np.arange(n), np.arange(n)[::-1]) / (2.0 * rate))
    x = x * ramp
    return rms * x / np.sqrt(np.mean(x ** 2))


def record(rig: Rig, rate: float, duration: float, sensors: Sensors = Sensors(), zdd=None) -> np.ndarray:
    """Absolute accelerations (n, 1 + d): the table, then floors 1..d, as the sensors read them."""
    n = int(round(duration * rate))
    zdd = table_motion(n, rate, seed=sensors.seed) if zdd is None else zdd
    t = np.arange(n) / rate
    freq, zeta, R = rig.modes()
    out = np.tile(zdd[:, None], (1, 1 + rig.storeys))
    for f, z, r in zip(freq, zeta, R):
        w = 2 * np.pi * f
        _, eta_dd, _ = signal.lsim(([-1.0, 0.0, 0.0], [1.0, 2 * z * w, w * w]), zdd, t)
        out[:, 1:] += eta_dd[:, None] * r[None, :]
    rng = np.random.default_rng(sensors.seed + 1000)
    c = out.shape[1]
    gains = np.asarray(sensors.gains or (1.0,) * c)
    offsets = np.asarray(sensors.offsets or (0.0,) * c)
    return gains * out + offsets + sensors.noise * rng.standard_normal(out.shape)
