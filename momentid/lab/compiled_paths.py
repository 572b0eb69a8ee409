"""Which compiled replay carries a batch of models, if any: the choice :func:`momentid.lab.resim.simulate`
(a twin's fits) and :func:`momentid.lab.simulation.replay` (the diagnosis's replays of a lab rig) both make.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco

from momentid.lab import native_replay, step_replay
from momentid.lab.replay_batch import Replay

__all__ = ["compiled_path"]


def compiled_path(models: Sequence[mujoco.MjModel]) -> Replay | None:
    """The compiled replay that carries every one of ``models`` as ``mujoco.rollout`` steps them, else None.

    Parameters
    ----------
    models : sequence of mujoco.MjModel
        Models of one layout (their callback forces' programs loaded).

    Returns
    -------
    Replay or None
        :func:`momentid.lab.native_replay.replay` (RK4, compiled laws the only nonlinear forces),
        :func:`momentid.lab.step_replay.replay` (a step linear but for friction rows and polynomial tendons),
        or None: ``mujoco.rollout``'s.
    """
    for path in (native_replay, step_replay):
        if path.applies(models):
            return path.replay
    return None
