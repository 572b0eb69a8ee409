"""A joint-friction twin (Iwan sliders: MuJoCo friction loss, implicitfast, PGS), a cubic-spring and a
quadratic-damping twin (a tendon's polynomial stiffness or damping) replayed in compiled code (issue 31): the
same readings as ``mujoco.rollout`` to round-off on both shipped rigs, per-model drives included, and a twin
with anything else nonlinear, or coupled friction rows, is refused."""

from __future__ import annotations

import numpy as np
import pytest

import momentid as mi
from momentid.core.structure import Mechanism
from momentid.diagnosis.twin.folds import linear_start
from momentid.errors import ModelError
from momentid.lab import resim, step_replay
from momentid.twin import fit as twin_fit
from momentid.twin.fitted_rig import friction_start, storey_levels

from conftest import DATA, rollout_and_replay

#: Relative agreement of the two replays: the step maps are centred differences of a linear map (exact to
#: round-off) and each slider's row is solved exactly where PGS converges on it in one sweep; stick-slip
#: switches amplify round-off over a record, measured 5e-12 of the signal over the flexible rig's 12 000
#: samples (8e-14 on the stiff rig's; a cubic spring 1e-13); 1e-9 leaves room for another BLAS or compiler.
ROUND_OFF = 1e-9


def _friction_twin(rig: str, start_trial: str, trial: str):
    experiment = mi.import_folder(DATA / "mini_shake_table" / rig)
    tr = twin_fit.trial(experiment.run(trial), experiment.storeys)
    storeys = tuple(range(1, experiment.storeys + 1))
    return friction_start(linear_start(experiment, start_trial), storeys, 0.3, 2e-3, -0.4), tr


def _cubic_twin(rig: str, start_trial: str, trial: str, hardening: float):
    """The rig's linear twin with a cubic spring in every storey that changes the storey's tangent stiffness by
    ``hardening`` of itself at the trial's peak drift (softening below 0)."""
    experiment = mi.import_folder(DATA / "mini_shake_table" / rig)
    tr = twin_fit.trial(experiment.run(trial), experiment.storeys)
    linear = linear_start(experiment, start_trial)
    levels = storey_levels(linear, [tr])
    springs = tuple(Mechanism("cubic_spring", s, (("k3", hardening * k / (3.0 * drift ** 2)),))
                    for s, (k, _, drift, _) in levels.items())
    return twin_fit.FittedRig(linear.masses, linear.stiffness, linear.damping_ratio, springs), tr


@pytest.mark.parametrize("rig, start_trial, trial", [("stiff_1storey", "el_centro_1", "northridge_1"),
                                                     ("flexible_3storey", "sine_1p0", "northridge")])
def test_a_friction_twin_replays_as_mujocos_rollout(rig, start_trial, trial, monkeypatch):
    twin, tr = _friction_twin(rig, start_trial, trial)
    substeps = resim.substeps_for(tr.dt)
    models = resim.compile_models([twin.rig(), twin.rig()], tr.dt / substeps)
    assert step_replay.applies(models)
    loss = models[0].dof_frictionloss.copy()
    rolled, replayed = rollout_and_replay(step_replay, models, tr.zdd, tr.dt, substeps, monkeypatch)
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
    rolled, replayed = rollout_and_replay(step_replay, models, drives, tr.dt, substeps, monkeypatch)
    scale = np.sqrt(np.mean(rolled ** 2))
    assert np.max(np.abs(replayed - rolled)) <= ROUND_OFF * scale
    alone = resim.simulate(models[1:], drives[1], tr.dt, substeps)[0]
    assert np.max(np.abs(alone - replayed[1])) <= ROUND_OFF * scale


def _damped_twin(rig: str, start_trial: str, trial: str, share: float):
    """The rig's linear twin with a quadratic damper in every storey, ``share`` times as strong as the storey's
    viscous damping at the trial's peak drift velocity."""
    experiment = mi.import_folder(DATA / "mini_shake_table" / rig)
    tr = twin_fit.trial(experiment.run(trial), experiment.storeys)
    linear = linear_start(experiment, start_trial)
    dampers = tuple(Mechanism("quadratic_damping", s, (("c2", share * max(c, 1e-9) / velocity),))
                    for s, (_, c, _, velocity) in storey_levels(linear, [tr]).items())
    return twin_fit.FittedRig(linear.masses, linear.stiffness, linear.damping_ratio, dampers), tr


@pytest.mark.parametrize("rig, start_trial, trial", [("stiff_1storey", "el_centro_1", "northridge_1"),
                                                     ("flexible_3storey", "sine_1p0", "northridge")])
@pytest.mark.parametrize("tendons, size", [(_cubic_twin, 1.0), (_cubic_twin, -0.1), (_damped_twin, 0.5),
                                           (_damped_twin, 50.0)])
