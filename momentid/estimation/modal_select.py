"""How many modes the data hold, which of them are the storeys', and a second opinion on each damping.

A rig has ``d`` storey modes, but its floor accelerometers may also see a torsional or out-of-plane
mode, or an appendage's, leaking into the shaking axis.  Fitted with ``d`` modes only, such a
resonance is absorbed by the nearest storey mode, whose damping ratio then comes out several times
too large (one mode fitted to two 1 % apart).  :func:`select_modes`:

1. **Candidates.**  The spectral peaks of the floors' response relative to the table
   (:func:`~momentid.estimation.peaks.peak_candidates`) and the poles of a subspace estimate that are
   stable over model orders (:func:`~momentid.estimation.subspace.stable_poles`).
2. **Storey-mode fit.**  The ``d`` likeliest storey modes among the candidates (a least-squares fit at
   all of them, then step 5's choice) start a ``d``-mode fit (so do the ``d`` most prominent peaks);
   the band runs up to :data:`~momentid.estimation.modal.FIT_BAND_FACTOR` x the top one.
3. **Extra modes.**  Every stable subspace pole in the band that no fitted mode claims is tried as
   one more mode, and so is the peak of the residual beside each fitted mode (within
   :data:`NEIGHBOURHOOD`: a close mode too weakly excited for the subspace estimate).  A residual
   peak elsewhere is not enough: a rig that is not linear leaves peaks at the harmonics of its modes,
   which no linear input-output model holds stable over orders.  The candidate that lowers the cost
   most is kept when the decrease is significant (:func:`f_test`: an F-test of nested models against
   the larger model's residual variance, at :data:`SIGNIFICANCE`) *and* the new mode is a mode:
   damping ratio in (0, :data:`EXTRA_MAX_DAMPING`), frequency and damping determined (standard errors
   below 1 % and 50 %), a residue beyond :data:`SEEN_SIGMAS` standard errors on at least one sensor,
   separated from every other mode by more than the larger half-power half-width (closer than that,
   two poles describe one resonance's shape, not two modes), no mode fitted before turned unstable;
   a residual-peak candidate, and a subspace pole within :data:`NEIGHBOURHOOD` of a fitted mode when
   the misfit is far above the noise, must also remove :data:`NEIGHBOUR_MIN_SHARE` of the misfit above
   the noise level (a rig that is not linear leaves residual beside every mode, which one more linear
   mode lowers significantly but by a sliver; its subspace estimate holds a pole there stable too).
   Repeat, up to :data:`MAX_EXTRA` extra modes.
4. **Complex pairs.**  Two modes closer than :data:`CLOSE_PAIR` half-power half-widths, an
   appendage's and a storey's, share their damping in proportions the classical model cannot hold
   (their floors move out of phase): each such pair is tried with quadrature residues (complex modes),
   kept when the F-test asks for them.
5. **Which are the storeys'.**  Among the ``n`` modes, the ``d`` whose shapes (residue rows) are
   closest to orthogonal with the stated masses (equal masses when none are stated), and among
   those equally orthogonal (within :data:`ORTHOGONALITY_SLACK`) the ones with the largest effective
   mass ``sum_j m_j R_ij``.  A storey mode and an extra mode near it share a shape, so orthogonality
   cannot tell them apart; the effective mass can: an appendage or a leaking out-of-plane mode moves
   little of the rig's mass along the shaking axis.
6. **Second opinion.**  Each fitted mode's damping ratio is compared with the subspace estimate of
   the same data (the stable pole nearest in frequency, median over the runs).
"""

from __future__ import annotations

from collections.abc import Sequence
import itertools
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from momentid.core.series import RunData
from momentid.errors import IdentificationError
from momentid.estimation.eiv import spectra
from momentid.estimation.modal import (NYQUIST_FRACTION, START_DAMPING, ModalFit, ModalModel, f_test, fit_band,
                                       linear_start, modal_spectra, refine, shear_start)
from momentid.estimation.noise import estimate_noise
from momentid.estimation.peaks import peak_candidates, require_resonances
from momentid.estimation.subspace import STABLE_FREQUENCY, stable_poles

