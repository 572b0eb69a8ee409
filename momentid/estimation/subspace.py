"""An input-output subspace estimate of the modes: start values and an independent check.

The modal fit of :mod:`momentid.estimation.modal` is a nonlinear likelihood; it needs a start near its
optimum and, for every damping ratio it reports, a second opinion from the same data by another
method.  Both come from here: the past-output MOESP subspace method (Verhaegen 1994; the family of
SRIM and N4SID), applied to the table acceleration (input) and the floor accelerations (outputs) in
the time domain:

1. block Hankel matrices of ``i`` past and ``i`` future samples of input and outputs;
2. the lower-triangular factor ``L`` of their stacked Gram matrix (the LQ factorisation's, computed
   as a Cholesky factor of one ``8 i x 8 i``-sized product: milliseconds for a two-minute record);
3. the SVD of the block of ``L`` relating future outputs to past data, with the future inputs
   projected out, gives the extended observability matrix; its shift invariance gives ``A``;
4. the eigenvalues of ``A`` at every model order are the poles; a pole is a resonance when it is
   found with the same frequency (:data:`STABLE_FREQUENCY`) at :data:`MIN_ORDERS` or more model orders
   (a stabilisation diagram), and its damping ratio is an estimate when it also stays within
   :data:`STABLE_DAMPING` of its median over those orders (:attr:`StablePole.damping_stable`).

Output noise does not bias it (the past outputs are instruments); table noise slightly does, which is
why it only starts and checks the errors-in-variables fit.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import scipy.linalg

__all__ = ["StablePole", "poles_by_order", "stable_poles", "STABLE_FREQUENCY", "STABLE_DAMPING", "MIN_ORDERS"]

#: A pole is the same resonance at two model orders when its frequency agrees within this fraction, ...
STABLE_FREQUENCY = 0.01
#: ... a resonance when so found at this many model orders, ...
MIN_ORDERS = 3
#: ... and its damping ratio an estimate when it stays within this fraction of its median.
STABLE_DAMPING = 0.3
#: Poles with a damping ratio outside this range are noise or drift, not structural modes (slightly
#: negative ones count: a lightly damped, weakly excited mode scatters about zero at some orders).
DAMPING_RANGE = (-0.01, 0.2)
#: A fit starts from a pole's damping ratio clipped to this range.
START_DAMPING_RANGE = (5e-4, 0.1)
#: Extra state dimensions (beyond two per expected mode) of the highest order tried: noise and
#: unmodelled dynamics take some, and a mode missed at low orders appears there.
EXTRA_ORDERS = 10
#: Block rows per past and future horizon: at least this many, and enough for the highest order.
MIN_HORIZON = 12
MAX_HORIZON = 40


@dataclass(frozen=True)
class StablePole:
    """A pole found at several model orders (medians over them).

    Attributes
    ----------
    frequency : float
        Undamped natural frequency ``|lambda| / 2 pi`` (Hz).
    damping_ratio : float
        ``-Re(lambda) / |lambda|``.
    orders : int
        Model orders at which it was found.
    damping_spread : float
        Relative spread of its damping ratio over those orders: interquartile range over median (the
        lowest orders, where noise takes a mode's place, do not count).
    """

    frequency: float
    damping_ratio: float
    orders: int
    damping_spread: float

    @property
    def start_damping(self) -> float:
        """The damping ratio a fit may start from (clipped to :data:`START_DAMPING_RANGE`)."""
        return float(np.clip(self.damping_ratio, *START_DAMPING_RANGE))

    @property
    def damping_stable(self) -> bool:
        """The damping ratio is positive and its spread over the orders within :data:`STABLE_DAMPING`."""
        return self.damping_ratio > 0 and self.damping_spread <= STABLE_DAMPING


def _hankel(x: np.ndarray, start: int, rows: int, cols: int) -> np.ndarray:
    """Block Hankel matrix of ``x`` (n, c): block row ``k`` holds ``x[start + k + j]`` for j < cols."""
    c = x.shape[1]
    out = np.empty((rows * c, cols))
    for k in range(rows):
        out[k * c:(k + 1) * c] = x[start + k:start + k + cols].T
    return out


def poles_by_order(u: np.ndarray, y: np.ndarray, dt: float, orders: Iterable[int], horizon: int | None = None
                   ) -> list[np.ndarray]:
    """Continuous-time poles of the MOESP model at each state order.

    Parameters
    ----------
    u : ndarray, shape (n,)
        Input (table acceleration, m/s^2).
    y : ndarray, shape (n, l)
        Outputs (floor accelerations, m/s^2).
    dt : float
        Sample interval (s).
    orders : sequence of int
        State dimensions (even: two per mode).
    horizon : int, optional
        Block rows of the past and of the future.

    Returns
    -------
    list of ndarray
        Per order, the poles with positive imaginary part (rad/s, complex).
    """
    u = np.asarray(u, float)[:, None]
    y = np.asarray(y, float)
    u = u - u.mean(axis=0)
    y = y - y.mean(axis=0)
    outs = y.shape[1]
    n_max = max(orders)
    i = horizon or int(np.clip(np.ceil(2 * n_max / outs) + 2, MIN_HORIZON, MAX_HORIZON))
    j = u.shape[0] - 2 * i + 1
    if j < 4 * i * (1 + outs):
        return [np.zeros(0, complex) for _ in orders]
    scale_u, scale_y = np.std(u) or 1.0, np.std(y, axis=0)
    scale_y[scale_y == 0] = 1.0
    u, y = u / scale_u, y / scale_y
    H = np.vstack([_hankel(u, i, i, j), _hankel(u, 0, i, j), _hankel(y, 0, i, j), _hankel(y, i, i, j)])
    gram = H @ H.T / j
    gram += 1e-10 * np.trace(gram) / gram.shape[0] * np.eye(gram.shape[0])
    L = scipy.linalg.cholesky(gram, lower=True)
    fu, past = i, 2 * i + i * outs
    L32 = L[past:, fu:past]
    U, s, _ = np.linalg.svd(L32, full_matrices=False)
    out = []
    for n in orders:
        if n > U.shape[1]:
            out.append(np.zeros(0, complex))
            continue
        gamma = U[:, :n] * np.sqrt(s[:n])[None, :]
        A = np.linalg.lstsq(gamma[:-outs], gamma[outs:], rcond=None)[0]
        z = np.linalg.eigvals(A)
        z = z[(np.abs(z) > 1e-12) & (z.imag > 0)]
        out.append(np.log(z) / dt)
    return out


def stable_poles(u: np.ndarray, y: np.ndarray, dt: float, n_modes: int, f_max: float) -> list:
    """Modes stable over model orders, ascending in frequency.

    Parameters
    ----------
    u, y, dt
        As :func:`poles_by_order`.
    n_modes : int
        Modes expected (the storeys); orders ``2 n_modes`` .. ``2 n_modes + EXTRA_ORDERS`` are tried.
    f_max : float
        Highest frequency of interest (Hz).

    Returns
    -------
    list of StablePole
    """
    orders = list(range(2 * n_modes, 2 * n_modes + EXTRA_ORDERS + 1, 2))
    found = []
    for lam in poles_by_order(u, y, dt, orders):
        f = np.abs(lam) / (2 * np.pi)
        zeta = -lam.real / np.maximum(np.abs(lam), 1e-300)
        keep = (f < f_max) & (zeta > DAMPING_RANGE[0]) & (zeta < DAMPING_RANGE[1])
        found.append(np.column_stack([f[keep], zeta[keep]]))
    clusters: list[list] = []
    for poles in found:
        used = set()
        for f, z in poles:
            best, gap = None, STABLE_FREQUENCY
            for c, cluster in enumerate(clusters):
                g = abs(f / np.median([p[0] for p in cluster]) - 1)
                if c not in used and g < gap:
                    best, gap = c, g
            if best is None:
                clusters.append([(f, z)])
                used.add(len(clusters) - 1)
            else:
                clusters[best].append((f, z))
                used.add(best)
    out = []
    for cluster in clusters:
        if len(cluster) < MIN_ORDERS:
            continue
        c = np.array(cluster)
        zm = float(np.median(c[:, 1]))
        q25, q75 = np.percentile(c[:, 1], [25, 75])
        out.append(StablePole(float(np.median(c[:, 0])), zm, len(cluster), float((q75 - q25) / max(abs(zm), 1e-12))))
    return sorted(out, key=lambda p: p.frequency)
