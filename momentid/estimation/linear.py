"""Exact discrete-time simulation of the linear shear model driven by the table.

For output-error identification, Cramér-Rao bounds and model-vs-recording
comparison, the model ``M q'' + C q' + K q = -M 1 z''`` is simulated from a
*measured* table acceleration: far faster than re-running MuJoCo, and exact
for an input that is linear between samples (first-order hold).

State ``x = [q, q']``; ``x_(k+1) = Phi x_k + G1 u_k + G2 (u_(k+1) - u_k) / h``
with ``Phi, G1, G2`` from one matrix exponential.  In modal coordinates each
mode is a first-order complex recursion evaluated by ``scipy.signal.lfilter``.
Outputs: ``q`` (relative displacement), ``v`` (relative velocity) and
``a = -(M)^-1 (C v + K q)`` (absolute floor acceleration).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
import scipy.linalg
import scipy.signal

from momentid.errors import IdentificationError

__all__ = ["LinearModel", "discretize", "simulate_linear", "MAX_EIGENVALUE_STEP"]


@dataclass(frozen=True)
class LinearModel:
    """A discretised model (modal form) for one run's M, C, K and step h."""

    d: int
    h: float
    lam: np.ndarray      # (2d,) discrete eigenvalues
    V: np.ndarray        # (2d, 2d) eigenvectors
    b0: np.ndarray       # (2d,) modal input weights of u_k
    b1: np.ndarray       # (2d,) modal input weights of u_(k-1)
    out_a: np.ndarray    # (d, 2d) acceleration output matrix on x
    Phi: np.ndarray      # (2d, 2d) state transition over one step
    G1: np.ndarray       # (2d,) input matrix of u_k
    G2: np.ndarray       # (2d,) input matrix of the slope (u_(k+1) - u_k) / h


#: Largest ``|lambda| h`` (a continuous eigenvalue times the step) of a model worth discretising: a
#: mode 50 / (2 pi) ~ 8 times faster than the sample rate is no model of sampled data, and an
#: unstable one that fast overflows ``exp(A h)`` to inf (then NaN, then LAPACK errors downstream).
MAX_EIGENVALUE_STEP = 50.0


def _state_matrix(M, C, K, h: float):
    """``(M^-1, A)`` of ``x' = A x`` (x = [q, q']), or :class:`IdentificationError` for a model that is
    absurd (non-finite, singular mass, or a mode far beyond the sample rate): a trial step of an
    optimiser is rejected here, with a reason, before it reaches ``expm`` or LAPACK."""
    d = M.shape[0]
    if not (np.all(np.isfinite(M)) and np.all(np.isfinite(C)) and np.all(np.isfinite(K))):
        raise IdentificationError("model has non-finite entries in M, C or K: cannot simulate it")
    try:
        Minv = np.linalg.inv(M)
    except np.linalg.LinAlgError:
        raise IdentificationError("mass matrix is singular: cannot simulate the model") from None
    A = np.zeros((2 * d, 2 * d))
    A[:d, d:] = np.eye(d)
    A[d:, :d] = -Minv @ K
    A[d:, d:] = -Minv @ C
    if not np.all(np.isfinite(A)):
        raise IdentificationError("mass matrix is nearly singular (M^-1 K or M^-1 C overflows): cannot "
                                  "simulate the model")
    fastest = float(np.max(np.abs(np.linalg.eigvals(A)))) * h
    if not fastest <= MAX_EIGENVALUE_STEP:
        raise IdentificationError(f"model has a mode with |lambda| h = {fastest:.3g} (above "
                                  f"{MAX_EIGENVALUE_STEP:g}): far faster than the sample rate, so it is no "
                                  f"model of these data")
    return Minv, A


def _expm(Zh: np.ndarray) -> np.ndarray:
    """``exp(Zh)``, or :class:`IdentificationError` when it overflows (a model unstable over one step)."""
    with np.errstate(over="raise", invalid="raise"):
        try:
            E = scipy.linalg.expm(Zh)
        except FloatingPointError:
            E = np.full_like(Zh, np.inf)
    if not np.all(np.isfinite(E)):
        raise IdentificationError("model overflows over one sample step (unstable): cannot simulate it")
    return E


def discretize(M: ArrayLike, C: ArrayLike, K: ArrayLike, h: float) -> LinearModel:
    """Discretise ``M q'' + C q' + K q = -M 1 u`` with step ``h`` (s)."""
    M, C, K = (np.asarray(X, float) for X in (M, C, K))
    d = M.shape[0]
    Minv, A = _state_matrix(M, C, K, h)
    Z = np.zeros((2 * d + 2, 2 * d + 2))
    Z[:2 * d, :2 * d] = A
    Z[d:2 * d, 2 * d] = -1.0
    Z[2 * d, 2 * d + 1] = 1.0
    E = _expm(Z * h)
    Phi, G1, G2 = E[:2 * d, :2 * d], E[:2 * d, 2 * d], E[:2 * d, 2 * d + 1]
    lam, V = np.linalg.eig(Phi)
    if np.linalg.cond(V) > 1e10:
        raise IdentificationError("model has (nearly) repeated modes; cannot use the modal simulator")
    g1 = np.linalg.solve(V, G1.astype(complex))
    g2 = np.linalg.solve(V, G2.astype(complex))
    return LinearModel(d=d, h=h, lam=lam, V=V, b0=g2 / h, b1=g1 - g2 / h, out_a=A[d:, :],
                       Phi=Phi, G1=G1, G2=G2)


