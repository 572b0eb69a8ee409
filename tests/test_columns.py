"""Residuals evaluated on the machine's cores: the same numbers as one after the other."""

import numpy as np

from momentid.estimation import columns


def _residual(x):
    return np.concatenate([np.sin(x) * np.arange(1, x.size + 1), np.exp(0.1 * x) - x ** 3])


def test_points_on_workers_come_back_in_order_and_unchanged():
    points = [np.full(4, float(i)) for i in range(7)]
    with columns.point_map(_residual, workers=2) as evaluate:
        forked = evaluate(points)
    with columns.point_map(_residual, workers=1) as evaluate:
        here = evaluate(points)
    assert all(np.array_equal(a, b) for a, b in zip(forked, here)) and len(forked) == 7
