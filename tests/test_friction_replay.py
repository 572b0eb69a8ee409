"""A joint-friction twin (Iwan sliders: MuJoCo friction loss, implicitfast, PGS) replayed in compiled code
(issue 31): the same readings as ``mujoco.rollout`` to round-off on both shipped rigs, per-model drives
included, and a twin with anything else nonlinear, or coupled friction rows, is refused."""

from __future__ import annotations

import numpy as np
import pytest

import momentid as mi
from momentid.core.structure import Mechanism
from momentid.diagnosis.twin.folds import linear_start
from momentid.errors import ModelError
from momentid.lab import friction_replay, resim
from momentid.twin import fit as twin_fit
from momentid.twin.fitted_rig import friction_start

from conftest import DATA, rollout_and_replay

#: Relative agreement of the two replays: the step maps are centred differences of a linear map (exact to
#: round-off) and each slider's row is solved exactly where PGS converges on it in one sweep; stick-slip
#: switches amplify round-off over a record, measured 1.2e-11 of the signal over the flexible rig's 12 000
#: samples (2.5e-13 on the stiff rig's); 1e-9 leaves room for another BLAS or compiler.
ROUND_OFF = 1e-9


def _friction_twin(rig: str, start_trial: str, trial: str):
    experiment = mi.import_folder(DATA / "mini_shake_table" / rig)
    tr = twin_fit.trial(experiment.run(trial), experiment.storeys)
    storeys = tuple(range(1, experiment.storeys + 1))
    return friction_start(linear_start(experiment, start_trial), storeys, 0.3, 2e-3, -0.4), tr


@pytest.mark.parametrize("rig, start_trial, trial", [("stiff_1storey", "el_centro_1", "northridge_1"),
                                                     ("flexible_3storey", "sine_1p0", "northridge")])
def test_a_friction_twin_replays_as_mujocos_rollout(rig, start_trial, trial, monkeypatch):
    twin, tr = _friction_twin(rig, start_trial, trial)
    substeps = resim.substeps_for(tr.dt)
    models = resim.compile_models([twin.rig(), twin.rig()], tr.dt / substeps)
    assert friction_replay.applies(models)
    loss = models[0].dof_frictionloss.copy()
    rolled, replayed = rollout_and_replay(friction_replay, models, tr.zdd, tr.dt, substeps, monkeypatch)
    assert replayed.shape == rolled.shape
    scale = np.sqrt(np.mean(rolled ** 2))
    assert np.max(np.abs(replayed - rolled)) <= ROUND_OFF * scale
    assert np.array_equal(models[0].dof_frictionloss, loss)          # the maps are read off a copy
    # the sliders slip in the replay: the twin without its joints' friction reads otherwise, far beyond round-off
    stuck = twin_fit.FittedRig(twin.masses, twin.stiffness, twin.damping_ratio)
    linear = resim.compile_models([stuck.rig()], tr.dt / substeps)
    assert np.max(np.abs(resim.simulate(linear, tr.zdd, tr.dt, substeps)[0] - replayed[0])) > 1e-3 * scale


def test_each_model_its_own_drive(monkeypatch):
    """A batch with one table drive per model (a Jacobian's motion columns) replays each under its own."""
    twin, tr = _friction_twin("stiff_1storey", "el_centro_1", "northridge_1")
    substeps = resim.substeps_for(tr.dt)
    other = twin_fit.FittedRig(twin.masses, 1.1 * twin.stiffness, twin.damping_ratio, twin.friction)
    models = resim.compile_models([twin.rig(), other.rig()], tr.dt / substeps)
    drives = np.stack([tr.zdd, 0.5 * tr.zdd + 0.01])
    rolled, replayed = rollout_and_replay(friction_replay, models, drives, tr.dt, substeps, monkeypatch)
    scale = np.sqrt(np.mean(rolled ** 2))
    assert np.max(np.abs(replayed - rolled)) <= ROUND_OFF * scale
    alone = resim.simulate(models[1:], drives[1], tr.dt, substeps)[0]
    assert np.max(np.abs(alone - replayed[1])) <= ROUND_OFF * scale


@pytest.mark.parametrize("kind, parameters", [(None, {}), ("cubic_spring", {"k3": 2.0e6}),
                                              ("bouc_wen", {"alpha": 0.9, "yield_drift": 1e-3, "exponent": 2.0,
                                                            "beta": 0.5})])
def test_a_twin_without_friction_loss_or_with_more_is_refused(kind, parameters):
    mechanisms = (Mechanism(kind, 1, tuple(parameters.items())),) if kind else ()
    twin = twin_fit.FittedRig(np.array([0.179]), np.array([[3400.0]]), np.array([0.002]), mechanisms)
    model = resim.compile_models([twin.rig()], 1.0 / 240)[0]
    with pytest.raises(ModelError, match="only nonlinearity is its sliders' friction loss"):
        friction_replay.check(model)
    assert not friction_replay.applies([model])


def test_coupled_friction_rows_are_refused(monkeypatch):
    """PGS's solution is the row-by-row one only where the rows do not couple: a model whose rows couple by
    more than :data:`~momentid.lab.friction_replay.MAX_COUPLING` is left to ``mujoco.rollout`` (here the
    sliders' 1e-13, refused by a bound of 0)."""
    twin, tr = _friction_twin("stiff_1storey", "el_centro_1", "northridge_1")
    model = resim.compile_models([twin.rig()], tr.dt / resim.substeps_for(tr.dt))[0]
    friction_replay.check(model)
    monkeypatch.setattr(friction_replay, "MAX_COUPLING", 0.0)
    with pytest.raises(ModelError, match="friction rows coupled by"):
        friction_replay.check(model)


def test_a_diverging_twin_reads_its_blow_up_finite(monkeypatch):
    """A twin that grows without bound (negative damping) is reset to rest when a state passes 1e10, as
    ``mj_step`` resets it; up to the blow-up the two replays agree, and the replay stays finite."""
    twin, tr = _friction_twin("stiff_1storey", "el_centro_1", "northridge_1")
    unstable = twin_fit.FittedRig(twin.masses, twin.stiffness, np.array([-0.5]), twin.friction)
    substeps = resim.substeps_for(tr.dt)
    models = resim.compile_models([unstable.rig()], tr.dt / substeps)
    rolled, replayed = rollout_and_replay(friction_replay, models, tr.zdd, tr.dt, substeps, monkeypatch)
    assert np.all(np.isfinite(replayed))
    blown = np.flatnonzero(np.abs(rolled[0, :, 0]) > 1e6)
    assert blown.size and np.max(np.abs(replayed)) > 1e8
    before = slice(0, blown[0])
    scale = np.sqrt(np.mean(rolled[0, before] ** 2))
    assert np.max(np.abs(replayed[0, before] - rolled[0, before])) <= ROUND_OFF * scale