__all__ = ["ModeSelection", "select_modes", "f_test", "storey_modes", "MAX_EXTRA", "SIGNIFICANCE"]

#: Extra modes tried at most (beyond the storeys').
MAX_EXTRA = 3
#: Significance level of the F-test that admits one more mode (a false extra mode in one fit in a million
#: when the residual is noise).
SIGNIFICANCE = 1e-6
#: An extra mode's damping ratio must be below this (a wider "mode" absorbs a broadband misfit).
EXTRA_MAX_DAMPING = 0.2
#: A mode is seen by a sensor whose residue exceeds this many standard errors.
SEEN_SIGMAS = 3.0
#: An extra mode's frequency and damping ratio must be known to these fractions of themselves.
EXTRA_FREQUENCY_STD = 0.01
EXTRA_DAMPING_STD = 0.5
#: Two modes closer than this many half-power half-widths (of the wider) are a pair whose damping may be
#: non-classical (tried with quadrature residues).
CLOSE_PAIR = 10.0
#: A fitted mode claims a subspace pole within this relative distance (log frequency).
CLAIM_DISTANCE = 0.03
#: The residual is searched for a neighbour of each fitted mode within this fraction of its frequency
#: (outside its own half-power band), smoothed over this many bins; the neighbour starts at this damping.
NEIGHBOURHOOD = 0.08
NEIGHBOUR_SMOOTHING = 5
NEIGHBOUR_START_DAMPING = 0.003
#: ... when the fit leaves a residual variance factor below NEIGHBOUR_SEARCH_SCALE, and such a mode is
#: kept only when it removes NEIGHBOUR_MIN_SHARE of the misfit above the noise level: a rig that is not
#: linear leaves residual beside every mode (its frequency moves with amplitude), which one more linear
#: mode lowers significantly (the F-test) but by a sliver; a missed linear mode takes most of it away.
NEIGHBOUR_SEARCH_SCALE = 5.0
NEIGHBOUR_MIN_SHARE = 0.3
#: The misfit above the noise level counts as at least this share of the degrees of freedom (a fit at
#: the noise level has almost none: a mode that removes what noise alone would, ~its parameter count,
#: must not look like one removing all of it).
NOISE_FLOOR_SHARE = 0.01
#: Subsets of modes within this much of the most orthogonal are equally orthogonal (then the effective
#: mass decides).
ORTHOGONALITY_SLACK = 0.1


@dataclass(frozen=True)
class ModeSelection:
    """Result of :func:`select_modes`.

    Attributes
    ----------
    model : ModalModel
        ``n = d + extra`` modes.
    fit : ModalFit
    storey : tuple of int
        Indices (in the model) of the ``d`` storey modes, ascending in frequency.
    extra : tuple of int
        Indices of the extra modes, ascending in frequency.
    subspace : tuple of list of StablePole
        Per run, the subspace estimate's stable poles.
    independent : ndarray, shape (n,)
        Per model mode, the subspace damping ratio of the same data (NaN where no stable pole matches).
    notes : tuple of str
        What was tried and decided.
    """

    model: ModalModel
    fit: ModalFit
    storey: tuple
    extra: tuple
    subspace: tuple
    independent: np.ndarray
    notes: tuple


def _std(fit: ModalFit) -> np.ndarray:
    return np.sqrt(np.clip(np.diag(fit.covariance), 0, None))


def _is_mode(model: ModalModel, fit: ModalFit, i: int) -> str:
    """Why mode ``i`` of ``fit`` is not a mode ('' when it is one)."""
    sd = _std(fit)
    w, z = model.omega(fit.theta), model.zeta(fit.theta)
    f = w / (2 * np.pi)
    R = model.residues(fit.theta)
    R_sd = sd[model.residue_slice].reshape(model.n, model.d)
    if not 0 < z[i] < EXTRA_MAX_DAMPING:
        return f"damping ratio {z[i]:.3g} outside (0, {EXTRA_MAX_DAMPING:g})"
    if sd[i] > EXTRA_FREQUENCY_STD or sd[model.n + i] > EXTRA_DAMPING_STD * z[i]:
        return "frequency or damping not determined"
    if not np.any(np.abs(R[i]) > SEEN_SIGMAS * R_sd[i]):
        return "no sensor sees it"
    for k in range(model.n):
        if k != i and abs(f[k] - f[i]) <= max(z[i] * f[i], z[k] * f[k]):
            return f"within the half-power band of the mode at {f[k]:.4g} Hz"
    return ""


