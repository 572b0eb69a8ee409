"""A linear twin replayed as MuJoCo's own step map (issue 31: fewer and cheaper replays): the same
readings as ``mujoco.rollout`` to round-off, and a twin with a mechanism is refused."""

from __future__ import annotations

import numpy as np
import pytest

import momentid as mi
from momentid.core.structure import Mechanism
from momentid.diagnosis.twin.folds import linear_start
from momentid.errors import ModelError
from momentid.lab import linear_replay, resim
from momentid.lab.sensors import gain_and_delay
from momentid.twin import fit as twin_fit

from conftest import DATA

#: Relative agreement of the two replays: the step is linear, so centred differences give its maps to
#: round-off (about 1e-13 of the signal measured over 12 000 samples); 1e-9 leaves room for another BLAS.
ROUND_OFF = 1e-9


@pytest.mark.parametrize("rig, start_trial, trial", [("stiff_1storey", "el_centro_1", "northridge_1"),
                                                     ("flexible_3storey", "sine_1p0", "northridge")])
def test_a_linear_twin_replays_as_mujocos_rollout(rig, start_trial, trial):
    experiment = mi.import_folder(DATA / "mini_shake_table" / rig)
    twin = linear_start(experiment, start_trial)
    tr = twin_fit.trial(experiment.run(trial), experiment.storeys)
    substeps = resim.substeps_for(tr.dt)
    models = resim.compile_models([twin.rig(), twin.rig()], tr.dt / substeps)
    rolled = resim.simulate(models, tr.zdd, tr.dt, substeps)
    replayed = resim.simulate(models, tr.zdd, tr.dt, substeps, linear=True)
    assert replayed.shape == rolled.shape
    scale = np.sqrt(np.mean(rolled ** 2))
    assert np.max(np.abs(replayed - rolled)) <= ROUND_OFF * scale


@pytest.mark.parametrize("kind, parameters", [("cubic_spring", {"k3": 2.0e6}), ("quadratic_damping", {"c2": 30.0}),
                                              ("joint_friction", {"stiffness": 300.0, "slip_drift": 1e-3,
                                                                  "exponent": 0.0})])
def test_a_twin_with_a_mechanism_is_not_replayed_as_linear(kind, parameters):
    twin = twin_fit.FittedRig(np.array([0.179]), np.array([[3400.0]]), np.array([0.002]),
                              (Mechanism(kind, 1, tuple(parameters.items())),))
    model = resim.compile_models([twin.rig()], 1.0 / 240)[0]
    with pytest.raises(ModelError, match="expected a linear twin"):
        linear_replay.check_linear(model)
    linear_replay.check_linear(resim.compile_models([twin_fit.FittedRig(twin.masses, twin.stiffness,
                                                                        twin.damping_ratio).rig()], 1.0 / 240)[0])


def test_one_map_per_sample_is_the_step_map_repeated():
    """A control held over each sample's substeps replays one lifted map per sample; a control that varies
    inside a sample steps every substep.  A change after the last reading varies the last sample only
    where it is never read, so both paths must read the same to round-off."""
    experiment = mi.import_folder(DATA / "mini_shake_table" / "stiff_1storey")
    twin = linear_start(experiment, "el_centro_1")
    tr = twin_fit.trial(experiment.run("northridge_1"), experiment.storeys)
    substeps = 3
    model = resim.compile_models([twin.rig()], tr.dt / substeps)[0]
    held = np.repeat(np.diff(tr.zdd, append=tr.zdd[-1]) / tr.dt, substeps)
    varied = held.copy()
    varied[-1] += 1.0                     # after the last sample's reading: never read
    rows = np.arange(model.nsensordata)
    lifted = linear_replay.simulate([model], held, float(tr.zdd[0]), rows, substeps)
    stepped = linear_replay.simulate([model], varied, float(tr.zdd[0]), rows, substeps)
    assert lifted.shape == stepped.shape == (1, tr.zdd.size, rows.size)
    assert np.max(np.abs(lifted - stepped)) <= ROUND_OFF * np.sqrt(np.mean(stepped ** 2))


def test_sensors_read_a_batch_as_each_simulation_alone():
    rng = np.random.default_rng(0)
    a = rng.standard_normal((4, 500, 3))
    gain, offset = np.array([1.01, 0.98, 1.0]), np.array([0.002, -0.001, 0.0])
    batch = gain_and_delay(a, gain, offset, 0.01)
    alone = np.stack([gain_and_delay(x, gain, offset, 0.01) for x in a])
    assert np.array_equal(batch, alone)   # the same transforms, one call: bit for bit