def force_response(M: ArrayLike, C: ArrayLike, K: ArrayLike, h: float, forces: np.ndarray, H_rows: np.ndarray,
                   z: np.ndarray, lam: np.ndarray, V: np.ndarray, groups: Sequence[str]) -> np.ndarray:
    """DFT-domain response to generalised floor forces ``forces`` (d, m), FOH between samples.

    ``M, C, K`` (d, d) in kg, N s/m, N/m; ``h`` the sample interval (s); ``H_rows`` (n_out, 2d) the output
    rows (:func:`output_matrix` of ``groups``); ``z`` (bins,) the DFT points; ``lam``, ``V`` the
    eigenvalues (2d,) and eigenvectors (2d, 2d) of the discretised model's transition matrix
    (:func:`discretize`).  Returns ``Gf`` of shape (bins, n_out, m): outputs per unit force signal
    (absolute accelerations include the direct term ``M^-1 f``).
    """
    M, C, K = (np.asarray(X, float) for X in (M, C, K))
    d = M.shape[0]
    Minv, A = _state_matrix(M, C, K, h)
    m = forces.shape[1]
    Bf = np.zeros((2 * d, m))
    Bf[d:] = Minv @ forces
    Z = np.zeros((2 * d + 2 * m, 2 * d + 2 * m))
    Z[:2 * d, :2 * d] = A
    Z[:2 * d, 2 * d:2 * d + m] = Bf
    Z[2 * d:2 * d + m, 2 * d + m:] = np.eye(m)
    E = _expm(Z * h)
    Phi, G1, G2 = E[:2 * d, :2 * d], E[:2 * d, 2 * d:2 * d + m], E[:2 * d, 2 * d + m:]
    B = Phi @ G2 / h + G1 - G2 / h
    # Acceleration rows of H include the direct force term M^-1 f: D = H G2 / h covers the FOH part;
    # the absolute acceleration output a = out_a x + M^-1 f needs the force itself at the sample.
    HV = H_rows @ V
    Vinv = np.linalg.inv(V)
    R = 1.0 / (z[:, None] - lam[None, :])
    direct = np.vstack([Minv @ forces if g == "a" else np.zeros((d, m)) for g in groups])
    G = np.einsum("oj,mj,jk->mok", HV, R, Vinv @ B, optimize=True) + (H_rows @ G2 / h + direct)[None]
    return G


def frequency_response(model: LinearModel, H: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact DFT-domain response of the discretised model.

    With ``s_k = x_k - G2 u_k / h`` the model is the discrete state space
    ``s_(k+1) = Phi s_k + B u_k``, ``y_k = H s_k + D u_k``, and the DFT of any
    finite record obeys ``Y(z) = G(z) U(z) + T(z) (s_0 - s_N)`` exactly, with
    ``G(z) = H (zI - Phi)^-1 B + D`` and ``T(z) = H (zI - Phi)^-1 z``.

    Parameters
    ----------
    H : ndarray, shape (n_out, 2d)
        Output rows on the state (see :func:`output_matrix`).
    z : ndarray, shape (m,)
        Points ``exp(2 pi i k / N)`` of the DFT bins used.

    Returns
    -------
    G : ndarray, shape (m, n_out), complex
    T : ndarray, shape (m, n_out, 2d), complex
    """
    h = model.h
    B = model.Phi @ model.G2 / h + model.G1 - model.G2 / h
    D = H @ model.G2 / h
    HV = H @ model.V                                   # (n_out, 2d)
    Vinv = np.linalg.inv(model.V)
    VB = Vinv @ B                                      # (2d,)
    R = 1.0 / (z[:, None] - model.lam[None, :])        # (m, 2d) modal resolvent
    G = (R * VB[None, :]) @ HV.T + D[None, :]
    T = np.einsum("oj,mj,jl->mol", HV, R * z[:, None], Vinv, optimize=True)
    return G, T


def simulate_linear(model: LinearModel, u: np.ndarray, x0: ArrayLike | None = None) -> np.ndarray:
    """States ``x_k = [q_k, v_k]`` for input samples ``u`` (m/s^2).

    Parameters
    ----------
    model : LinearModel
    u : ndarray, shape (n,)
        Table acceleration at the sample times.
    x0 : ndarray, shape (2d,), optional
        Initial state (zero: at rest relative to the table).

    Returns
    -------
    ndarray, shape (n, 2d)
    """
    u = np.asarray(u, float)
    n = u.shape[0]
    xi0 = (np.zeros(model.lam.size, complex) if x0 is None
           else np.linalg.solve(model.V, np.asarray(x0, complex)))
    xi = np.empty((n, model.lam.size), dtype=complex)
    xi[0] = xi0
    for j, lam in enumerate(model.lam):
        # Transposed direct form: the state after sample 0 is b1 u_0 + lam xi_0.
        zi = [model.b1[j] * u[0] + lam * xi0[j]]
        xi[1:, j], _ = scipy.signal.lfilter([model.b0[j], model.b1[j]], [1.0, -lam], u[1:], zi=zi)
    return np.real(xi @ model.V.T)


def output_matrix(model: LinearModel, groups: Iterable[str]) -> np.ndarray:
    """Rows mapping the state to the output groups (``'q'``, ``'v'``, ``'a'``), stacked."""
    d = model.d
    rows = {"q": np.eye(2 * d)[:d], "v": np.eye(2 * d)[d:], "a": model.out_a}
    return np.vstack([rows[g] for g in groups])


def outputs(model: LinearModel, x: np.ndarray) -> dict[str, np.ndarray]:
    """``q``, ``v`` (relative) and ``a`` (absolute) from states, each (n, d)."""
    d = model.d
    return {"q": x[:, :d], "v": x[:, d:], "a": x @ model.out_a.T}
