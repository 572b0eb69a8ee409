"""The shake table and its floors drawn moving in the rerun viewer, one run at a time.

:func:`log_rig` draws a run's rig at :data:`RIG_RATE` (table and floor boxes, storeys sheared by their
drifts, a scale bar) under ``/runs/<run>/rig``; :mod:`momentid.report.viewer` draws the recording's,
:mod:`momentid.report.twin_overlay` the twin's beside it.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from momentid.core.series import RunData
from momentid.report.scene import Scene, nice_number

if TYPE_CHECKING:
    import rerun as rr

__all__ = ["TIMELINE", "RIG_RATE", "PALETTE", "BASE_COLOR", "run_path", "rig_samples", "log_rig"]

#: The timeline of every run: seconds of experiment time.
TIMELINE = "time"
#: The 3D rig is drawn at most this often (Hz): every k-th sample, exact at those instants
#: (the viewer animates at screen rate; the time series keep every sample).
RIG_RATE = 100.0
#: Series colours, one per floor (the twin's overlay takes the second).
PALETTE = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
           (140, 86, 75), (227, 119, 194), (188, 189, 34), (23, 190, 207), (127, 127, 127)]
#: The table's series and the scale bar.
BASE_COLOR = (110, 110, 110)
_TABLE_COLOR = (120, 120, 130)


def run_path(run: str) -> str:
    """The entity path of ``run``'s tab (``/runs/<run>``, escaped)."""
    import rerun as rr

    return f"/runs/{rr.escape_entity_path_part(run)}"


def rig_samples(run: RunData) -> np.ndarray:
    """Indices of the samples the 3D rig is drawn at (at most :data:`RIG_RATE` per second)."""
    rate = run.sample_rate
    step = max(1, int(math.floor(rate / RIG_RATE))) if math.isfinite(rate) else 1
    return np.arange(0, run.n_samples, step)


def log_rig(rec: rr.RecordingStream, scene: Scene, run: RunData, root: str | None = None,
            motion: tuple[np.ndarray, np.ndarray] | None = None) -> None:
    """Draw the rig of ``run`` moving: table and floors, at ``root`` (default ``/runs/<run>/rig``),
    with ``motion = (z, q)`` (table displacement (n,), floors relative to it (n, d), m; default: the
    recording's, :meth:`Scene.drawn`)."""
    import rerun as rr

    d, X = scene.experiment.storeys, scene.exaggeration
    h = scene.heights
    level = np.concatenate([[0.0], np.cumsum(h)])
    w = float(h.max())
    root = root or f"{run_path(run.name)}/rig"
    idx = rig_samples(run)
    n = idx.size
    time = rr.TimeColumn(TIMELINE, duration=run.time[idx])
    zero = np.zeros(n)
    z, q = scene.drawn(run) if motion is None else motion
    z = zero if z is None else z[idx]
    q = np.zeros((n, d)) if q is None else q[idx]
    rec.log(root, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log(f"{root}/base", rr.Boxes3D(centers=[[0, 0, -0.04 * w]], half_sizes=[[0.9 * w, 0.6 * w, 0.04 * w]],
                                       colors=[_TABLE_COLOR], labels=[f"shake table (x{X:g})"],
                                       fill_mode="solid"), static=True)
    rec.send_columns(f"{root}/base", indexes=[time],
                     columns=rr.Transform3D.columns(translation=np.column_stack([X * z, zero, zero])))
    posts = np.array([[sx * 0.45 * w, sy * 0.3 * w] for sx in (-1, 1) for sy in (-1, 1)])
    for i in range(d):
        color = PALETTE[i % len(PALETTE)]
        below = q[:, i - 1] if i else zero
        rec.log(f"{root}/base/floor{i + 1}",
                rr.Boxes3D(half_sizes=[[0.5 * w, 0.35 * w, 0.03 * w]], colors=[color], fill_mode="solid",
                           labels=[f"floor {i + 1}"]), static=True)
        rec.send_columns(f"{root}/base/floor{i + 1}", indexes=[time], columns=rr.Transform3D.columns(
            translation=np.column_stack([X * q[:, i], zero, np.full(n, level[i + 1])])))
        rec.log(f"{root}/base/storey{i + 1}",
                rr.Boxes3D(centers=np.column_stack([posts, np.full(4, h[i] / 2)]),
                           half_sizes=[[0.01 * w, 0.01 * w, h[i] / 2]] * 4, colors=[color], fill_mode="solid"),
                static=True)
        shear = np.tile(np.eye(3), (n, 1, 1))
        shear[:, 0, 2] = X * (q[:, i] - below) / h[i]
        rec.send_columns(f"{root}/base/storey{i + 1}", indexes=[time], columns=rr.Transform3D.columns(
            translation=np.column_stack([X * below, zero, np.full(n, level[i])]), mat3x3=shear))
    peak = float(np.max(np.abs(z[:, None] + q), initial=0.0))  # of the drawn samples
    true = nice_number(peak) if peak > 0 else 0.01 / X
    rec.log(f"{root}/scale", rr.Arrows3D(origins=[[-0.5 * w, -0.7 * w, 0.0]], vectors=[[X * true, 0.0, 0.0]],
                                         colors=[BASE_COLOR], labels=[f"{true * 1e3:g} mm x{X:g}"]),
            static=True)