def storey_modes(residues: np.ndarray, frequency: np.ndarray, d: int, masses: ArrayLike | None = None
                 ) -> tuple[int, ...]:
    """Indices of the ``d`` storey modes among ``n`` (see the module docstring, step 4), ascending in frequency.

    Parameters
    ----------
    residues : ndarray, shape (n, d)
    frequency : ndarray, shape (n,)
    d : int
    masses : array_like, shape (d,), optional
    """
    n = residues.shape[0]
    if n == d:
        return tuple(int(i) for i in np.argsort(frequency))
    m = np.ones(d) if masses is None else np.asarray(masses, float)
    effective = residues @ m / np.sum(m)
    norm = np.sqrt(np.abs(np.einsum("ij,j,ij->i", residues, m, residues)))
    shapes = residues / np.maximum(norm, 1e-300)[:, None]
    scored = []
    for subset in itertools.combinations(range(n), d):
        S = shapes[list(subset)]
        gram = (S * m) @ S.T
        off = float(np.max(np.abs(gram - np.diag(np.diag(gram))))) if d > 1 else 0.0
        scored.append((off, float(np.sum(effective[list(subset)])), subset))
    best_off = min(s[0] for s in scored)
    chosen = max((s for s in scored if s[0] <= best_off + ORTHOGONALITY_SLACK), key=lambda s: s[1])[2]
    return tuple(sorted(chosen, key=lambda i: frequency[i]))


def _first_storey_modes(runs, d: int, poles, peaks, masses, f_top: float):
    """Frequencies (Hz) and damping ratios of the ``d`` likeliest storey modes among the stable subspace
    poles and the ``d`` most prominent peaks (those no pole explains, at :data:`START_DAMPING`): the
    :func:`storey_modes` of a least-squares fit at all of them up to ``f_top`` (Hz)."""
    f = [p.frequency for p in poles]
    z = [p.start_damping for p in poles]
    for peak in peaks[:d]:
        if all(abs(peak / x - 1) > STABLE_FREQUENCY for x in f):
            f.append(float(peak))
            z.append(START_DAMPING)
    f, z = np.array(f), np.array(z)
    if f.size == d:
        order = np.argsort(f)
        return f[order], z[order]
    unit = {"zdd": 1.0, **{f"a{j + 1}": 1.0 for j in range(d)}}        # plain least squares: no weights needed
    wide = [spectra(r, d, f_top, sigma=unit, groups=["a"]) for r in runs]
    probe = ModalModel(d, len(runs), extra=f.size - d)
    theta = linear_start(probe, wide, 2 * np.pi * f, z)
    first = list(storey_modes(probe.residues(theta), f, d, masses))
    return f[first], z[first]


def _match(freq: np.ndarray, poles, tolerance: float = 3 * STABLE_FREQUENCY) -> list:
    """For each frequency, the index of the nearest pole within ``tolerance`` (relative), or None."""
    pf = np.array([p.frequency for p in poles])
    out = []
    for f in freq:
        if pf.size == 0:
            out.append(None)
            continue
        k = int(np.argmin(np.abs(pf / f - 1)))
        out.append(k if abs(pf[k] / f - 1) < tolerance else None)
    return out


def _independent(freq: np.ndarray, subspace) -> np.ndarray:
    """Per frequency, the median subspace damping ratio of the matching stable poles over the runs."""
    found = [[] for _ in freq]
    for poles in subspace:
        for i, k in enumerate(_match(freq, poles, STABLE_FREQUENCY)):
            if k is not None and poles[k].damping_stable:
                found[i].append(poles[k].damping_ratio)
    return np.array([np.median(z) if z else np.nan for z in found])


