"""The analytic shear-building model: M, C, K, Rayleigh coefficients, modes.

Vocabulary (used across momentid): ``d`` storeys, floor 1 = lowest; ``M``,
``C``, ``K`` are ``(d, d)`` arrays in kg, N*s/m and N/m; ``mu`` (1/s) and
``kappa`` (s) are the Rayleigh coefficients of ``C = mu M + kappa K``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
import scipy.linalg

from momentid.errors import ScenarioError

__all__ = [
    "Modes",
    "shear_stiffness",
    "rayleigh_coefficients",
    "modal_properties",
]


def shear_stiffness(storey_stiffness: ArrayLike) -> np.ndarray:
    """Stiffness matrix of a shear building.

    Parameters
    ----------
    storey_stiffness : array_like, shape (d,)
        Storey stiffnesses k_1..k_d in N/m; storey 1 joins the base and floor 1.

    Returns
    -------
    K : ndarray, shape (d, d)
        ``K[i, i] = k_i + k_(i+1)``, ``K[i, i+1] = -k_(i+1)`` (N/m).
    """
    k = np.asarray(storey_stiffness, dtype=float)
    d = k.size
    K = np.zeros((d, d))
    for i in range(d):
        K[i, i] += k[i]
        if i > 0:
            K[i - 1, i - 1] += k[i]
            K[i - 1, i] -= k[i]
            K[i, i - 1] -= k[i]
    return K


@dataclass(frozen=True)
class Modes:
    """Modal properties of ``M q'' + C q' + K q = 0``, sorted by frequency.

    Attributes
    ----------
    frequency : ndarray, shape (d,)
        Undamped natural frequencies (Hz) from ``K phi = w^2 M phi``.
    damping_ratio : ndarray, shape (d,)
        Damping ratios from the complex eigenvalues of the damped system
        (``zeta = -Re(lambda) / |lambda|``); exact for non-proportional C too.
    damped_frequency : ndarray, shape (d,)
        ``|Im(lambda)| / 2 pi`` (Hz).
    shapes : ndarray, shape (d, d)
        Mass-normalised undamped mode shapes, one per column.
    """

    frequency: np.ndarray
    damping_ratio: np.ndarray
    damped_frequency: np.ndarray
    shapes: np.ndarray


def modal_properties(M: ArrayLike, C: ArrayLike, K: ArrayLike) -> Modes:
    """Natural frequencies and damping ratios of a (possibly identified) model.

    Parameters
    ----------
    M, C, K : array_like, shape (d, d)
        Mass (kg), damping (N*s/m) and stiffness (N/m) matrices.

    Returns
    -------
    Modes
        Undamped natural frequencies (Hz) in increasing order, damping
        ratios and damped frequencies (Hz) of the complex modes, and mode
        shapes, shape (d, d), one column per mode.
    """
    M = np.asarray(M, float)
    C = np.asarray(C, float)
    K = np.asarray(K, float)
    d = M.shape[0]
    Ms = 0.5 * (M + M.T)
    Ks = 0.5 * (K + K.T)
    try:
        w2, phi = scipy.linalg.eigh(Ks, Ms)
    except np.linalg.LinAlgError:
        w2, phi = np.linalg.eig(np.linalg.solve(Ms, Ks))
        w2, phi = np.real(w2), np.real(phi)
    order = np.argsort(w2)
    w2, phi = w2[order], phi[:, order]
    freq = np.sqrt(np.clip(w2, 0.0, None)) / (2 * np.pi)
    # Complex modes of the first-order form x' = A x.
    A = np.zeros((2 * d, 2 * d))
    A[:d, d:] = np.eye(d)
    A[d:, :d] = -np.linalg.solve(M, K)
    A[d:, d:] = -np.linalg.solve(M, C)
    lam = np.linalg.eigvals(A)
    lam = lam[np.imag(lam) >= 0] if np.sum(np.imag(lam) > 0) == d else lam
    lam = lam[np.argsort(np.abs(lam))][:d]
    mag = np.abs(lam)
    zeta = np.where(mag > 0, -np.real(lam) / np.where(mag > 0, mag, 1), 0.0)
    return Modes(
        frequency=freq,
        damping_ratio=zeta,
        damped_frequency=np.abs(np.imag(lam)) / (2 * np.pi),
        shapes=phi,
    )


def rayleigh_coefficients(M: ArrayLike, K: ArrayLike, damping_ratios: Sequence[float],
                          modes: tuple[int, int] = (1, 2), *, file: str = "<scenario>",
                          key: str = "structure.damping") -> tuple[float, float]:
    """Rayleigh ``mu`` (1/s) and ``kappa`` (s) giving two modes chosen ratios.

    Solves ``zeta_r = mu / (2 w_r) + kappa w_r / 2`` for the two modes
    ``modes`` (1-based, 1 = lowest frequency).

    Parameters
    ----------
    M, K : array_like, shape (d, d)
        Mass (kg) and stiffness (N/m) matrices.
    damping_ratios : sequence of 2 floats
        Target damping ratios of the two modes (dimensionless).
    modes : pair of int
        The two mode numbers, 1-based.
    file, key : str
        Where the request came from, named in the error message.

    Returns
    -------
    mu : float
        Mass-proportional coefficient (1/s).
    kappa : float
        Stiffness-proportional coefficient (s).

    Raises
    ------
    ScenarioError
        The mode numbers are not two different modes of the model.
    """
    w = 2 * np.pi * modal_properties(M, np.zeros_like(M), K).frequency
    d = len(w)
    r, s = modes
    if not (1 <= r <= d and 1 <= s <= d and r != s):
        raise ScenarioError(
            f"{file}: key '{key}.modes' = {list(modes)!r}: expected two different mode numbers in 1..{d}"
        )
    wr, ws = w[r - 1], w[s - 1]
    A = np.array([[1 / (2 * wr), wr / 2], [1 / (2 * ws), ws / 2]])
    mu, kappa = np.linalg.solve(A, np.asarray(damping_ratios, float))
    return float(mu), float(kappa)
