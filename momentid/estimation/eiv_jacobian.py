"""The errors-in-variables residual's exact sensitivities: one pass in place of a column per unknown.

:func:`momentid.estimation.eiv.whitened_residual` is ``r = P W (Y - G U - T beta)`` per run: the model's
response ``G`` at each DFT bin, its transient term ``T`` (coefficients ``beta`` projected out by ``P``)
and the whitening ``W = (I + phi g g^H) / s_y``.  Its forward differences cost one residual per unknown
(16 for 3 storeys, 36 for 5), and the fit takes one such Jacobian per iteration.  Here every column
comes from one evaluation of the model:

* ``Phi, G1, G2`` (the first-order-hold discretisation) are blocks of one matrix exponential ``exp(Z h)``;
  their derivative along each unknown is its Fréchet derivative (``scipy.linalg.expm_frechet``);
* the resolvent's derivative is ``(zI - Phi)^-1 dPhi (zI - Phi)^-1``, evaluated in the modal basis the
  residual already uses;
* the whitening's derivative follows ``g`` (Pintelon & Schoukens, ch. 10), and ``beta`` is held fixed
  (Kaufman's variable-projection Jacobian, as :mod:`momentid.estimation.modal_model` does): its
  gradient ``J^T r`` is the exact gradient, and where the residual is noise it is the exact Jacobian.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from momentid.estimation.bins import Spectra
from momentid.estimation.layout import Layout
from momentid.estimation.linear import discretize

__all__ = ["whitened_jacobian"]

#: Singular values of the scaled transient columns below this share of the largest are dropped, as the
#: residual's least squares on the normal equations drops theirs (``rcond=1e-12`` of the squares).
_RCOND = 1e-6


def whitened_jacobian(layout: Layout, theta: np.ndarray, sp: Spectra) -> np.ndarray:
    """Jacobian of :func:`~momentid.estimation.eiv.whitened_residual` at ``theta`` (Kaufman's form).

    Parameters
    ----------
    layout : momentid.estimation.layout.Layout
    theta : ndarray, shape (p,) or (p + m,)
        Parameters (plus the coefficients of ``sp``'s ``m`` force signals when it carries them).
    sp : Spectra
        One run's spectra.

    Returns
    -------
    ndarray, shape (2 bins n_out, theta.size)
        Rows in the residual's order (real parts of every bin and output, then imaginary parts).

    Raises
    ------
    IdentificationError
        When the model at ``theta`` cannot be discretised (as the residual raises).
    """
    theta = np.asarray(theta, float)
    m = _Model(layout, theta, sp)
    cols, terms = [], np.zeros((m.Q.shape[1], theta.size))
    for i in range(layout.p):
        column, terms[:, i] = m.column(_directions(layout, i, sp.added_mass))
        cols.append(column)
    for k in range(theta.size - layout.p):                     # a force signal's coefficient: linear
        cols.append(m.whiten(-m.Gf[:, :, k] * sp.F[None, :, k].T))
    J = np.sqrt(2.0) * np.concatenate([np.array([c.real.ravel() for c in cols]),
                                       np.array([c.imag.ravel() for c in cols])], axis=1).T
    return J - m.Q @ (m.Q.T @ J - terms)       # the second projection terms -Q c_i of every column at once


def _directions(layout: Layout, i: int, added_mass: np.ndarray):
    """``(dM, dC, dK)`` of the run's model (added mass included) along unknown ``i``."""
    e = np.zeros(layout.p)
    e[i] = 1.0
    dM, dC, dK, dmu = layout.unpack(e)
    return dM, dC + dmu * np.diag(added_mass), dK


class _Model:
    """One run's model, response, whitening and projection at ``theta``: what every column reuses."""

    def __init__(self, layout: Layout, theta: np.ndarray, sp: Spectra):
        d, h = layout.d, sp.h
        M, C, K, mu = layout.unpack(theta[:layout.p])
        dm = np.diag(sp.added_mass)
        self.M, self.C, self.K = M + dm, C + mu * dm, K
        model = discretize(self.M, self.C, self.K, h)          # raises for a model that cannot be simulated
        forces = sp.forces if sp.F is not None else np.zeros((d, 0))
        self.d, self.h, self.sp, self.forces = d, h, sp, forces
        self.Minv = np.linalg.inv(self.M)
        self.A = np.vstack([np.hstack([np.zeros((d, d)), np.eye(d)]), model.out_a])
        nw = 1 + forces.shape[1]
        Bc = np.zeros((2 * d, nw))
        Bc[d:, 0] = -1.0
        Bc[d:, 1:] = self.Minv @ forces
        self.nw = nw
        self.Zh = self._block(self.A, Bc) * h
        E = scipy.linalg.expm(self.Zh)
        self.Phi, self.G2 = E[:2 * d, :2 * d], E[:2 * d, 2 * d + nw:]
        self.Bd = self.Phi @ self.G2 / h + E[:2 * d, 2 * d:2 * d + nw] - self.G2 / h
        self.lam, self.V = np.linalg.eig(self.Phi)
        self.Vinv = np.linalg.inv(self.V)
        self.H = self._rows(self.A[d:], True)
        self.Dc = self._rows(self.Minv @ forces, False)
        self.inv_sd = 1.0 / sp.sigma_y
        self.R = 1.0 / (sp.z[:, None] - self.lam[None, :])     # (bins, 2d)
        self.HV = self.H @ self.V
        VB = self.Vinv @ self.Bd
        Gall = np.einsum("oj,mj,jw->mow", self.HV, self.R, VB) + (self.H @ self.G2 / h + np.hstack(
            [np.zeros((self.H.shape[0], 1)), self.Dc]))[None]
        Gall = Gall * self.inv_sd[None, :, None]
        self.g, self.Gf, self.VB = Gall[:, :, 0], Gall[:, :, 1:], VB
        e = sp.Y * self.inv_sd[None, :] - self.g * sp.U[:, None]
        if forces.shape[1]:
            e = e - np.einsum("mok,mk->mo", self.Gf, sp.F * theta[layout.p:][None, :])
        self.coef_f = theta[layout.p:]
        self._whitening(sp)
        T = np.einsum("oj,mj,jl->mol", self.HV, self.R * sp.z[:, None], self.Vinv) * self.inv_sd[None, :, None]
        self.T, self.T_conj = T, np.conj(T)
        self._project(e, T)

    @staticmethod
    def _block(A: np.ndarray, Bc: np.ndarray, slope: float = 1.0) -> np.ndarray:
        """``Z`` of the first-order hold (``exp(Z h)`` holds ``Phi``, ``G1`` and ``G2``); ``slope`` 0 for a
        derivative of ``Z`` (its input-slope block is a constant)."""
        n, nw = A.shape[0], Bc.shape[1]
        Z = np.zeros((n + 2 * nw, n + 2 * nw))
        Z[:n, :n], Z[:n, n:n + nw] = A, Bc
        Z[n:n + nw, n + nw:] = slope * np.eye(nw)
        return Z

    def _rows(self, a_block: np.ndarray, state: bool) -> np.ndarray:
        """Rows per output group: ``a_block`` for ``'a'``; for ``'q'`` and ``'v'`` the state's rows
        (``state``) or zeros (a derivative, or a force's direct term)."""
        d = self.d
        rest = np.eye(2 * d) if state else np.zeros((2 * d, a_block.shape[1]))
        pick = {"q": rest[:d], "v": rest[d:], "a": a_block}
        return np.vstack([pick[g] for g in self.sp.groups])

    def _whitening(self, sp: Spectra) -> None:
        s_u = sp.sigma_u ** 2
        q = np.sqrt(1.0 + s_u * np.sum(np.abs(self.g) ** 2, axis=1))
        self.phi = -s_u / (q * (1.0 + q))
        self.dphi = s_u ** 2 * (1.0 + 2.0 * q) / (2.0 * q ** 3 * (1.0 + q) ** 2)   # d phi / d |g|^2

    def whiten(self, x: np.ndarray) -> np.ndarray:
        """``(I + phi g g^H) x`` per bin (``x`` already divided by the noise levels), shape of ``x``."""
        proj = np.einsum("mo,mo...->m...", np.conj(self.g), x)
        return x + (self.phi[:, None] * self.g)[(...,) + (None,) * (x.ndim - 2)] * proj[:, None]

    def _project(self, e: np.ndarray, T: np.ndarray) -> None:
        """The transient's orthonormal basis ``Q`` and coefficients ``beta``; ``v``, ``g^H v`` with them fixed."""
        ew = self.whiten(e)
        rw = np.sqrt(2.0) * np.concatenate([ew.real.ravel(), ew.imag.ravel()])
        Tw = self.whiten(T)
        B = np.sqrt(2.0) * np.concatenate([Tw.real.reshape(-1, T.shape[2]), Tw.imag.reshape(-1, T.shape[2])])
        norms = np.linalg.norm(B, axis=0)
        norms[norms == 0] = 1.0
        U, s, Vt = np.linalg.svd(B / norms, full_matrices=False)
        keep = s > _RCOND * max(float(s[0]), 1e-300) if s.size else s > 0
        self.Q = U[:, keep]
        self._pinv = (s[keep], Vt[keep], norms)
        beta = (Vt[keep].T @ ((self.Q.T @ rw) / s[keep])) / norms
        self.gamma = self.Vinv @ beta.astype(complex)          # the transient in modal coordinates
        self.v = e - np.einsum("mol,l->mo", T, beta)
        self.gv = np.einsum("mo,mo->m", np.conj(self.g), self.v)
        # the projected residual rho (complex, as rw = sqrt 2 [Re, Im]) and what the columns' second
        # variable-projection term (Golub & Pereyra) reuses
        rest = rw - self.Q @ (self.Q.T @ rw)
        n = rest.size // 2
        rho = ((rest[:n] + 1j * rest[n:]) / np.sqrt(2.0)).reshape(e.shape)
        self.rho_s = self.whiten(rho) * self.inv_sd[None, :]    # W rho, per unit of the unscaled outputs
        self.rho_hv = self.rho_s @ np.conj(self.HV)              # (bins, 2d)
        self.g_rho = np.einsum("mo,mo->m", np.conj(self.g), rho)
        self.rho = rho
        self.T_g = np.einsum("mol,mo->ml", np.conj(T), self.g)   # T^H g per bin

    def transient_term(self, dH: np.ndarray, W: np.ndarray, dg: np.ndarray) -> np.ndarray:
        """Golub and Pereyra's second term ``-B^+T dB^T r`` of a column (``B`` the whitened transient
        columns, ``r`` the projected residual) as ``Q c``: its coefficients ``c`` on the transient's
        orthonormal basis ``Q``, shape (n_keep,)."""
        rz = np.conj(self.R * self.sp.z[:, None])
        inner = (rz * (self.rho_s @ np.conj(dH @ self.V))).sum(axis=0)
        inner = inner + (rz * ((np.conj(self.R) * self.rho_hv) @ np.conj(W))).sum(axis=0)
        inner = inner @ np.conj(self.Vinv)                      # sum over bins of dT^H W rho
        gdg = np.sum(np.conj(self.g) * dg, axis=1)
        T_dg = (dg[:, None, :] @ self.T_conj)[:, 0, :]            # T^H dg per bin
        dW = (self.dphi * 2.0 * gdg.real * self.g_rho)[:, None] * self.T_g + self.phi[:, None] * (
            T_dg * self.g_rho[:, None] + self.T_g * np.sum(np.conj(dg) * self.rho, axis=1)[:, None])
        x = 2.0 * (inner + dW.sum(axis=0)).real                  # dB^T r
        s, Vt, norms = self._pinv
        return -(Vt @ (x / norms)) / s

    def column(self, directions) -> tuple[np.ndarray, np.ndarray]:
        """Along one direction of ``(M, C, K)``: ``d(W v)`` with ``beta`` fixed, shape (bins, n_out), and the
        column's second projection term's coefficients on ``Q`` (:meth:`transient_term`), shape (n_keep,)."""
        dM, dC, dK = directions
        d, h, sp = self.d, self.h, self.sp
        lower = -self.Minv @ (np.hstack([dK, dC]) + dM @ self.A[d:])
        dA = np.vstack([np.zeros((d, 2 * d)), lower])
        dF = -self.Minv @ dM @ self.Minv @ self.forces          # d(M^-1 forces)
        dBc = np.zeros((2 * d, self.nw))
        dBc[d:, 1:] = dF
        dE = scipy.linalg.expm_frechet(self.Zh, self._block(dA, dBc, 0.0) * h, compute_expm=False)
        nw = self.nw
        dPhi, dG1, dG2 = dE[:2 * d, :2 * d], dE[:2 * d, 2 * d:2 * d + nw], dE[:2 * d, 2 * d + nw:]
        dBd = dPhi @ self.G2 / h + self.Phi @ dG2 / h + dG1 - dG2 / h
        dH = self._rows(lower, False)
        dD = dH @ self.G2 / h + self.H @ dG2 / h + np.hstack([np.zeros((dH.shape[0], 1)),
                                                               self._rows(dF, False)])
        W = self.Vinv @ dPhi @ self.V
        X = self.R[:, :, None] * self.VB[None]                  # (bins, 2d, nw): R V^-1 Bd
        Y = self.R[:, :, None] * (W @ X + (self.Vinv @ dBd)[None])          # matmul per bin
        dG = ((dH @ self.V) @ X + self.HV @ Y + dD[None]) * self.inv_sd[None, :, None]
        t = self.R * sp.z[:, None] * self.gamma[None, :]         # (bins, 2d): R z V^-1 beta
        dTb = (t @ (dH @ self.V).T + (self.R * (t @ W.T)) @ self.HV.T) * self.inv_sd[None, :]
        dg = dG[:, :, 0]
        term = self.transient_term(dH, W, dg)
        dv = -dg * sp.U[:, None] - dTb
        if nw > 1:
            dv = dv - (dG[:, :, 1:] @ (sp.F * self.coef_f[None, :])[:, :, None])[:, :, 0]
        gdg = np.sum(np.conj(self.g) * dg, axis=1)
        kappa = self.dphi * 2.0 * gdg.real * self.gv + self.phi * np.sum(np.conj(dg) * self.v, axis=1)
        return self.whiten(dv) + self.g * kappa[:, None] + self.phi[:, None] * dg * self.gv[:, None], term
