"""The MJCF rig: analytic M, C, K exactly, every scenario steps without warnings."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import momentid as mi
from momentid.lab import rig
from momentid.lab.scenario import Run, Scenario
from momentid.lab.simulation import ground_motion_of, simulate_run

from conftest import ROOT, SCENARIOS, load, scenario_files


def structure(d: int) -> mi.Structure:
    rng = np.random.default_rng(d)
    return mi.Structure(
        masses=tuple(rng.uniform(5, 20, d)), storey_stiffness=tuple(rng.uniform(1e3, 5e3, d)),
        storey_heights=(0.3,) * d, rayleigh_mu=0.05, rayleigh_kappa=0.002,
    )


def floor_matrices(model: mujoco.MjModel, data: mujoco.MjData):
    """Mass, damping and stiffness of the floor rows, read back from MuJoCo."""
    nv = model.nv
    full = np.zeros((nv, nv))
    mujoco.mj_forward(model, data)
    mujoco.mj_fullM(model, data, full)
    d = nv - 1
    K = np.zeros((d, d))
    C = np.zeros((d, d))
    for j in range(d):       # unit displacement / velocity of floor j -> passive force
        for target, matrix in ((data.qpos, K), (data.qvel, C)):
            mujoco.mj_resetData(model, data)
            target[1 + j] = 1.0
            mujoco.mj_forward(model, data)
            matrix[:, j] = -data.qfrc_passive[1:]
    return full[1:, 1:], C, K


@pytest.mark.parametrize("d", [1, 2, 3, 7, 20])
def test_rig_carries_the_analytic_matrices(d):
    s = structure(d)
    added = np.linspace(0.0, 1.0, d)
    model = rig.compile_model(rig.build_spec(s, added))
    M, C, K = floor_matrices(model, mujoco.MjData(model))
    # Exact up to round-off of sums of a few products (1e-12 relative).
    assert np.allclose(M, s.mass_matrix() + np.diag(added), rtol=1e-12, atol=0)
    assert np.allclose(K, s.stiffness_matrix(), rtol=1e-12, atol=1e-9)
    assert np.allclose(C, s.damping_matrix(added), rtol=1e-12, atol=1e-12)


def test_bad_model_input_is_refused():
    with pytest.raises(mi.ModelError, match="added_mass"):
        rig.build_spec(structure(3), [0.1, -0.1, 0.0])
    with pytest.raises(mi.ModelError, match="timestep"):
        rig.build_spec(structure(3), None, timestep=0.0)


def test_shipped_mjcf_is_the_builders_output():
    sc = load("paper_harmonic")
    spec = rig.build_spec(sc.structure, None, timestep=sc.timestep)
    spec.compiler.saveinertial = True
    shipped = (ROOT / "models" / "shear_building" / "shear_building.xml").read_text()
    assert shipped == spec.to_xml(), "regenerate models/shear_building/shear_building.xml (see its README)"
    scene = mujoco.MjModel.from_xml_path(str(ROOT / "models" / "shear_building" / "scene.xml"))
    assert scene.njnt == 4 and scene.ntendon == 3


@pytest.mark.parametrize("path", scenario_files(recursive=True), ids=lambda p: p.stem)
def test_every_scenario_steps_without_warnings(path):
    sc = load(str(path.relative_to(SCENARIOS).with_suffix("")))
    short = Scenario(**{**sc.__dict__, "duration": 0.2})   # 0.2 s: a few hundred steps
    motion = ground_motion_of(sc)
    for run in sc.runs:
        data = simulate_run(short, run, motion)   # raises SimulationError on any MuJoCo warning
        assert np.all(np.isfinite(data.values))


def test_warnings_and_divergence_are_errors():
    sc = load("default")
    stiff = mi.Structure(masses=(1e-3,), storey_stiffness=(1e9,), storey_heights=(0.3,),
                         rayleigh_mu=0.0, rayleigh_kappa=0.0)
    bad = Scenario(**{**sc.__dict__, "structure": stiff, "duration": 0.1,
                      "runs": (Run("r", (0.0,)), Run("s", (1.0,)))})
    with pytest.raises(mi.SimulationError, match="step below"):
        mi.simulate(bad)


@pytest.mark.parametrize("name", ["paper_harmonic", "paper_elcentro"])
def test_rig_equals_the_exact_discretisation(name):
    """MuJoCo's rollout of the rig = the linear model solved exactly for a table
    acceleration linear between steps (the drive the rig's table actuator makes)."""
    from momentid.estimation.linear import discretize, outputs, simulate_linear

    sc = load(name)
    short = Scenario(**{**sc.__dict__, "duration": 4.0})
    motion = ground_motion_of(sc)
    run = sc.runs[-1]
    data = simulate_run(short, run, motion)
    # The table reads its command z''(t_k) up to 1 / TABLE_INERTIA_RATIO (1e-10) of the
    # structure's reaction; 1e-9 of the peak leaves room for round-off.
    assert np.max(np.abs(data["zdd"] - motion.acceleration(data.time))) < 1e-9 * np.abs(data["zdd"]).max()
    s, dm = sc.structure, np.asarray(run.added_mass)
    M = s.mass_matrix() + np.diag(dm)
    lin = discretize(M, s.damping_matrix(dm), s.stiffness_matrix(), sc.timestep)
    exact = outputs(lin, simulate_linear(lin, data["zdd"]))
    for g in ("q", "v", "a"):
        got = data.values[:, [data.channels.index(f"{g}{i + 1}") for i in range(s.storeys)]]
        # RK4's global error at w h ~ 0.05 (highest mode, 1 kHz) is ~1e-8 of the peak; 1e-7 bounds it.
        assert np.max(np.abs(got - exact[g])) < 1e-7 * np.abs(exact[g]).max(), g


def test_callback_applies_the_storey_force_laws():
    """The simulator's fast callback and ``rig.callback_forces`` are the same physics."""

    from momentid.core.structure import Mechanism

    from momentid.lab import simulation as sim
    s = structure(4)
    mechanisms = (Mechanism("coulomb_friction", 2, (("force", 0.7),)),
                  Mechanism("cubic_stiffness", 1, (("k3", 2e7),)),
                  Mechanism("stiffness_loss", 4, (("fraction", 0.3), ("time", 0.5))))
    model = rig.compile_model(rig.build_spec(s, None, mechanisms=mechanisms))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    callback = sim.CallbackForces(model, mechanisms, s)
    for t in (0.2, 0.7):
        data.qpos[1:] = rng.normal(0, 2e-3, 4)
        data.qvel[1:] = rng.normal(0, 2e-3, 4)
        data.time = t
        callback(model, data)
        want = rig.callback_forces(mechanisms, data.qpos[1:], data.qvel[1:], t, s)[0]
        # Same formulas, evaluated in another order: round-off apart.
        assert np.allclose(data.qfrc_applied[1:], want, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("floor", [1, 2])
def test_callback_forces_reach_the_floors_past_an_attachment(floor):
    """Issue 30's bug: an attachment with a joint of its own (``flexible_added_mass``) on floor 1 or 2
    beside any callback kind was refused ("floor joints' dofs [1, 3, 4] are not one after another").
    Its dof sits between two floors' dofs: the callback still pushes exactly the floors, and the rig
    simulates."""
    from momentid.core.structure import Mechanism
    from momentid.lab import simulation as sim

    s = structure(3)
    added = np.zeros(3)
    added[floor - 1] = 1.5
    mechanisms = (Mechanism("flexible_added_mass", floor, (("frequency", 6.0), ("damping_ratio", 0.05))),
                  Mechanism("coulomb_friction", 3, (("force", 0.7),)),
                  Mechanism("cubic_stiffness", 1, (("k3", 2e7),)))
    model = rig.compile_model(rig.build_spec(s, added, mechanisms=mechanisms))
    dofs = [int(model.jnt_dofadr[model.joint(f"q{i + 1}").id]) for i in range(3)]
    assert dofs != [1, 2, 3]                            # the attachment's dof sits between the floors'
    data = mujoco.MjData(model)
    rng = np.random.default_rng(floor)
    data.qpos[1:] = rng.normal(0, 2e-3, model.nq - 1)
    data.qvel[1:] = rng.normal(0, 2e-3, model.nv - 1)
    sim.CallbackForces(model, mechanisms, s)(model, data)
    want = rig.callback_forces(mechanisms, data.qpos[dofs], data.qvel[dofs], 0.0, s)[0]
    # Same formulas, evaluated in another order: round-off apart.
    assert np.allclose(data.qfrc_applied[dofs], want, rtol=1e-12, atol=1e-15)
    attachment = [i for i in range(1, model.nv) if i not in dofs]
    assert np.all(data.qfrc_applied[attachment] == 0.0)  # no callback force on the attachment
    scenario = load("default")
    short = Scenario(**{**scenario.__dict__, "duration": 0.5, "structure": s, "truth": mechanisms,
                        "runs": (Run("r1", tuple(added)),)})
    run = simulate_run(short, short.runs[0], ground_motion_of(short))
    assert np.all(np.isfinite(run.values))
