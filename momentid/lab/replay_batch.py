"""The batch around a compiled replay: many models of one layout under one table drive or one each, replayed
on threads (the compiled loops release the GIL), each read at the same sensordata entries.

:mod:`momentid.lab.native_replay` and :mod:`momentid.lab.step_replay` replay one model at a time; this
module shapes their inputs and output and spreads their models over threads.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Protocol
from concurrent.futures import ThreadPoolExecutor

import mujoco
import numpy as np

from momentid.errors import ModelError

__all__ = ["Replay", "replay_batch", "accepts"]


class Replay(Protocol):
    """How a compiled path replays one model (:func:`momentid.lab.native_replay.replay`,
    :func:`momentid.lab.step_replay.replay`)."""

    def __call__(self, model: mujoco.MjModel, rows: np.ndarray, substeps: int, x: np.ndarray, control: np.ndarray,
                 out: np.ndarray) -> int:
        """Replay ``model`` from state ``x`` under the table's jerk ``control``.

        Parameters
        ----------
        model : mujoco.MjModel
            A twin the path accepts (its ``check``).
        rows : ndarray of int, shape (k,)
            The sensordata entries read.
        substeps : int
            Integrator steps per reading.
        x : ndarray, shape (2 nv + na,)
            Positions, velocities and activations at the start; the end state on return.
        control : ndarray, shape (n_steps,)
            The table actuator's control (m/s^3) at each step.
        out : ndarray, shape (ceil(n_steps / substeps), k)
            The readings, written as ``mujoco.rollout`` reads them.

        Returns
        -------
        int
            How many times the model was reset to rest as ``mj_step`` resets it (a state or acceleration NaN
            or beyond 1e10: each a MuJoCo warning).
        """


def replay_batch(models: Sequence[mujoco.MjModel], jerk: np.ndarray, act0: np.ndarray, rows: np.ndarray,
                 substeps: int, threads: int,
                 replay: Replay) -> np.ndarray:
    """Sensor readings of ``models`` under a table jerk, one reading per sample, each model by ``replay``.

    Parameters
    ----------
    models : sequence of mujoco.MjModel
        Twins of one layout.
    jerk : ndarray, shape (n_steps,) or (len(models), n_steps)
        The table actuator's control at each integrator step (m/s^3), for every model or one per model.
    act0 : float or ndarray, shape (len(models),)
        The table's acceleration (m/s^2) at the start (its actuator's activation); the rest at rest.
    rows : ndarray of int, shape (k,)
        The sensordata entries read.
    substeps : int
        Integrator steps per sample: readings at steps 0, ``substeps``, ...
    threads : int
        Models replayed at once.
    replay : Replay
        How each model is replayed (e.g. :func:`momentid.lab.native_replay.replay`).

    Returns
    -------
    ndarray, shape (len(models), ceil(n_steps / substeps), len(rows))
        The readings, as ``mujoco.rollout`` returns them at those steps.
    """
    jerk = np.atleast_2d(np.asarray(jerk, float))
    act0 = np.broadcast_to(np.asarray(act0, float), (len(models),))
    rows = np.asarray(rows, int)
    out = np.empty((len(models), -(-jerk.shape[1] // substeps), rows.size))

    def one(k):
        model = models[k]
        x = np.zeros(2 * model.nv + model.na)
        x[2 * model.nv + int(model.actuator_actadr[0])] = act0[k]
        replay(model, rows, substeps, x, np.ascontiguousarray(jerk[k if jerk.shape[0] > 1 else 0]), out[k])

    if threads > 1 and len(models) > 1:
        with ThreadPoolExecutor(min(threads, len(models))) as pool:
            list(pool.map(one, range(len(models))))
    else:
        for k in range(len(models)):
            one(k)
    return out


def accepts(check: Callable[[mujoco.MjModel], None], models: Sequence[mujoco.MjModel]) -> bool:
    """True when ``models`` is not empty and ``check`` (a path's, raising
    :class:`~momentid.errors.ModelError` for a model it cannot replay) passes every one of them."""
    if not models:
        return False
    try:
        for m in models:
            check(m)
    except ModelError:
        return False
    return True

