"""The callback kinds' compiled force laws (issue 31) against their Python laws: the same to round-off,
law by law and in whole replays, so that replays and every diagnosis stay the same."""

from __future__ import annotations

import numpy as np
import pytest

from momentid import mechanisms
from momentid.core.structure import Mechanism
from momentid.lab import native_forces, rig
from momentid.lab import simulation as sim
from momentid.mechanisms.native import call_force, call_rate
from momentid.mechanisms.place import Target

from test_mechanisms import _record, _structure, _table_run

CALLBACK_KINDS = [k.name for k in mechanisms.rig_kinds() if k.callback]


def _records(kind) -> list[dict]:
    records = [{p.name: p.example for p in kind.params}]
    if kind.open_search:   # every term of a discovered force at once, and with gaps of 0
        every = {p.name: (p.example or 1e3) if p.name.startswith("c_") else p.example for p in kind.params}
        records += [every, {k: 0.0 if k.endswith("_delta") else value for k, value in every.items()}]
    return records


def test_the_native_callbacks_are_available_here():
    assert native_forces.available()


def test_the_dispatching_callbacks_load_from_numbas_cache():
    """numba keys a cached closure on its cells' pickled values: the callbacks close over integers only (the
    struct offsets), so a second process loads them from disk, and a MuJoCo laid out differently compiles
    its own (a function or an object among the cells would miss the cache in every process)."""
    control, act_dyn = native_forces._callbacks()
    for callback in (control, act_dyn):
        cells = [c.cell_contents for c in callback._pyfunc.__closure__]
        assert cells and all(type(c) is int for c in cells)
        assert callback._cache is not None and type(callback._cache).__name__ != "NullCache"


@pytest.mark.parametrize("name", CALLBACK_KINDS)
def test_a_kinds_compiled_law_is_its_force_law_to_round_off(name):
    kind = mechanisms.get(name)
    assert kind.native_law() is not None, "every callback kind has a compiled law"
    place, stiffness = kind.place(2), 2500.0
    force = kind.storey_force if place.target is Target.STOREY else kind.floor_force
    rng = np.random.default_rng(5)
    x, v = rng.normal(0, 3e-3, 300), rng.normal(0, 3e-2, 300)
    x[:3], v[:3] = 0.0, [0.0, -0.0, 1e-9]   # the rest state and signed zeros
    x[3:5] = [1e-3, -1e-3]                  # at the examples' gaps
    for params in _records(kind):
        p = kind.native_parameters(params, stiffness)
        stateful = kind.has_state(params)
        for xi, vi, t in zip(x, v, np.linspace(0.0, 10.0, len(x))):
            s = float(1e-3 * np.tanh(xi / 1e-3)) if stateful else 0.0
            want = float(force(params, float(xi), float(vi), float(t), stiffness, **({"state": s} if stateful else {})))
            got = call_force(kind.native_law(), p, float(xi), float(vi), float(t), s)
            assert got == pytest.approx(want, rel=1e-14, abs=1e-300), (params, xi, vi, t)
            if stateful:
                want = float(kind.state_rate(params, s, float(xi), float(vi)))
                assert call_rate(kind.native_law(), p, s, float(xi), float(vi)) == pytest.approx(want, rel=1e-14,
                                                                                                  abs=1e-300)


def _replays(structure, mechs, run, monkeypatch) -> tuple[dict, dict]:
    native = sim.replay(structure, mechs, run)
    monkeypatch.setattr(native_forces, "ENABLED", False)
    python = sim.replay(structure, mechs, run)
    monkeypatch.setattr(native_forces, "ENABLED", True)
    return native, python


@pytest.mark.parametrize("name", CALLBACK_KINDS)
def test_a_replay_with_the_compiled_law_is_the_python_callbacks(name, monkeypatch):
    kind, structure, run = mechanisms.get(name), _structure(), _table_run()
    mech = _record(kind, 2)
    model = rig.compile_model(rig.build_spec(structure, run.added_mass, mechanisms=[mech]))
    assert native_forces.load_program(model, [mech], structure.storey_stiffness), "the replay runs the native callback"
    native, python = _replays(structure, [mech], run, monkeypatch)
    nominal = sim.replay(structure, [], run)
    for g in ("a", "q", "v"):
        scale = np.max(np.abs(python[g]))
        assert np.max(np.abs(python[g] - nominal[g])) > 1e-3 * scale   # the force acts
        assert np.max(np.abs(native[g] - python[g])) <= 1e-12 * scale


def test_several_forces_with_memory_and_stiffness_at_once(monkeypatch):
    """Two forces with states on two storeys, a time-dependent one and a link force on one model: each
    reads its own state, dofs and parameters from the program."""
    structure, run = _structure(), _table_run()
    mechs = [Mechanism("bouc_wen", 1, (("alpha", 0.3), ("yield_drift", 0.001), ("exponent", 2.0), ("beta", 0.5))),
             Mechanism("stiffness_loss", 2, (("fraction", 0.3), ("time", 1.0))),
             _record(mechanisms.get("data_driven_storey"), 3),
             Mechanism("data_driven_storey", 2, tuple((p.name, {"c_hysteretic": 300.0, "hysteretic_yield": 2e-3}
                                                       .get(p.name, p.example if not p.name.startswith("c_") else 0.0))
                                                      for p in mechanisms.get("data_driven_storey").params)),
             Mechanism("coulomb_friction", 3, (("force", 0.2),))]
    native, python = _replays(structure, mechs, run, monkeypatch)
    for g in ("a", "q", "v"):
        assert np.max(np.abs(native[g] - python[g])) <= 1e-12 * np.max(np.abs(python[g]))