def select_modes(runs: Sequence[RunData], d: int, *, masses: ArrayLike | None = None, stated: dict | None = None
                 ) -> ModeSelection:
    """Fit the storey modes and every extra mode the data hold (see the module docstring).

    Parameters
    ----------
    runs : sequence of RunData
        ``zdd`` and ``a1..ad`` (m/s^2), no added mass (or the same in every run).
    d : int
        Storeys.
    masses : array_like, shape (d,), optional
        Stated floor masses (kg): which modes are the storeys' (equal masses without them).
    stated : dict, optional
        Stated noise levels per channel group.

    Raises
    ------
    IdentificationError
        No noise source, fewer resonances than storeys, a singular fit.
    """
    runs = tuple(runs)
    sigma_u = estimate_noise(runs[0], stated=stated).sigma["zdd"]
    peaks, _ = peak_candidates(runs, d, sigma_u)
    require_resonances(runs, d, peaks.size)
    fs = min(r.sample_rate for r in runs)
    rates = [r.sample_rate for r in runs]
    subspace = tuple(stable_poles(r["zdd"], r.group("a", d), 1.0 / r.sample_rate, d, NYQUIST_FRACTION * fs)
                     for r in runs)
    longest = subspace[int(np.argmax([r.n_samples for r in runs]))]
    f0, z0 = _first_storey_modes(runs, d, longest, peaks, masses, NYQUIST_FRACTION * fs)
    f_max = fit_band(f0, fs)
    spectra_list = modal_spectra(runs, d, f_max, stated)
    model = ModalModel(d, len(runs))
    top = np.sort(peaks[:d])
    starts = [("storey candidates", linear_start(model, spectra_list, 2 * np.pi * f0, z0)),
              ("picked peaks", linear_start(model, spectra_list, 2 * np.pi * top, np.full(d, START_DAMPING))),
              ("shear building at the picked peaks", shear_start(model, top, masses))]
    fit = refine(model, spectra_list, starts, sample_rates=rates, f_max=f_max)
    notes = []
    tried: set = set()
    while model.n - d < MAX_EXTRA:
        candidates = _candidates(model, fit, spectra_list, longest, f_max, tried)
        best = None
        for f_c, z_c, source in candidates:
            tried.add(round(f_c, 4))
            if source == "neighbour":
                local = _local_share(model, fit, spectra_list, f_c, z_c, rates, f_max)
                if local < NEIGHBOUR_MIN_SHARE:
                    notes.append(f"a mode near {f_c:.4g} Hz was tried and rejected: it removes "
                                 f"{max(local, 0.0):.0%} of the misfit above the noise level (a residual beside a "
                                 f"mode that one more linear mode "
                                 f"barely lowers is the rig's nonlinearity)")
                    continue
            trial = _with_mode(model, fit, spectra_list, f_c, z_c, rates, f_max)
            if trial is None:
                continue
            big, big_fit, new = trial
            F, p = f_test(fit.cost, big_fit.cost, 2 + d + 2 * len(runs), big_fit.dof)
            why = _is_mode(big, big_fit, new) if p < SIGNIFICANCE else f"not significant (F = {F:.3g}, p = {p:.2g})"
            if not why and np.any((model.zeta(fit.theta) > 0) & (np.delete(big.zeta(big_fit.theta), new) <= 0)):
                why = "a mode fitted before turns unstable beside it"
            share = (fit.cost - big_fit.cost) / max(fit.cost - fit.dof, NOISE_FLOOR_SHARE * fit.dof)
            f_new = float(big.omega(big_fit.theta)[new] / (2 * np.pi))
            if not why and share < NEIGHBOUR_MIN_SHARE and (source == "neighbour" or _beside_mode(
                    model, fit, f_new)):
                why = (f"it removes {share:.0%} of the misfit above the noise level (a residual beside a mode that "
                       f"one more linear mode barely lowers is the rig's nonlinearity)")
            if why:
                notes.append(f"a mode at {f_new:.4g} Hz was tried and rejected: {why}")
            elif best is None or big_fit.cost < best[1].cost:
                best = (big, big_fit, f_new, F)
        if best is None:
            break
        model, fit = best[0], best[1]
        notes.append(f"the data hold one more resonance than the storeys explain: a mode at {best[2]:.4g} Hz "
                     f"lowers the cost significantly (F = {best[3]:.3g}) and is fitted too")
    model, fit = _drop_non_modes(model, fit, spectra_list, rates, f_max, masses, notes)
    model, fit = _complex_pairs(model, fit, spectra_list, rates, f_max, notes)
    freq = model.omega(fit.theta) / (2 * np.pi)
    storey = storey_modes(model.residues(fit.theta), freq, d, masses)
    extra = tuple(sorted((i for i in range(model.n) if i not in storey), key=lambda i: freq[i]))
    return ModeSelection(model=model, fit=fit, storey=storey, extra=extra, subspace=subspace,
                         independent=_independent(freq, subspace), notes=tuple(notes))


