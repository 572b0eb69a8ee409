"""Several parameters of one force searched together by re-simulation: a Gauss-Newton trust region on the
replay's residual, its Jacobian's columns replayed side by side with the point they belong to.

The misfit a size search minimises is a sum of squares (:meth:`~momentid.diagnosis.added_mass.resimulation.
Refitter.misfit`), so its residual vector, not only its value, is at hand.  A trust-region Gauss-Newton
search (scipy's ``least_squares``, ``trf``) on the parameters' logarithms then needs a few iterations,
each one replay of the point and one of each forward-difference column, all known together and replayed
side by side; a simplex search on the misfit's value alone (Nelder-Mead, used before) spent its 100
replays one after the other and stopped at that cap on a tuned-mass damper's three parameters.

The standard errors come from the same Jacobian at the optimum: ``cov = s^2 (J^T J)^-1`` in the
logarithms, ``s^2`` the misfit per independent sample, the Gauss-Newton form of the misfit-curvature rule
of the one-parameter search (``var = 2 s^2 / Q''`` with ``Q'' = 2 J^T J``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import scipy.optimize

from momentid.diagnosis.thresholds import UNSTABLE_MISFIT

__all__ = ["search_logs", "DIFF_STEP", "SEARCH_EVALUATIONS", "SEARCH_TOLERANCE"]

#: Forward-difference step in the parameters' logarithms (0.1 %): a replay is deterministic to round-off,
#: so the step's truncation error, not noise, bounds it from above.
DIFF_STEP = 1e-3
#: Points the search may replay (each with its Jacobian's columns) ...
SEARCH_EVALUATIONS = 15
#: ... and its tolerance on the logarithms' step (0.1 %) and on the misfit's relative decrease.
SEARCH_TOLERANCE = 1e-3
MISFIT_TOLERANCE = 1e-6
#: Largest change of a parameter from its start (a factor of 100 either way): a search that runs further
#: has found another rig's dynamics.
SPAN = np.log(100.0)


def search_logs(residuals: Callable[[Sequence[np.ndarray]], list], x0: np.ndarray, independent: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Minimise the sum of squares of ``residuals`` over the logarithms ``x``, from ``x0``.

    Parameters
    ----------
    residuals : callable
        A list of points (each shape (n,)) -> their residual vectors (each shape (m,), the same m), or
        None for a point whose model goes unstable; the points of a call are replayed side by side.
    x0 : ndarray, shape (n,)
        The start (logarithms of the parameters).
    independent : float
        Independent samples behind the residual (its band-limited channels' samples).

    Returns
    -------
    x : ndarray, shape (n,)
        The optimum (the start when the start goes unstable).
    std : ndarray, shape (n,)
        Standard errors of ``x`` (inf where the residual does not determine them).
    """
    x0 = np.asarray(x0, float)
    n = x0.size
    last: dict[bytes, np.ndarray | None] = {}

    def batch(x: np.ndarray) -> None:
        """Replay ``x`` and its forward-difference neighbours together, unless they are the last batch."""
        if x.tobytes() in last:
            return
        points = [x] + [x + DIFF_STEP * e for e in np.eye(n)]
        last.clear()
        last.update(zip((p.tobytes() for p in points), residuals(points)))

    batch(x0)
    start = last[x0.tobytes()]
    if start is None:
        return x0, np.full(n, np.inf)
    unstable = np.full(start.size, np.sqrt(UNSTABLE_MISFIT / start.size))   # finite, worse than any fit

    def fun(x: np.ndarray) -> np.ndarray:
        batch(x)
        r = last[x.tobytes()]
        return unstable if r is None else r

    def jac(x: np.ndarray, *_) -> np.ndarray:
        batch(x)
        base = fun(x)
        J = np.zeros((base.size, n))
        for i, e in enumerate(np.eye(n)):
            r = last[(x + DIFF_STEP * e).tobytes()]
            if r is not None:         # a neighbour that goes unstable: the parameter held this iteration
                J[:, i] = (r - base) / DIFF_STEP
        return J

    res = scipy.optimize.least_squares(fun, x0, jac=jac, bounds=(x0 - SPAN, x0 + SPAN), method="trf",
                                       x_scale=1.0, xtol=SEARCH_TOLERANCE, ftol=MISFIT_TOLERANCE, gtol=1e-12,
                                       max_nfev=SEARCH_EVALUATIONS)
    best = np.asarray(res.x, float)
    r, J = fun(best), jac(best)
    s2 = float(r @ r) / max(independent - 1.0, 1.0)
    information = J.T @ J
    std = np.full(n, np.inf)
    if np.all(np.isfinite(information)) and np.linalg.cond(information) < 1e12:
        std = np.sqrt(np.maximum(s2 * np.diag(np.linalg.inv(information)), 0.0))
    return best, std
