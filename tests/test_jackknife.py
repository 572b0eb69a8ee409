"""The whole record's damping error from a delete-a-block jackknife: near the fit's own on a stationary
linear record, far above it when the record changes partway."""

from __future__ import annotations

import numpy as np

from momentid.core.series import RunData
from momentid.estimation.jackknife import BLOCKS, block_edges, block_jackknife
from momentid.estimation.linear import discretize, outputs, simulate_linear
from momentid.estimation.modal_select import select_modes
from momentid.estimation.noise import estimate_noise, quiet_lead_in

FS = 120.0
MASS = 0.5
SIGMA = 0.01


def _response(zeta: float, seconds: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Table noise band-limited to 40 Hz and a 1-storey rig's floor acceleration (mode at 15 Hz)."""
    rng = np.random.default_rng(seed)
    n = int(seconds * FS)
    spectrum = np.fft.rfft(rng.standard_normal(n))
    spectrum[np.fft.rfftfreq(n, 1 / FS) > 40.0] = 0.0
    u = np.fft.irfft(spectrum, n)
    u = 0.5 * u / np.std(u)
    w = 2 * np.pi * 15.0
    M, K, C = np.array([[MASS]]), np.array([[MASS * w * w]]), np.array([[2 * zeta * w * MASS]])
    model = discretize(M, C, K, 1 / FS)
    return u, outputs(model, simulate_linear(model, u))["a"][:, 0]


def _jackknife(u: np.ndarray, a: np.ndarray, seed: int):
    rng = np.random.default_rng(seed)
    values = np.column_stack([u, a]) + SIGMA * rng.standard_normal((u.size, 2))
    run = RunData("shake", np.zeros(1), np.arange(u.size) / FS, ("zdd", "a1"), values)
    selection = select_modes([run], 1, masses=(MASS,))
    i = selection.storey[0]
    own = float(np.sqrt(selection.fit.covariance[selection.model.n + i, selection.model.n + i]))
    zeta = float(selection.model.zeta(selection.fit.theta)[i])
    jk = block_jackknife([run], selection, [estimate_noise(run).sigma])
    return zeta, own, jk, i


def test_a_stationary_record_gives_an_error_near_the_fits_own():
    u, a = _response(0.003, 30.0, 1)
    zeta, own, jk, i = _jackknife(u, a, 2)
    assert jk is not None and jk.dof == BLOCKS - 1 and jk.refits.shape == (BLOCKS, 1)
    # a linear record with white noise: the jackknife estimates the same variance as the fit's own, to
    # within what 7 degrees of freedom allow (a chi-square with 7 dof lies within 0.3-2.2x of its mean
    # with 99 %: the standard error within 0.5-1.5x; 3x is kept for the jackknife's own bias)
    assert own / 3 < jk.damping_ratio_std[i] < 3 * own, (own, jk.damping_ratio_std)
    # the refits scatter about the whole record's value (each holds 7/8 of it)
    assert abs(float(np.mean(jk.refits[:, i])) - zeta) < jk.damping_ratio_std[i]


def test_a_record_whose_damping_changes_partway_gives_an_error_the_fit_does_not_see():
    u1, a1 = _response(0.002, 15.0, 1)
    u2, a2 = _response(0.008, 15.0, 3)
    zeta, own, jk, i = _jackknife(np.concatenate([u1, u2]), np.concatenate([a1, a2]), 2)
    # the two halves damp at 0.2 % and 0.8 %: leaving a block of either half out moves the whole record's
    # ratio by much more than white noise would (the fit's own error, scaled by its misfit, sees 2-3x less)
    assert jk.damping_ratio_std[i] > 2 * own, (own, jk.damping_ratio_std)


def test_a_quiet_lead_in_is_in_every_refit():
    """A record that rests for 40 % of its length before the table moves: blocks of equal time would leave
    out lead-in alone in three of eight refits (no information left out, yet a degree of freedom counted);
    the blocks hold equal shaking, the lead-in before the first edge, in every run."""
    u, a = _response(0.003, 18.0, 1)
    rest = np.zeros(int(12.0 * FS))
    runs = []
    for k, (uu, aa) in enumerate(((np.concatenate([rest, u]), np.concatenate([rest, a])), (u[:1200], a[:1200]))):
        values = np.column_stack([uu, aa]) + SIGMA * np.random.default_rng(k).standard_normal((uu.size, 2))
        runs.append(RunData(f"shake{k}", np.zeros(1), np.arange(uu.size) / FS, ("zdd", "a1"), values))
    lead = quiet_lead_in(runs[0])
    assert 0.8 * rest.size < lead <= rest.size                # the lead-in is found (it ends before the shaking)
    edges = block_edges(runs)
    shaking = (runs[0].n_samples - lead) + runs[1].n_samples     # the second run shakes from its first sample
    assert edges[0] == lead and edges[-1] == runs[0].n_samples + runs[1].n_samples
    # every block the same amount of shaking, to the sample (the edges are rounded)
    assert np.all(np.abs(np.diff(edges) - shaking / BLOCKS) <= 1.0), np.diff(edges)
