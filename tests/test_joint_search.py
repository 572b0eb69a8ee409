"""The several-parameter size search (:mod:`momentid.diagnosis.added_mass.joint_search`): Gauss-Newton on
the logarithms, each point replayed with its Jacobian's columns, standard errors from that Jacobian."""

import numpy as np

from momentid.diagnosis.added_mass.joint_search import DIFF_STEP, search_logs


def _decay(seed: int, sigma: float):
    """A noisy damped ring ``a exp(-b t) cos(w t)``, the model's three parameters searched in logarithms."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 4.0, 800)
    truth = np.array([2.0, 0.7, 9.0])

    def model(p):
        a, b, w = p
        return a * np.exp(-b * t) * np.cos(w * t)

    y = model(truth) + rng.normal(0.0, sigma, t.size)
    return t, truth, model, y


def test_search_finds_the_least_squares_optimum_and_its_standard_errors():
    """From 20-30 % off, the search reaches the optimum of a noisy decay, its standard errors are the
    Gauss-Newton ones of the noise (their spread over 40 noise draws), and each call replays a point
    with its forward-difference columns."""
    sigma = 0.05
    found, stds, calls = [], [], []
    for seed in range(40):
        t, truth, model, y = _decay(seed, sigma)

        def residuals(xs):
            calls.append(len(xs))
            return [(y - model(np.exp(x))) / sigma for x in xs]

        best, std = search_logs(residuals, np.log(truth * [1.3, 0.75, 1.2]), independent=t.size)
        found.append(best)
        stds.append(std)
    found, stds = np.array(found), np.array(stds)
    assert set(calls) == {4}   # a point and its 3 columns, always together
    # unbiased to within 4 standard errors of the 40-draw mean (a wrong optimum is off by tens of %)
    assert np.all(np.abs(found.mean(axis=0) - np.log([2.0, 0.7, 9.0])) < 4 * stds.mean(axis=0) / np.sqrt(40))
    # the stated errors match the scatter over draws: the ratio of 40 draws' std lies within 0.7-1.4
    # (chi-square with 39 dof: 99.9 % of ratios)
    ratio = found.std(axis=0, ddof=1) / stds.mean(axis=0)
    assert np.all((0.7 < ratio) & (ratio < 1.4)), ratio


def test_an_unstable_start_is_returned_with_infinite_errors_and_unstable_columns_are_held():
    """A start that goes unstable (None) is the answer, with infinite errors; a neighbour that goes
    unstable leaves its parameter where it is for that step, never a NaN."""
    x0 = np.log([1.0, 2.0])
    best, std = search_logs(lambda xs: [None for _ in xs], x0, independent=100)
    assert np.array_equal(best, x0) and np.all(np.isinf(std))

    def residuals(xs):   # the second parameter's forward neighbour is always unstable
        return [None if x[1] > np.log(2.0) + DIFF_STEP / 2 else np.array([x[0] - 0.5, 0.1 * x[1]]) for x in xs]

    best, std = search_logs(residuals, x0, independent=100)
    # the search stops on a step below its tolerance (1e-3 of the logarithms' size), so within 2e-3
    assert np.isclose(best[0], 0.5, atol=2e-3) and best[1] <= x0[1] and np.all(np.isfinite(best))