def _beside_mode(model: ModalModel, fit: ModalFit, f_new: float) -> bool:
    """Whether a new mode at ``f_new`` (Hz) lies within :data:`NEIGHBOURHOOD` of a fitted mode while the fit
    leaves a misfit far above the noise (variance factor beyond :data:`NEIGHBOUR_SEARCH_SCALE`): a rig
    whose mode moves with its amplitude leaves a pole beside it that a subspace estimate holds stable
    over orders too, and one more linear mode there must take most of the misfit away to be believed."""
    freq = model.omega(fit.theta) / (2 * np.pi)
    return bool(fit.scale > NEIGHBOUR_SEARCH_SCALE and np.any(np.abs(f_new / freq - 1) < NEIGHBOURHOOD))


def _drop_non_modes(model: ModalModel, fit: ModalFit, spectra_list, rates, f_max: float, masses, notes: list):
    """The fit without the modes beyond the storeys' that are no modes (:func:`_is_mode`) after the
    extra modes joined (one that a later mode took the place of), refitted after each one dropped."""
    while model.n > model.d:
        freq = model.omega(fit.theta) / (2 * np.pi)
        storey = storey_modes(model.residues(fit.theta), freq, model.d, masses)
        why = {i: _is_mode(model, fit, i) for i in range(model.n) if i not in storey}
        bad = [i for i, w in why.items() if w]
        if not bad:
            break
        i = bad[0]
        keep = [k for k in range(model.n) if k != i]
        small = ModalModel(model.d, model.n_runs, extra=model.n - model.d - 1)
        try:
            fit = refine(small, spectra_list, [("the fit without it", fit.theta[model.select_indices(keep)])],
                         sample_rates=rates, f_max=f_max)
        except IdentificationError:
            break
        notes.append(f"the mode at {freq[i]:.4g} Hz is dropped: {why[i]}")
        model = small
    return model, fit


def _complex_pairs(model: ModalModel, fit: ModalFit, spectra_list, rates, f_max: float, notes: list):
    """The fit with quadrature residues on every pair of modes closer than :data:`CLOSE_PAIR` half-power
    half-widths, where the F-test (:data:`SIGNIFICANCE`) asks for them and every mode stays a mode."""
    f = model.omega(fit.theta) / (2 * np.pi)
    z = np.abs(model.zeta(fit.theta))
    pairs = sorted({tuple(sorted((i, k))) for i in range(model.n) for k in range(model.n)
                    if i != k and abs(f[i] - f[k]) < CLOSE_PAIR * max(z[i] * f[i], z[k] * f[k])})
    for pair in pairs:
        quad = tuple(sorted(set(model.quadrature) | set(pair)))
        if quad == model.quadrature:
            continue
        big = ModalModel(model.d, model.n_runs, extra=model.n - model.d, quadrature=quad)
        start = big.pack(model.omega(fit.theta), model.zeta(fit.theta), model.residues(fit.theta),
                         quadrature=model.quadrature_residues(fit.theta))
        start[big.n_modal:] = fit.theta[model.n_modal:]
        try:
            trial = refine(big, spectra_list, [("classical fit", start)], sample_rates=rates, f_max=f_max)
        except IdentificationError:
            continue
        F, p = f_test(fit.cost, trial.cost, len(pair) * model.d, trial.dof)
        valid = all(not _is_mode(big, trial, i) for i in pair)
        if p < SIGNIFICANCE and valid:
            notes.append(f"the modes at {f[pair[0]]:.4g} and {f[pair[1]]:.4g} Hz, closer than their half-power "
                         f"bands, are fitted as complex (non-classical) modes: quadrature residues lower the cost "
                         f"significantly (F = {F:.3g}); their shapes, K and C use the in-phase residues")
            model, fit = big, trial
    return model, fit


