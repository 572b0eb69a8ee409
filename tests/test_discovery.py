"""The open search's pieces (issue 13, item 2): the simulator's floor forces and forces with memory,
and the function library's selection and location on forces of known law.

The blind cases (hidden rigs with pounding, Bouc-Wen hysteresis and a stiffness loss, diagnosed from
their recordings) are in ``tests/test_discrepancy.py``.
"""

from __future__ import annotations

from types import SimpleNamespace

import mujoco
import numpy as np
import pytest

import momentid as mi
from momentid.core.structure import Mechanism
from momentid.diagnosis.added_mass import open_search as discovery
from momentid.diagnosis.discovered_physics import describe
from momentid.lab import rig
from momentid.lab import simulation as sim
from momentid.mechanisms.place import Place, Target

from conftest import load

ADDED = np.array([1.0, 1.0, 2.0])


def _callback_forces(structure, mechs, qpos, qvel, act=None):
    """Generalised forces (N) the simulator's callback puts on the floor joints, at a given state."""
    model = rig.compile_model(rig.build_spec(structure, ADDED, mechanisms=mechs))
    data = mujoco.MjData(model)
    data.qpos[1:], data.qvel[1:] = qpos, qvel
    if act is not None:
        data.act[1:] = act
    callback = sim.CallbackForces(model, mechs, structure)
    callback(model, data)
    return data.qfrc_applied[1:].copy(), callback, model, data


def test_pounding_pushes_its_floor_alone_against_the_table():
    structure = load("hidden/clean").structure
    mech = Mechanism("pounding", 3, (("gap", 0.004), ("stiffness", 2e4), ("damping", 5.0)))
    qpos, qvel = np.array([0.001, 0.003, 0.005]), np.array([0.01, -0.02, 0.03])
    got, *_ = _callback_forces(structure, (mech,), qpos, qvel)
    # 1 mm into the stop, moving in at 3 cm/s: 2e4 x 1e-3 + 5 x 0.03 = 20.15 N back on floor 3 only.
    assert np.allclose(got, [0.0, 0.0, -20.15], rtol=1e-12, atol=1e-12)
    away, *_ = _callback_forces(structure, (mech,), qpos * np.array([1, 1, 0.5]), qvel)
    assert np.all(away == 0.0)   # short of the stop: no force


def test_contact_stops_push_back_on_either_side():
    structure = load("hidden/clean").structure
    mech = Mechanism("contact_stop", 2, (("gap_pos", 0.004), ("gap_neg", 0.002), ("stiffness", 2e4),
                                         ("damping", 5.0)))
    qvel = np.array([0.01, -0.02, 0.03])
    minus, *_ = _callback_forces(structure, (mech,), np.array([0.001, -0.003, 0.005]), qvel)
    # 1 mm past the - side stop, moving into it at 2 cm/s: it pushes floor 2 up by 2e4 x 1e-3 + 5 x 0.02.
    assert np.allclose(minus, [0.0, 20.1, 0.0], rtol=1e-12, atol=1e-12)
    plus, *_ = _callback_forces(structure, (mech,), np.array([0.001, 0.005, 0.005]), -qvel)
    # 1 mm past the + side stop, moving in at 2 cm/s: the same force, pushing down.
    assert np.allclose(plus, [0.0, -20.1, 0.0], rtol=1e-12, atol=1e-12)
    between, *_ = _callback_forces(structure, (mech,), np.array([0.001, 0.0035, 0.005]), qvel)
    assert np.all(between == 0.0)   # between the stops: no force
    with pytest.raises(mi.MomentidError, match="at least one side"):
        rig.build_spec(structure, ADDED, mechanisms=(Mechanism("contact_stop", 2, (
            ("gap_pos", 0.0), ("gap_neg", 0.0), ("stiffness", 2e4), ("damping", 0.0))),))


def test_bouc_wen_reads_its_state_from_the_simulator():
    structure = load("hidden/clean").structure
    p = {"alpha": 0.3, "yield_drift": 0.001, "exponent": 2.0, "beta": 0.5}
    mech = Mechanism("bouc_wen", 2, tuple(p.items()))
    qpos, qvel, z = np.array([0.001, 0.003, 0.004]), np.array([0.01, -0.02, 0.03]), 0.0008
    got, callback, model, data = _callback_forces(structure, (mech,), qpos, qvel, act=[z])
    x, v, k = qpos[1] - qpos[0], qvel[1] - qvel[0], structure.storey_stiffness[1]
    f = (1 - p["alpha"]) * k * (z - x)   # alpha k x + (1 - alpha) k z, less the tendon's k x
    assert np.allclose(got, [f, -f, 0.0], rtol=1e-12, atol=1e-12)
    # The state's rate, written out: z' = v - (beta |v| |z|^(n-1) z + gamma v |z|^n) / x_y^n.
    gamma, n, xy = 1 - p["beta"], p["exponent"], p["yield_drift"]
    want = v - (p["beta"] * abs(v) * abs(z) ** (n - 1) * z + gamma * v * abs(z) ** n) / xy ** n
    actuator = model.actuator(rig.state_actuator(0)).id
    assert np.isclose(callback.state_rate(model, data, actuator), want, rtol=1e-12)


