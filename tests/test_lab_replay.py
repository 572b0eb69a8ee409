"""The diagnosis's replays of a lab rig (``lab.simulation.replay``) in compiled code (issue 31): a rig whose
only nonlinear forces are compiled laws runs RK4 in compiled code (``lab.native_replay``), a linear rig as its
step map (``lab.step_replay``); both read what ``mujoco.rollout`` reads to round-off, a rig with MJCF
physics still rolls out in MuJoCo, and a diverging replay is refused on every path."""

from __future__ import annotations

import numpy as np
import pytest

from momentid import mechanisms
from momentid.core.structure import Mechanism
from momentid.errors import SimulationError
from momentid.lab import native_replay, step_replay
from momentid.lab import compiled_paths
from momentid.lab import simulation as sim

from test_mechanisms import _record, _structure, _table_run

#: Relative agreement of the compiled replay and the rollout: both integrate the same RK4 tableau with the
#: same compiled laws (or the same linear step), measured 3e-13 of the signal's peak; 1e-9 leaves room for
#: another BLAS or compiler.
ROUND_OFF = 1e-9


def _both(structure, mechs, run, monkeypatch) -> tuple[dict, dict]:
    """(rollout's, compiled) replays of ``run`` through the rig with ``mechs``."""
    with monkeypatch.context() as m:
        m.setattr(native_replay, "ENABLED", False)
        m.setattr(step_replay, "ENABLED", False)
        rolled = sim.replay(structure, mechs, run)
    return rolled, sim.replay(structure, mechs, run)


@pytest.mark.parametrize("mechs", [(), ("bouc_wen",), ("coulomb_friction", "cubic_stiffness")],
                         ids=["linear", "bouc_wen", "friction+cubic"])
def test_a_lab_replay_in_compiled_code_reads_as_the_rollout(mechs, monkeypatch):
    structure, run = _structure(), _table_run()
    records = [_record(mechanisms.get(name), s + 1) for s, name in enumerate(mechs)]
    taken = []
    real = compiled_paths.compiled_path
    monkeypatch.setattr(compiled_paths, "compiled_path", lambda models: taken.append(real(models)) or taken[-1])
    rolled, compiled = _both(structure, records, run, monkeypatch)
    assert taken[-1] is (native_replay.replay if records else step_replay.replay)
    for g in ("a", "q", "v"):
        assert np.max(np.abs(compiled[g] - rolled[g])) <= ROUND_OFF * np.max(np.abs(rolled[g]))


def test_a_rig_with_mjcf_physics_rolls_out_in_mujoco(monkeypatch):
    """Joint friction's sliders in a lab rig (RK4): neither compiled path carries them."""
    structure, run = _structure(), _table_run()
    mech = Mechanism("joint_friction", 1, (("stiffness", 200.0), ("slip_drift", 0.002), ("exponent", 0.0)))
    taken = []
    real = compiled_paths.compiled_path
    monkeypatch.setattr(compiled_paths, "compiled_path", lambda models: taken.append(real(models)) or taken[-1])
    sim.replay(structure, [mech], run)
    assert taken == [None]


def test_a_diverging_replay_is_refused_on_every_path(monkeypatch):
    """A storey with a strongly softening cubic spring snaps through under the table's motion: MuJoCo's step
    resets it (a warning), and the compiled replay counts the same reset: both refuse the replay."""
    structure, run = _structure(), _table_run()
    snap = Mechanism("cubic_stiffness", 1, (("k3", -1e12),))
    with pytest.raises(SimulationError, match="diverging"):
        sim.replay(structure, [snap], run)
    with monkeypatch.context() as m:
        m.setattr(native_replay, "ENABLED", False)
        with pytest.raises(SimulationError, match="diverging"):
            sim.replay(structure, [snap], run)
