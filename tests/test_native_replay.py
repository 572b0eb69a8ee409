"""A twin whose only nonlinear force is a compiled law (Bouc-Wen's, under RK4) replayed in compiled code
(issue 31: compiled mechanism forces): the same readings as ``mujoco.rollout`` to round-off, per-model
drives included, and a twin with anything else nonlinear is refused."""

from __future__ import annotations

import numpy as np
import pytest

import momentid as mi
from momentid.core.structure import Mechanism
from momentid.diagnosis.twin.folds import linear_start
from momentid.errors import ModelError
from momentid.lab import native_replay, resim
from momentid.twin import fit as twin_fit

from conftest import DATA, rollout_and_replay

#: Relative agreement of the two replays: the linear part's maps are centred differences of a linear map
#: (exact to round-off) and both integrate the classical RK4 tableau with the same compiled laws; measured
#: 3e-13 of the signal over 12 000 samples; 1e-9 leaves room for another BLAS or compiler.
ROUND_OFF = 1e-9


def _bouc_wen_twin(rig: str, start_trial: str, trial: str):
    experiment = mi.import_folder(DATA / "mini_shake_table" / rig)
    tr = twin_fit.trial(experiment.run(trial), experiment.storeys)
    storeys = tuple(range(1, experiment.storeys + 1))
    return twin_fit.mechanism_start(linear_start(experiment, start_trial), "bouc_wen", storeys, [tr]), tr


@pytest.mark.parametrize("rig, start_trial, trial", [("stiff_1storey", "el_centro_1", "northridge_1"),
                                                     ("flexible_3storey", "sine_1p0", "northridge")])
def test_a_bouc_wen_twin_replays_as_mujocos_rollout(rig, start_trial, trial, monkeypatch):
    twin, tr = _bouc_wen_twin(rig, start_trial, trial)
    substeps = resim.substeps_for(tr.dt)
    models = resim.compile_models([twin.rig(), twin.rig()], tr.dt / substeps)
    assert native_replay.applies(models)
    program = models[0].numeric_data.copy()
    rolled, replayed = rollout_and_replay(native_replay, models, tr.zdd, tr.dt, substeps, monkeypatch)
    assert replayed.shape == rolled.shape
    scale = np.sqrt(np.mean(rolled ** 2))
    assert np.max(np.abs(replayed - rolled)) <= ROUND_OFF * scale
    assert np.array_equal(models[0].numeric_data, program)       # the maps are read off a copy
    # the hysteresis is in the replay: the linear twin reads otherwise, far beyond round-off
    linear = resim.compile_models([twin_fit.FittedRig(twin.masses, twin.stiffness, twin.damping_ratio).rig()],
                                  tr.dt / substeps)
    assert np.max(np.abs(resim.simulate(linear, tr.zdd, tr.dt, substeps)[0] - replayed[0])) > 1e-3 * scale


def test_each_model_its_own_drive(monkeypatch):
    """A batch with one table drive per model (a Jacobian's motion columns) replays each under its own."""
    twin, tr = _bouc_wen_twin("stiff_1storey", "el_centro_1", "northridge_1")
    substeps = resim.substeps_for(tr.dt)
    other = twin_fit.FittedRig(twin.masses, 1.1 * twin.stiffness, twin.damping_ratio, twin.friction)
    models = resim.compile_models([twin.rig(), other.rig()], tr.dt / substeps)
    drives = np.stack([tr.zdd, 0.5 * tr.zdd + 0.01])
    rolled, replayed = rollout_and_replay(native_replay, models, drives, tr.dt, substeps, monkeypatch)
    scale = np.sqrt(np.mean(rolled ** 2))
    assert np.max(np.abs(replayed - rolled)) <= ROUND_OFF * scale
    alone = resim.simulate(models[1:], drives[1], tr.dt, substeps)[0]
    assert np.max(np.abs(alone - replayed[1])) <= ROUND_OFF * scale


@pytest.mark.parametrize("kind, parameters", [(None, {}), ("cubic_spring", {"k3": 2.0e6}),
                                              ("joint_friction", {"stiffness": 300.0, "slip_drift": 1e-3,
                                                                  "exponent": 0.0})])
def test_a_twin_without_compiled_laws_or_with_more_is_refused(kind, parameters):
    mechanisms = (Mechanism(kind, 1, tuple(parameters.items())),) if kind else ()
    twin = twin_fit.FittedRig(np.array([0.179]), np.array([[3400.0]]), np.array([0.002]), mechanisms)
    model = resim.compile_models([twin.rig()], 1.0 / 240)[0]
    with pytest.raises(ModelError, match="expected an RK4 twin whose only nonlinear forces are compiled laws"):
        native_replay.check(model)
    assert not native_replay.applies([model])


def test_a_diverging_twin_is_reset_as_mujocos_step_resets_it(monkeypatch):
    """A twin that grows without bound (negative damping) is reset by MuJoCo's step when a state passes 1e10
    (``mj_resetData``).  The replay resets as ``mj_step`` does and goes on from rest; ``mujoco.rollout`` stops
    stepping a reset model until the next of momentid's chunks, so the two agree up to the reset only: a point
    that far off is a residual of 1e10 either way (a fit rejects it), never an error or a NaN."""
    twin, tr = _bouc_wen_twin("stiff_1storey", "el_centro_1", "northridge_1")
    unstable = twin_fit.FittedRig(twin.masses, twin.stiffness, np.array([-0.5]), twin.friction)
    substeps = resim.substeps_for(tr.dt)
    models = resim.compile_models([unstable.rig()], tr.dt / substeps)
    rolled, replayed = rollout_and_replay(native_replay, models, tr.zdd, tr.dt, substeps, monkeypatch)
    assert np.all(np.isfinite(replayed))
    blown = np.flatnonzero(np.abs(rolled[0, :, 0]) > 1e6)
    assert blown.size and np.max(np.abs(replayed)) > 1e8           # both blew up
    before = slice(0, blown[0])
    scale = np.sqrt(np.mean(rolled[0, before] ** 2))
    assert np.max(np.abs(replayed[0, before] - rolled[0, before])) <= ROUND_OFF * scale
