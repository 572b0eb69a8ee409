"""The errors-in-variables residual's exact Jacobian against central differences of the residual."""

from pathlib import Path

import numpy as np
import pytest

import momentid as mi
from momentid.estimation.eiv import fit_eiv, spectra, whitened_residual
from momentid.estimation.eiv_jacobian import whitened_jacobian
from momentid.estimation.layout import Layout

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


@pytest.fixture(scope="module")
def lab():
    experiment = mi.simulate(mi.load_scenario(SCENARIOS / "lab_noisy.toml"))
    s = experiment.structure
    layout = Layout(experiment.runs[0].added_mass.shape[0])
    truth = layout.pack(s.mass_matrix(), s.damping_matrix(), s.stiffness_matrix(), s.rayleigh_mu)
    return experiment, layout, truth


def _central(layout, theta, sp, rel_step):
    """Central differences of the residual, each unknown stepped by ``rel_step`` of its own size."""
    size = np.maximum(np.abs(theta), 1e-3 * np.max(np.abs(theta)))
    cols = []
    for i in range(theta.size):
        step = np.zeros_like(theta)
        step[i] = rel_step * size[i]
        cols.append((whitened_residual(layout, theta + step, sp)[0]
                     - whitened_residual(layout, theta - step, sp)[0]) / (2 * step[i]))
    return np.column_stack(cols)


def _column_errors(J, reference):
    return np.linalg.norm(J - reference, axis=0) / np.linalg.norm(reference, axis=0)


@pytest.mark.parametrize("groups", [None, ["a"]], ids=["every sensor", "accelerometers"])
def test_the_jacobian_is_the_residuals_derivative_at_the_truth(lab, groups):
    experiment, layout, truth = lab
    run = experiment.runs[1]                       # with added mass: the Rayleigh mu column is live
    sp = spectra(run, layout.d, 30.0, groups=groups)
    J = whitened_jacobian(layout, truth, sp)
    # Central differences at this step are good to about 1e-5 of a column (halving the step moves them by
    # that much); 1e-3 leaves room for the worst-scaled column and still catches any wrong term (a missing
    # one moved columns by 5-160 %).
    assert np.all(_column_errors(J, _central(layout, truth, sp, 1e-5)) < 1e-3)


def test_far_from_the_optimum_with_force_signals_the_jacobian_is_still_exact(lab):
    """A large residual: the variable projection's second term (Golub and Pereyra) counts; Kaufman's
    approximation alone is up to 30 % off here.  Force signals add columns of their own."""
    from dataclasses import replace

    experiment, layout, truth = lab
    run = experiment.runs[1]
    rng = np.random.default_rng(3)
    n = run.n_samples
    signals = np.column_stack([0.3 * run["a1"], np.sign(run[f"a{layout.d}"])])
    F = np.fft.rfft(signals, axis=0) / np.sqrt(n)
    sp = spectra(run, layout.d, 30.0)
    k = np.rint(np.angle(sp.z) / (2 * np.pi) * n).astype(int) % n
    sp = replace(sp, forces=rng.normal(size=(layout.d, 2)), F=F[k])
    theta = np.concatenate([truth * (1 + 0.02 * np.sin(np.arange(truth.size))), [0.05, 0.2]])
    r, _ = whitened_residual(layout, theta, sp)
    assert np.linalg.norm(r) > 100 * np.sqrt(r.size)          # far above the noise: a real test of the term
    J = whitened_jacobian(layout, theta, sp)
    assert J.shape == (r.size, theta.size)
    assert np.all(_column_errors(J, _central(layout, theta, sp, 1e-5)) < 1e-3)   # as above


def test_the_fit_ends_where_the_gradient_vanishes(lab):
    """The fit's end point is a minimum of the likelihood: its gradient is round-off next to the gradient
    at the truth (which noise makes no minimum), and its cost no higher."""
    experiment, layout, truth = lab
    fit = fit_eiv(layout, experiment.runs, truth * 1.05, f_max=30.0)
    assert not fit.capped
    sps = [spectra(r, layout.d, 30.0) for r in experiment.runs]

    def cost_and_gradient(theta):
        rs = [whitened_residual(layout, theta, sp)[0] for sp in sps]
        g = sum(whitened_jacobian(layout, theta, sp).T @ r for sp, r in zip(sps, rs))
        return sum(float(r @ r) for r in rs) / 2, g * np.abs(theta)   # per unit relative change

    cost, g = cost_and_gradient(fit.theta)
    cost0, g0 = cost_and_gradient(truth)
    assert cost <= cost0 and np.linalg.norm(g) < 1e-4 * np.linalg.norm(g0)