def test_a_polynomial_tendon_twin_replays_as_mujocos_rollout(rig, start_trial, trial, tendons, size, monkeypatch):
    """A hardening or softening cubic spring, a light or heavy quadratic damper in every storey.  implicitfast
    differentiates a polynomial damper: the replay carries that share of its update too (without it, the
    flexible rig's replay is 3.5 % of the signal off at half the viscous damping)."""
    twin, tr = tendons(rig, start_trial, trial, size)
    substeps = resim.substeps_for(tr.dt)
    models = resim.compile_models([twin.rig()], tr.dt / substeps)
    assert np.any(models[0].tendon_stiffnesspoly) or np.any(models[0].tendon_dampingpoly)
    assert step_replay.applies(models)
    rolled, replayed = rollout_and_replay(step_replay, models, tr.zdd, tr.dt, substeps, monkeypatch)
    scale = np.sqrt(np.mean(rolled ** 2))
    assert np.max(np.abs(replayed - rolled)) <= ROUND_OFF * scale
    # the tendons' forces are in the replay: the linear twin reads otherwise, far beyond round-off
    linear = resim.compile_models([twin_fit.FittedRig(twin.masses, twin.stiffness, twin.damping_ratio).rig()],
                                  tr.dt / substeps)
    assert np.max(np.abs(resim.simulate(linear, tr.zdd, tr.dt, substeps)[0] - replayed[0])) > 1e-3 * scale


def test_a_twin_with_a_compiled_law_is_refused():
    """A compiled law under RK4 (Bouc-Wen's) is :mod:`momentid.lab.native_replay`'s, not this replay's."""
    bouc_wen = (("alpha", 0.9), ("yield_drift", 1e-3), ("exponent", 2.0), ("beta", 0.5))
    twin = twin_fit.FittedRig(np.array([0.179]), np.array([[3400.0]]), np.array([0.002]),
                              (Mechanism("bouc_wen", 1, bouc_wen),))
    model = resim.compile_models([twin.rig()], 1.0 / 240)[0]
    with pytest.raises(ModelError, match="its sliders' friction loss and its fixed tendons'"):
        step_replay.check(model)
    assert not step_replay.applies([model])


def test_a_damper_across_dofs_the_implicit_update_couples_is_refused():
    """A polynomial damper on a tendon across a dof and its ancestor's: implicitfast keeps that off-diagonal
    entry of its derivative, which the replay's diagonal update does not carry."""
    import mujoco

    spec = mujoco.MjSpec.from_string("""<mujoco><option integrator="implicitfast"/><worldbody>
      <body name="a"><joint name="q1" type="slide" axis="1 0 0"/><geom size=".1" mass="1" contype="0"/>
        <body name="b"><joint name="q2" type="slide" axis="1 0 0"/><geom size=".1" mass="1" contype="0"/>
        </body></body></worldbody>
      <actuator><general joint="q1" dyntype="integrator" gaintype="fixed" gainprm="1"/></actuator></mujoco>""")
    tendon = spec.add_tendon(name="across")
    tendon.wrap_joint("q2", 1.0)
    tendon.wrap_joint("q1", -1.0)
    tendon.damping = [0.0, 5.0, 0.0]
    with pytest.raises(ModelError, match="polynomial damper across dofs that implicitfast's update couples"):
        step_replay.check(spec.compile())


def test_coupled_friction_rows_are_refused(monkeypatch):
    """PGS's solution is the row-by-row one only where the rows do not couple: a model whose rows couple by
    more than :data:`~momentid.lab.step_replay.MAX_COUPLING` is left to ``mujoco.rollout`` (here the
    sliders' 1e-13, refused by a bound of 0)."""
    twin, tr = _friction_twin("stiff_1storey", "el_centro_1", "northridge_1")
    model = resim.compile_models([twin.rig()], tr.dt / resim.substeps_for(tr.dt))[0]
    step_replay.check(model)
    monkeypatch.setattr(step_replay, "MAX_COUPLING", 0.0)
    with pytest.raises(ModelError, match="friction rows coupled by"):
        step_replay.check(model)


@pytest.mark.parametrize("twin_of", ["friction, negative damping", "softening cubic spring"])
def test_a_diverging_twin_reads_its_blow_up_finite(twin_of, monkeypatch):
    """A twin that grows without bound (a negative damping; a softening spring that snaps through) is reset to
    rest when a state or an acceleration passes 1e10, as ``mj_step`` resets it; up to the blow-up the two
    replays agree, and the replay stays finite (``mujoco.rollout`` stops stepping a reset model until the
    next of momentid's chunks: after it they differ).  A point that far off is a residual of 1e10 either way."""
    if twin_of.startswith("friction"):
        twin, tr = _friction_twin("stiff_1storey", "el_centro_1", "northridge_1")
        twin = twin_fit.FittedRig(twin.masses, twin.stiffness, np.array([-0.5]), twin.friction)
    else:
        twin, tr = _cubic_twin("stiff_1storey", "el_centro_1", "northridge_1", -0.2)
    substeps = resim.substeps_for(tr.dt)
    models = resim.compile_models([twin.rig()], tr.dt / substeps)
    rolled, replayed = rollout_and_replay(step_replay, models, tr.zdd, tr.dt, substeps, monkeypatch)
    assert np.all(np.isfinite(replayed))
    a, b = rolled[0, :, 0], replayed[0, :, 0]
    peak = int(np.argmax(np.abs(a)))                     # the blow-up's last reading before MuJoCo's reset
    scale = np.sqrt(np.mean(a[:peak // 2] ** 2))
    assert abs(a[peak]) > 30 * scale and a[peak + 1] == 0.0 and b[peak + 1] == 0.0     # both reset there
    through = slice(0, peak + 2)
    assert np.all(np.abs(b[through] - a[through]) <= ROUND_OFF * np.maximum(np.abs(a[through]), scale))
