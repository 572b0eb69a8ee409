"""Residuals evaluated on the machine's cores: the same numbers as one after the other."""

import numpy as np
from scipy.optimize._numdiff import approx_derivative

from momentid.estimation import columns


def _residual(x):
    return np.concatenate([np.sin(x) * np.arange(1, x.size + 1), np.exp(0.1 * x) - x ** 3])


def test_forward_jacobian_is_scipys_two_point_bit_for_bit():
    x = np.array([0.0, -0.3, 2.5, 1e-9, -7.0])
    fun = columns.Cached(_residual)
    with columns.point_map(_residual) as evaluate:
        got = columns.forward_jacobian(fun, x, evaluate)
    # Same steps, same arithmetic: exactly equal (the fit's iterates must not depend on the cores).
    assert np.array_equal(got, approx_derivative(_residual, x, method="2-point"))


def test_points_on_workers_come_back_in_order_and_unchanged():
    points = [np.full(4, float(i)) for i in range(7)]
    with columns.point_map(_residual, workers=2) as evaluate:
        forked = evaluate(points)
    with columns.point_map(_residual, workers=1) as evaluate:
        here = evaluate(points)
    assert all(np.array_equal(a, b) for a, b in zip(forked, here)) and len(forked) == 7


def test_the_cached_value_is_reused_only_at_the_same_point():
    calls = []
    fun = columns.Cached(lambda x: calls.append(x.copy()) or x * 2.0)
    fun(np.array([1.0, 2.0]))
    assert np.array_equal(fun.at(np.array([1.0, 2.0])), [2.0, 4.0]) and len(calls) == 1
    assert np.array_equal(fun.at(np.array([1.0, 3.0])), [2.0, 6.0]) and len(calls) == 2