def _candidates(model: ModalModel, fit: ModalFit, spectra_list, poles, f_max: float, tried: set) -> list:
    """(frequency Hz, start damping) of the resonances in the band that no fitted mode explains: the
    stable subspace poles no fitted mode claims, and the residual's peak beside each fitted mode.

    Each fitted mode claims the nearest unclaimed pole within :data:`CLAIM_DISTANCE` (nearest pairs first),
    so that two poles 1 % apart that one fitted mode straddles leave one of them a candidate.
    """
    freq = model.omega(fit.theta) / (2 * np.pi)
    pf = np.array([p.frequency for p in poles])
    pairs = sorted((abs(np.log(pf[k] / freq[i])), i, k) for i in range(freq.size) for k in range(pf.size))
    claimed, done = set(), set()
    for gap, i, k in pairs:
        if gap < CLAIM_DISTANCE and i not in done and k not in claimed:
            claimed.add(k)
            done.add(i)
    out = [(p.frequency, p.start_damping, "subspace") for k, p in enumerate(poles)
           if k not in claimed and p.frequency < f_max and round(p.frequency, 4) not in tried]
    if fit.scale > NEIGHBOUR_SEARCH_SCALE:    # the residual holds the rig's nonlinearity, not only noise
        return out
    for f_peak in _neighbour_peaks(model, fit, spectra_list):
        if round(f_peak, 4) not in tried and all(abs(f_peak / c[0] - 1) > STABLE_FREQUENCY for c in out):
            out.append((f_peak, NEIGHBOUR_START_DAMPING, "neighbour"))
    return out


def _neighbour_peaks(model: ModalModel, fit: ModalFit, spectra_list) -> list:
    """Per fitted mode, the peak (Hz) of the whitened residual power near it (within
    :data:`NEIGHBOURHOOD` of its frequency, or 10 half-power half-widths if wider), first run's bins.

    A second mode close to a fitted one, too weakly excited for the subspace estimate to hold it
    stable over orders, leaves its trace there: the one mode fitted to both misses it on its flank."""
    from momentid.estimation.modal_model import Likelihood

    sp = spectra_list[0]
    lik = Likelihood(model, spectra_list[:1], free=np.zeros(model.p, bool), base=fit.theta)
    r = lik.residual(np.zeros(0))
    m, d = sp.Y.shape
    power = np.sum(r[:m * d].reshape(m, d) ** 2 + r[m * d:].reshape(m, d) ** 2, axis=1)
    smooth = np.convolve(power, np.ones(NEIGHBOUR_SMOOTHING) / NEIGHBOUR_SMOOTHING, mode="same")
    freq = model.omega(fit.theta) / (2 * np.pi)
    zeta = np.abs(model.zeta(fit.theta))
    out = []
    for f, z in zip(freq, zeta):
        near = np.flatnonzero((np.abs(sp.freq - f) < max(NEIGHBOURHOOD * f, 10 * z * f))
                              & (np.abs(sp.freq - f) > 2 * z * f))
        if near.size:
            out.append(float(sp.freq[near[np.argmax(smooth[near])]]))
    return out


