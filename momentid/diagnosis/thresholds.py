"""The diagnosis's decision thresholds, one name each, shared by every stage."""

from __future__ import annotations

__all__ = ["EXCESS", "EXPLAINED", "ACCEPTED", "NOTHING_TO_EXPLAIN", "BLOCK_S", "UNSTABLE_MISFIT", "removed_share"]

#: A residual above this multiple of its noise-only level counts as a mismatch: equation and replay
#: residual RMS (:mod:`~momentid.diagnosis.added_mass.residuals`), storey/run/window excess
#: (:mod:`~momentid.diagnosis.added_mass.locate`) and the kinematic check's weighted residual power per
#: frequency bin (:mod:`~momentid.diagnosis.added_mass.kinematic_check`).  Noise alone gives ratios near 1; 1.3
#: leaves room for the scatter of the estimates and the approximations of the noise propagation.
EXCESS = 1.3

#: A screened candidate must explain this share of the excess (on held-out blocks) to be named.
EXPLAINED = 0.5

#: A rig is linear within its trials when the linear twin refitted to the training trials predicts a
#: held-out trial within this factor of a linear twin fitted to that trial itself: no model without
#: amplitude dependence does better than that fit, so the room left for physics is within the fits' scatter.
LINEAR_ROOM = 1.2

#: ... and its augmented model must remove this share of the training runs' replay misfit above the
#: noise (0.75: the misfit at least halves when noise is negligible).
ACCEPTED = 0.75

#: A fit's residual within 2 % of the noise-only level leaves nothing to explain (its "explained"
#: share would divide by a difference of two nearly equal numbers).
NOTHING_TO_EXPLAIN = 1.02

#: Length (s) of the alternate time blocks of screening: fitted on even blocks, scored on odd ones.
#: 1 s: several periods of the slowest mode, so a block's samples are not the neighbours' echo.
BLOCK_S = 1.0

#: Misfit (sum of squares) of a trial model that goes unstable in a replay: worse than any fit, finite
#: for the searches (a one-parameter line search and the several-parameter Gauss-Newton alike).
UNSTABLE_MISFIT = 1e200


def removed_share(before: float, after: float, noise: float) -> float:
    """Share of ``before``'s misfit power above noise that ``after`` removes (<= 1; 0 when ``before`` is
    at the noise): what the accelerometer-only paths (modal, twin) compare with :data:`EXPLAINED`.

    Parameters
    ----------
    before, after, noise : float
        Held-out NRMSE of the linear model, of the candidate, and of sensor noise alone (1).
    """
    excess = before ** 2 - noise ** 2
    return float((before ** 2 - after ** 2) / excess) if excess > 0 else 0.0