def test_hysteretic_state_converges_and_callbacks_are_restored():
    def top_floor(substeps):
        scenario = mi.load_scenario(load("hidden/boucwen_storey1").source, overrides={
            "sensors": {}, "scenario": {"duration": 6.0}, "simulation": {"substeps": substeps}})
        run = sim.simulate_run(scenario, scenario.runs[0])
        return run.group("q", 3)

    coarse, fine = top_floor(1), top_floor(2)
    # RK4 on the state and the motion: halving the 1 ms step moves the response by 5.0e-6 of its
    # peak (observed; the yield's |z|^n and sign(v z) are smooth enough for RK4): 2e-5 bounds it,
    # far below the 1 % sensor noise.
    assert np.max(np.abs(coarse - fine)) < 2e-5 * np.max(np.abs(fine))
    assert mujoco.get_mjcb_act_dyn() is None and mujoco.get_mjcb_control() is None


def _rows(force_at, law, d=3, fs=200.0, seconds=30.0, noise=0.05, seed=4):
    """Training rows of a synthetic rig: random floor motions, and the equation residual of a known
    force at one place plus white noise (``noise``: its RMS over the force's)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(fs * seconds)) / fs
    freqs = rng.uniform(0.5, 4.0, (d, 6))
    phases = rng.uniform(0, 2 * np.pi, (d, 6))
    amps = rng.uniform(0.5e-3, 1.5e-3, (d, 6))
    q = np.column_stack([np.sum(amps[j] * np.sin(2 * np.pi * freqs[j] * t[:, None] + phases[j]), axis=1)
                         for j in range(d)])
    v = np.column_stack([np.sum(amps[j] * 2 * np.pi * freqs[j] * np.cos(2 * np.pi * freqs[j] * t[:, None] + phases[j]),
                                axis=1) for j in range(d)])
    lower, upper = force_at.nodes
    x = q[:, upper - 1] - (q[:, lower - 1] if lower > 0 else 0.0)
    f = law(x)
    sigma = noise * float(np.sqrt(np.mean(f ** 2)))
    residual = np.outer(f, force_at.direction(d)) + rng.normal(0, sigma, (len(t), d))
    runs = []
    for k in range(2):   # two runs of half the record each
        part = slice(k * len(t) // 2, (k + 1) * len(t) // 2)
        run = SimpleNamespace(n_samples=len(t[part]), sample_rate=fs, time=t[part] - t[part][0])
        runs.append(SimpleNamespace(run=run, signals={"q": q[part], "v": v[part]}, residual=residual[part]))
    return tuple(runs), np.full(d, sigma)


@pytest.mark.parametrize("place", [Place(Target.FLOOR_TABLE, 3), Place(Target.STOREY, 3), Place(Target.STOREY, 1)],
                         ids=["floor3_table", "storey3", "storey1"])
def test_a_stop_is_found_where_it_acts(place):
    gap, k = 1.5e-3, 2e4
    rows, noise = _rows(place, lambda x: k * np.maximum(x - gap, 0.0))
    found = discovery.search(rows, noise, 3)
    # The top floor against the table, the top storey's drift and the first storey (the same as floor
    # 1 against the table) put the force on different floors: each place is told from the others.
    assert found.place == place
    terms = {c.term: (c, coef) for c, coef in zip(found.selected.columns, found.selected.coefficients)}
    assert set(terms) == {"x", "v", "gap_pos"}
    col, coef = terms["gap_pos"]
    # 5 % noise on the force; the gap is refined between grid points by least squares: 3 % on the
    # gap and the contact stiffness (observed within 1 %).
    assert abs(col.shape["gap_pos_delta"] - gap) < 0.03 * gap and abs(coef - k) < 0.03 * k
    words = describe(place, discovery.found_terms(found, 1.0), load("hidden/clean").structure,
                     float(np.max(np.abs(found.x))))
    assert "meets a stop on the + side: gap +1.5 mm" in words and "cubic" not in words


def test_a_linear_force_adds_no_nonlinear_term():
    rows, noise = _rows(Place(Target.STOREY, 2), lambda x: 300.0 * x)
    found = discovery.search(rows, noise, 3)
    # A storey spring missing from the model is linear: the library's nonlinear terms must not be
    # picked to fit its noise.
    assert [c.term for c in found.selected.columns] == ["x", "v"] and found.place == Place(Target.STOREY, 2)


def test_the_band_ignores_a_top_mode_the_data_do_not_hold():
    """A linear fit of a rig meeting a stop made two storeys all but rigid (randomised ``stop 8``: a 62.6 Hz
    mode beside a nominal 4.8 Hz, the data's power within 10.7 Hz); the band it opened lost the stop in
    noise.  Such a mode is cut to the data's band; a nominal mode stays the floor; a fit within the
    data's band is kept as it is."""
    from momentid.diagnosis.added_mass.residuals import top_mode

    assert top_mode(62.6, 4.8, 10.7) == 10.7
    assert top_mode(5.2, 4.8, 10.7) == 5.2
    assert top_mode(3.1, 4.8, 10.7) == 4.8           # a disturbed fit does not shrink the band
    assert top_mode(float("nan"), 4.8, 10.7) == 4.8
    assert top_mode(30.0, None, 10.7) == 10.7
    assert top_mode(12.0, 20.0, 10.7) == 20.0          # the lab's model stands above the data's band