def _window(sp, low: float, high: float):
    """The bins of ``sp`` between ``low`` and ``high`` (Hz)."""
    k = (sp.freq >= low) & (sp.freq <= high)
    return replace(sp, z=sp.z[k], U=sp.U[k], Y=sp.Y[k], freq=sp.freq[k])


def _local_share(model: ModalModel, fit: ModalFit, spectra_list, f_c: float, z_c: float, rates, f_max: float) -> float:
    """Share of the misfit above the noise level that one more mode at ``f_c`` removes: a screen that
    fits it on the bins within :data:`NEIGHBOURHOOD` of ``f_c`` only (with the modes there; the others
    and the sensors held), then evaluates the whole band once with it.  It underestimates what the full
    fit would remove, never by much for a mode that is there."""
    from momentid.estimation.modal_model import Likelihood

    low, high = f_c * (1 - NEIGHBOURHOOD), min(f_c * (1 + NEIGHBOURHOOD), f_max)
    local = [_window(sp, low, high) for sp in spectra_list]
    if min(sp.freq.size for sp in local) < 4 * model.d:
        return 0.0
    f = model.omega(fit.theta) / (2 * np.pi)
    big = ModalModel(model.d, model.n_runs, extra=model.n - model.d + 1)
    free = np.zeros(big.p, bool)
    for i in [i for i in range(model.n) if low <= f[i] <= high] + [model.n]:
        free[[i, big.n + i]] = True
        free[big.residue_slice.start + i * big.d:big.residue_slice.start + (i + 1) * big.d] = True
    start = big.pack(np.append(model.omega(fit.theta), 2 * np.pi * f_c), np.append(model.zeta(fit.theta), z_c),
                     np.vstack([model.residues(fit.theta), np.zeros(model.d)]))
    start[big.n_modal:] = fit.theta[model.n_modal:]
    fresh = linear_start(big, local, big.omega(start), big.zeta(start))
    start[big.residue_slice.start + model.n * model.d:big.residue_slice.stop] = big.residues(fresh)[-1]
    try:
        after = refine(big, local, [("fit", start)], sample_rates=rates, f_max=high, free=free,
                       fix_nuisance=False, frequency_bounds={model.n: (low, high)})
        r = Likelihood(big, spectra_list, free=np.zeros(big.p, bool), base=after.theta).residual(np.zeros(0))
    except (IdentificationError, np.linalg.LinAlgError, ValueError):
        return 0.0
    excess = max(fit.cost - fit.dof, NOISE_FLOOR_SHARE * fit.dof)
    return float((fit.cost - float(r @ r)) / excess)


def _with_mode(model: ModalModel, fit: ModalFit, spectra_list, f_c: float, z_c: float, rates, f_max: float):
    """The fit with one more mode at ``f_c``: (model, fit, index of the new mode), or None if it fails."""
    big = ModalModel(model.d, model.n_runs, extra=model.n - model.d + 1)
    w = np.append(model.omega(fit.theta), 2 * np.pi * f_c)
    z = np.append(model.zeta(fit.theta), z_c)
    fresh = linear_start(big, spectra_list, w, z)
    kept = fresh.copy()
    kept[:model.n], kept[big.n:big.n + model.n] = np.log(w[:-1]), z[:-1]
    R = big.residues(fresh)
    R[:model.n] = model.residues(fit.theta)
    kept[2 * big.n:big.n_modal] = R.ravel()
    kept[big.n_modal:] = fit.theta[model.n_modal:]
    try:
        out = refine(big, spectra_list, [("linear fit at every pole", fresh), ("previous fit", kept)],
                     sample_rates=rates, f_max=f_max,
                     frequency_bounds={model.n: (f_c * (1 - 2 * NEIGHBOURHOOD), f_c * (1 + 2 * NEIGHBOURHOOD))})
    except IdentificationError:
        return None
    f_new, f_old = big.omega(out.theta), model.omega(fit.theta)
    distance = np.min(np.abs(np.log(f_new[:, None] / f_old[None, :])), axis=1)
    return big, out, int(np.argmax(distance))
