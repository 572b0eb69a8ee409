"""The modal model of table-to-floor accelerations and its errors-in-variables likelihood.

Floor sensor ``j`` of run ``r`` reads, per unit table acceleration, at angular frequency ``w``::

    G_j(w) = g_rj exp(-i w tau_rj) (1 - sum_i R_ij H_i(w)),   H_i = s^2 / (s^2 + 2 zeta_i w_i s + w_i^2),

``s = i w``: ``n`` classical normal modes (``n >= d``, the storeys' and any extra mode's), each with an
undamped frequency ``w_i``, a damping ratio ``zeta_i`` and residues ``R_ij`` (participation x shape
on floor ``j``), and per run the floor sensors' gains ``g`` and clock offsets ``tau`` relative to the
table sensor.

**Band-limited, not held.**  A real accelerometer low-passes before it samples, and so does the lab's
sensor model; the table motion is then band-limited, not linear between samples, so the response at
a DFT bin is the continuous-time ``G(i w_k)`` (Pintelon & Schoukens, *System Identification*, ch. 6).
A first-order-hold discretisation assumes a piecewise-linear input instead; the two differ by a phase
that grows with ``w h``, which near 40 % of the sample rate bends a mode's damping by tens of percent.
The transient (the record's start and end state, the leakage of a finite record) is a sum of the
modes' free decays, sampled exactly: per mode ``c / (1 - p z^-1) + conj``, ``p = exp(lambda_i h)``, two
real coefficients per mode and run, shared by the floors through ``R_ij``, projected out.  A floor
sensor ``tau_j`` late reads those decays ``tau_j`` later: ``c exp(-lambda_i tau_j)``, a constant per mode
and floor (the forced part's delay ``exp(-i w tau_j)`` would spread a record's ringing end over every
bin and misfit by twice the noise).

**Likelihood.**  Per bin, the residual ``e = Y - G U - T beta`` has covariance
``diag(s_y^2) + s_u^2 G G^H`` (floor noise plus table noise through the model); the cost is the sum of
``e^H C^-1 e``, minimised over the parameters with ``beta`` eliminated (variable projection).  The
Jacobian is analytic (Kaufman's variable-projection form): one evaluation costs about two of the
residual, not one per parameter.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from enum import Enum

import numpy as np
from numpy.typing import ArrayLike

from momentid.estimation.eiv import Spectra

__all__ = ["ModalModel", "Likelihood", "Hold", "mode_response", "MAX_ABS_DAMPING", "OFFSET_BOUND", "GAIN_RANGE"]

#: Clock offsets are bounded to this many samples: separately clocked sensors aligned by the import sit
#: within a sample of the table's clock, and a wider offset trades with the damping ratios.
OFFSET_BOUND = 1.5
#: Gains are bounded to this range (a floor sensor reading half or twice the table is not a gain error).
GAIN_RANGE = (0.5, 2.0)
#: Damping ratios are bounded to ``(-MAX_ABS_DAMPING, 1 - ...)``: an unstable fit still shows (negative),
#: but never one past critical where the mode has no frequency.
MAX_ABS_DAMPING = 0.5


class ModalModel:
    """Parameter vector of ``n`` classical normal modes seen by ``d`` floor accelerometers.

    ``theta = [log w (n, rad/s), zeta (n), R (n x d: row i = mode i, column j = floor j),
    then per run: log g (d), tau (d, s)]``.

    ``g_j`` and ``tau_j`` are floor sensor j's gain and clock offset relative to the table sensor in
    that run (real accelerometers differ in gain by a percent or two; separately clocked devices are
    synchronised to about a sample).  They are separable from the modes: the gain is the response at
    low frequency, the offset a phase linear in frequency, the damping a phase change local to its
    resonance.

    Parameters
    ----------
    d : int
        Storeys (= floor accelerometers).
    n_runs : int
        Runs fitted together (each gets its own sensor gains and clock offsets).
    extra : int
        Modes beyond the ``d`` storey modes (``n = d + extra``).
    quadrature : sequence of int
        Modes with non-classical damping: besides ``R_ij`` they get a quadrature residue ``Q_ij``
        (their contribution is ``s^2 (R_ij + Q_ij s / w_i) / (s^2 + 2 zeta_i w_i s + w_i^2)``, a complex
        mode's), stored after the residues (``theta = [.., R, Q (c x d), sensors]``).  Two modes closer
        than their half-power bands whose damping differs (an appendage tuned near a storey mode) are
        complex modes; a classical fit of them bends their damping ratios.
    """

    def __init__(self, d: int, n_runs: int = 1, extra: int = 0, quadrature=()):
        self.d = d
        self.n_runs = n_runs
        self.n = d + extra
        self.quadrature = tuple(sorted(int(i) for i in quadrature))
        self.n_modal = 2 * self.n + (self.n + len(self.quadrature)) * d
        self.p = self.n_modal + 2 * d * n_runs

    def omega(self, theta: np.ndarray) -> np.ndarray:
        """Undamped angular frequencies (rad/s), shape (n,)."""
        return np.exp(theta[:self.n])

    def zeta(self, theta: np.ndarray) -> np.ndarray:
        """Damping ratios, shape (n,)."""
        return np.asarray(theta[self.n:2 * self.n], float)

    @property
    def residue_slice(self) -> slice:
        """Where ``R`` (n x d, row-major) sits in theta."""
        return slice(2 * self.n, 2 * self.n + self.n * self.d)

    def residues(self, theta: np.ndarray) -> np.ndarray:
        """``R``, shape (n modes, d floors)."""
        return np.asarray(theta[self.residue_slice], float).reshape(self.n, self.d)

    def quadrature_residues(self, theta: np.ndarray) -> np.ndarray:
        """``Q``, shape (n modes, d floors): zero rows for the classical modes."""
        Q = np.zeros((self.n, self.d))
        Q[list(self.quadrature)] = np.asarray(theta[2 * self.n + self.n * self.d:self.n_modal]).reshape(-1, self.d)
        return Q

    def sensor_slice(self, run: int) -> slice:
        """Where run ``run``'s ``log g`` (d) then ``tau`` (d) sit in theta."""
        start = self.n_modal + 2 * self.d * run
        return slice(start, start + 2 * self.d)

    def sensors(self, theta: np.ndarray, run: int) -> tuple[np.ndarray, np.ndarray]:
        """Gains (1) and clock offsets (s) of the floor sensors in run ``run``, each shape (d,)."""
        x = theta[self.sensor_slice(run)]
        return np.exp(x[:self.d]), np.asarray(x[self.d:])

    def pack(self, omega: ArrayLike, zeta: ArrayLike, residues: ArrayLike, gains: ArrayLike | None = None,
             offsets: ArrayLike | None = None, quadrature: ArrayLike | None = None) -> np.ndarray:
        """theta from its parts (gains 1, offsets 0 and quadrature residues 0 by default; gains and
        offsets per run (n_runs, d), quadrature residues (n, d) of which the quadrature modes' rows count)."""
        gains = np.ones((self.n_runs, self.d)) if gains is None else np.asarray(gains, float)
        offsets = np.zeros((self.n_runs, self.d)) if offsets is None else np.asarray(offsets, float)
        sensors = np.hstack([np.log(gains), offsets]).ravel()
        Q = np.zeros((self.n, self.d)) if quadrature is None else np.asarray(quadrature, float)
        return np.concatenate([np.log(omega), zeta, np.asarray(residues, float).ravel(),
                               Q[list(self.quadrature)].ravel(), sensors])

    def select_indices(self, modes: Iterable[int]) -> np.ndarray:
        """Indices into theta of the model restricted to ``modes`` (in that order), sensors kept, the
        quadrature residues left out: ``theta[select_indices(modes)]`` is a theta of
        ``ModalModel(d, n_runs, len(modes) - d)``."""
        modes = np.asarray(list(modes), int)
        residues = (2 * self.n + modes[:, None] * self.d + np.arange(self.d)[None, :]).ravel()
        return np.concatenate([modes, self.n + modes, residues, np.arange(self.n_modal, self.p)])

    def bounds(self, sample_rates: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of theta: frequencies in (0, Nyquist), damping within
        :data:`MAX_ABS_DAMPING`, gains 0.5-2, clock offsets within 1.5 samples of the run's rate."""
        lo, hi = np.full(self.p, -np.inf), np.full(self.p, np.inf)
        lo[:self.n] = np.log(2 * np.pi * 1e-3)
        hi[:self.n] = np.log(2 * np.pi * 0.5 * min(sample_rates))
        lo[self.n:2 * self.n], hi[self.n:2 * self.n] = -MAX_ABS_DAMPING, MAX_ABS_DAMPING
        for r, fs in enumerate(sample_rates):
            s = self.sensor_slice(r)
            lo[s.start:s.start + self.d], hi[s.start:s.start + self.d] = np.log(GAIN_RANGE[0]), np.log(GAIN_RANGE[1])
            lo[s.start + self.d:s.stop], hi[s.start + self.d:s.stop] = -OFFSET_BOUND / fs, OFFSET_BOUND / fs
        return lo, hi


class Hold(Enum):
    """What the table acceleration does between samples (how a DFT bin's response is computed)."""

    #: Band-limited (a sensor's anti-alias filter): the continuous-time response at the bin frequency.
    BAND_LIMITED = "band-limited"
    #: Linear between samples (an exact simulation of sampled data): the first-order-hold discretisation.
    FIRST_ORDER = "first-order hold"


def mode_response(hold: Hold, w_bins: np.ndarray, h: float, omega: np.ndarray, zeta: np.ndarray
                  ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """``H_i`` at the bins and its derivatives with respect to ``log w_i`` and ``zeta_i``.

    ``H(s) = s^2 / (s^2 + 2 zeta w s + w^2)``; with :attr:`Hold.FIRST_ORDER`, its first-order-hold
    equivalent ``(z - 1)^2 / h (1 / (z - p) - 1 / (z - conj p)) / (lambda - conj lambda)``,
    ``p = exp(lambda h)`` (the triangle-hold transform of ``H(s) / s^2``).

    Parameters
    ----------
    hold : Hold
    w_bins : ndarray, shape (m,)
        Bin angular frequencies (rad/s).
    h : float
        Sample interval (s).
    omega, zeta : ndarray, shape (n,)

    Returns
    -------
    H : ndarray, shape (m, n), complex
    dH : tuple of two ndarrays, shape (m, n)
        ``dH / d log w`` and ``dH / d zeta``.
    """
    if hold is Hold.BAND_LIMITED:
        s = 1j * w_bins[:, None]
        den = s ** 2 + 2 * zeta * omega * s + omega ** 2
        return s ** 2 / den, (-s ** 2 * (2 * zeta * omega * s + 2 * omega ** 2) / den ** 2,
                              -s ** 2 * (2 * omega * s) / den ** 2)
    root = np.sqrt(1 - zeta ** 2)
    lam = omega * (-zeta + 1j * root)
    mu = np.conj(lam)
    p, q = np.exp(lam * h), np.exp(mu * h)
    z = np.exp(1j * w_bins * h)[:, None]
    gap = lam - mu
    F = (1 / (z - p) - 1 / (z - q)) / gap
    dF_dlam = (h * p / (z - p) ** 2 - F) / gap
    dF_dmu = (-h * q / (z - q) ** 2 + F) / gap
    scale = (z - 1) ** 2 / h
    dH = []
    for dlam in (lam, omega * (-1 - 1j * zeta / root)):
        dH.append(scale * (dF_dlam * dlam + dF_dmu * np.conj(dlam)))
    return scale * F, tuple(dH)


class _Run:
    """One run's bins, normalised by the floor noise levels."""

    def __init__(self, sp: Spectra):
        self.w = 2 * np.pi * sp.freq                      # (m,) rad/s
        self.s = 1j * self.w
        self.zinv = np.conj(sp.z)                          # exp(-i w h)
        self.h = sp.h
        self.inv_sd = 1.0 / sp.sigma_y                     # (d,)
        self.U = sp.U                                      # (m,)
        self.Y = sp.Y * self.inv_sd[None, :]               # (m, d)
        self.s_u = sp.sigma_u ** 2
        self.size = 2 * sp.Y.size


class Likelihood:
    """Whitened, projected residual of :class:`ModalModel` over runs, and its Jacobian.

    Parameters
    ----------
    model : ModalModel
    spectra_list : sequence of Spectra
        One per run (groups ``['a']``).
    free : ndarray of bool, shape (p,), optional
        Parameters the fit varies (the others stay at the values of ``base``).
    base : ndarray, shape (p,), optional
        Full parameter vector the free ones are put into.
    hold : Hold
        How the table acceleration behaves between samples.
    """

    def __init__(self, model: ModalModel, spectra_list, free=None, base=None, hold: Hold = None):
        self.model = model
        self.hold = Hold.BAND_LIMITED if hold is None else hold
        self.runs = [_Run(sp) for sp in spectra_list]
        self.free = np.ones(model.p, bool) if free is None else np.asarray(free, bool)
        self.base = np.zeros(model.p) if base is None else np.asarray(base, float).copy()
        self.n_nuisance = 2 * model.n * len(self.runs)
        self.n_residuals = sum(r.size for r in self.runs)
        self._key, self._states, self._r = None, None, None

    def full(self, x: np.ndarray) -> np.ndarray:
        """The full parameter vector (p,): ``base`` with the free parameters set to ``x``."""
        theta = self.base.copy()
        theta[self.free] = x
        return theta

    def residual(self, x: np.ndarray) -> np.ndarray:
        """Whitened residual with the transient projected out, shape (n_residuals,)."""
        self._update(x)
        return self._r

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """Its Jacobian over the free parameters, shape (n_residuals, free)."""
        self._update(x)
        cols = np.flatnonzero(self.free)
        return np.vstack([_jacobian(self.model, st, k, cols) for k, st in enumerate(self._states)])

    def _update(self, x) -> None:
        key = np.asarray(x, float).tobytes()
        if key != self._key:
            theta = self.full(np.asarray(x, float))
            self._states = [_State(self.model, theta, run, k, self.hold) for k, run in enumerate(self.runs)]
            self._r = np.concatenate([st.r for st in self._states])
            self._key = key


class _State:
    """Everything one run's residual computes that its Jacobian reuses."""

    def __init__(self, model: ModalModel, theta, run: _Run, k: int, hold: Hold):
        d, n = model.d, model.n
        w, z, R = model.omega(theta), model.zeta(theta), model.residues(theta)
        gain, offset = model.sensors(theta, k)
        self.run, self.R, self.quad = run, R, list(model.quadrature)
        self.H, self.dH = mode_response(hold, run.w, run.h, w, z)
        self.Qr = Qr = model.quadrature_residues(theta)
        if self.quad:
            if hold is not Hold.BAND_LIMITED:
                raise ValueError("quadrature residues are implemented for the band-limited response only")
            ratio = (run.s[:, None] / w[None, self.quad])                # s / w_i of the quadrature modes
            self.Hq = ratio * self.H[:, self.quad]
            self.dHq = (ratio * (self.dH[0][:, self.quad] - self.H[:, self.quad]), ratio * self.dH[1][:, self.quad])
        # A classical mode's transient is shared by the floors through R_ij; a quadrature mode's is
        # free per floor (its floors' free decays differ in phase).
        self.classical = np.array([i not in self.quad for i in range(n)])
        root = np.sqrt(1 - z ** 2)
        lam = w * (-z + 1j * root)
        p = np.exp(lam * run.h)
        zi = run.zinv[:, None]
        A, Ab = 1 / (1 - p * zi), 1 / (1 - np.conj(p) * zi)          # (m, n)
        # Floor j samples its free decays tau_j late: mode i's decay there is exp(-lambda_i tau_j) times
        # the table clock's (a constant per mode and floor, not the forced part's exp(-i w tau_j)).
        E = np.exp(-lam[None, :] * offset[:, None])[None]             # (1, d, n)
        EA, EAb = E * A[:, None, :], np.conj(E) * Ab[:, None, :]      # (m, d, n)
        self.basis = _pair(EA, EAb)                                   # (m, d, n, 2)
        self.dbasis_offset = _pair(-lam * EA, -np.conj(lam) * EAb)    # d basis / d tau_j
        dlam = (lam, w * (-1 - 1j * z / root))                       # d lambda / d (log w, zeta)
        self.dbasis = []
        for dl in dlam:
            dA = (zi * A ** 2 * run.h * p)[:, None, :] * E - offset[None, :, None] * EA
            dAb = (zi * Ab ** 2 * run.h * np.conj(p))[:, None, :] * np.conj(E) - offset[None, :, None] * EAb
            self.dbasis.append(_pair(dA * dl, dAb * np.conj(dl)))
        self.Sn = gain[None, :] * run.inv_sd[None, :]                # (1, d): the transient's scale
        self.S = self.Sn * np.exp(-1j * run.w[:, None] * offset[None, :])
        F = 1 - self.H @ R
        if self.quad:
            F = F - self.Hq @ Qr[self.quad]
        self.G = G = self.S * F                                      # (m, d), noise-normalised
        weight = np.where(self.classical[None, :], R.T, 1.0)         # (d, n)
        T = self.Sn[:, :, None, None] * weight[None, :, :, None] * self.basis                   # (m, d, n, 2)
        cols = [T[:, :, i, :] for i in range(n) if self.classical[i]]
        for i in self.quad:                                          # per floor: d column pairs
            for j in range(d):
                block = np.zeros_like(T[:, :, i, :])
                block[:, j, :] = T[:, j, i, :]
                cols.append(block)
        T = np.concatenate(cols, axis=2) if cols else np.zeros((run.w.size, d, 0), complex)
        e = run.Y - G * run.U[:, None]
        # Whitening W = I + phi g g^H per bin, phi = -s_u / (q (1 + q)), q = sqrt(1 + s_u |g|^2).
        q = np.sqrt(1 + run.s_u * np.sum(np.abs(G) ** 2, axis=1))
        self.phi = -run.s_u / (q * (1 + q))
        self.dphi = run.s_u ** 2 * (1 + 2 * q) / (2 * q ** 3 * (1 + q) ** 2)   # d phi / d |g|^2
        B = _real(self._whiten(T))
        rw = _real(self._whiten(e))
        norms = np.linalg.norm(B, axis=0)
        keep = norms > 1e-12 * max(float(np.max(norms)), 1e-300)     # a mode with no residues has no transient
        self.Q, Rq = np.linalg.qr(B[:, keep] / norms[keep])
        coef = self.Q.T @ rw
        self.r = rw - self.Q @ coef
        beta = np.zeros(T.shape[2])
        beta[keep] = np.linalg.lstsq(Rq, coef, rcond=None)[0] / norms[keep]
        # Per mode and floor, the transient coefficients: classical beta_i R_ij, quadrature beta_ij.
        n_classical = int(self.classical.sum())
        coeff = np.zeros((n, d, 2))
        coeff[self.classical] = beta[:2 * n_classical].reshape(-1, 2)[:, None, :] * R[self.classical][:, :, None]
        if self.quad:
            coeff[self.quad] = beta[2 * n_classical:].reshape(len(self.quad), d, 2)
        self.beta_shared = np.zeros((n, 2))
        self.beta_shared[self.classical] = beta[:2 * n_classical].reshape(-1, 2)
        self.coeff = coeff
        self.bb = np.einsum("mjnc,nc->jnm", self.basis, self.beta_shared)   # classical modes' transients
        self.Tb = self.Sn * np.einsum("mjnc,njc->mj", self.basis, coeff)
        self.v = e - self.Tb                                         # unwhitened residual, beta fixed
        self.gv = np.einsum("md,md->m", np.conj(G), self.v)          # g^H v

    def _whiten(self, x):
        """``W x`` per bin, x of shape (m, d, ...)."""
        G = self.G
        proj = np.einsum("md,md...->m...", np.conj(G), x)
        return x + (self.phi[:, None] * G)[(...,) + (None,) * (x.ndim - 2)] * proj[:, None]


def _pair(a, b) -> np.ndarray:
    """The two real coefficients' columns of ``c a + conj(c) b``: ``[a + b, i (a - b)]`` on a last axis."""
    return np.stack([a + b, 1j * (a - b)], axis=-1)


def _real(x) -> np.ndarray:
    """Real and imaginary parts stacked (rows: bins x floors, then the same for the imaginary part), x sqrt(2)."""
    flat = x.reshape(x.shape[0] * x.shape[1], -1)
    return np.sqrt(2.0) * np.concatenate([flat.real, flat.imag]).reshape((-1,) + x.shape[2:])


def _jacobian(model: ModalModel, st: _State, k: int, cols) -> np.ndarray:
    """Kaufman's variable-projection Jacobian of run ``k``'s residual, columns ``cols`` of theta.

    With ``beta`` fixed, ``r = W v``, ``v = e - T beta``; per parameter
    ``dr = W dv + dW v = -(U - phi g^H v) dG - dT beta + g kappa`` with
    ``kappa = phi g^H dv + phi' |g|^2' g^H v + phi dG^H v``, then projected off the transient columns.
    """
    d, n, run, G = model.d, model.n, st.run, st.G
    m = run.w.size
    out = np.zeros((model.p, m, d), complex)
    coef = -(run.U - st.phi * st.gv)                                  # (m,)

    def finish(dG, dTb):                                              # dG, dTb: (q, m, d)
        gdg = np.einsum("md,qmd->qm", np.conj(G), dG)
        kappa = (st.phi * (-run.U * gdg - np.einsum("md,qmd->qm", np.conj(G), dTb))
                 + st.dphi * st.gv * 2 * gdg.real + st.phi * np.einsum("qmd,md->qm", np.conj(dG), st.v))
        return coef[None, :, None] * dG - dTb + G[None] * kappa[:, :, None]

    def finish_column(j, a, b):                                       # dG = a e_j, dTb = b e_j: (q, m)
        gj = np.conj(G[:, j])
        kappa = (st.phi * (-run.U * gj * a - gj * b) + st.dphi * st.gv * 2 * (gj * a).real
                 + st.phi * np.conj(a) * st.v[:, j])
        dr = G[None] * kappa[:, :, None]
        dr[:, :, j] += coef * a - b
        return dr

    S, R, quad, Qr = st.S, st.R, st.quad, st.Qr
    for a in range(2):                                                # log w, zeta of every mode
        idx = np.arange(n) + a * n
        dG = -S[None] * (st.dH[a].T[:, :, None] * R[:, None, :])
        if quad:
            dG[quad] -= S[None] * (st.dHq[a].T[:, :, None] * Qr[quad][:, None, :])
        dTb = st.Sn[None] * np.einsum("mjnc,njc->nmj", st.dbasis[a], st.coeff)
        out[idx] = finish(dG, dTb)
    bb = st.bb * st.classical[None, :, None]                          # a quadrature mode's transient is free
    for j in range(d):                                                # residues of floor j
        idx = 2 * n + np.arange(n) * d + j
        out[idx] = finish_column(j, -S[:, j][None] * st.H.T, st.Sn[:, j] * bb[j])
        if quad:
            idx = 2 * n + n * d + np.arange(len(quad)) * d + j
            out[idx] = finish_column(j, -S[:, j][None] * st.Hq.T, np.zeros((len(quad), m), complex))
    sl = model.sensor_slice(k)
    for j in range(d):                                                # gain and clock offset of sensor j
        a = np.stack([G[:, j], -1j * run.w * G[:, j]])
        b = np.stack([st.Tb[:, j], st.Sn[0, j] * np.einsum("mnc,nc->m", st.dbasis_offset[:, j], st.coeff[:, j])])
        out[[sl.start + j, sl.start + d + j]] = finish_column(j, a, b)
    sel = out[cols]                                                   # (q, m, d)
    J = np.sqrt(2.0) * np.concatenate([sel.real.reshape(len(cols), -1), sel.imag.reshape(len(cols), -1)], axis=1)
    J -= (J @ st.Q) @ st.Q.T
    return J.T
