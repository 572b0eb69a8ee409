"""Shared fixtures: paths, the shipped data folder, cached simulations."""

from __future__ import annotations

import functools
from pathlib import Path

import pytest

import momentid as mi
from momentid.lab.simulation import simulate

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"
#: Records and reference tables shipped with the project (see data/README.md).
DATA = ROOT / "data"


def data_file(*parts: str) -> Path:
    """A file under the project's ``data/`` folder (it must exist: the project ships it)."""
    path = DATA.joinpath(*parts)
    assert path.exists(), f"{path} is missing from the repository"
    return path


def scenario_files(recursive: bool = False) -> list[Path]:
    """Shipped scenarios; ``recursive`` adds the hidden-physics rigs in ``scenarios/hidden/``."""
    return sorted(SCENARIOS.rglob("*.toml") if recursive else SCENARIOS.glob("*.toml"))


def load(name: str) -> mi.Scenario:
    """Load scenarios/<name>.toml."""
    return mi.load_scenario(SCENARIOS / f"{name}.toml")


@functools.cache
def _simulated(name: str, ideal: bool):
    overrides = {"sensors": {}} if ideal else {}   # an empty [sensors]: every channel, exact
    return simulate(mi.load_scenario(SCENARIOS / f"{name}.toml", overrides=overrides))


@pytest.fixture(scope="session")
def simulated():
    """``simulated(name, ideal=False)``: the (cached) simulation of a shipped scenario;
    ``ideal=True`` records every channel exactly (noise-free virtual data)."""
    def get(name: str, ideal: bool = False):
        return _simulated(name, ideal)
    return get


# Hypothesis profiles of tests/test_fuzz_readers.py: a bounded, derandomized run by default (the same
# examples on every machine, a few seconds per reader) and a long random one selected by -m slow.
from hypothesis import HealthCheck, settings  # noqa: E402

settings.register_profile("fuzz-fast", max_examples=150, deadline=None, derandomize=True, database=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("fuzz-slow", max_examples=5000, deadline=None, derandomize=False, database=None,
                          suppress_health_check=[HealthCheck.too_slow])


def rollout_and_replay(path, models, zdd, dt: float, substeps: int, monkeypatch) -> tuple:
    """``(mujoco.rollout's, the compiled replay's)`` readings of ``models`` under ``zdd``: ``path`` (a replay
    module with an ``ENABLED`` switch, e.g. :mod:`momentid.lab.native_replay`) off, then on."""
    from momentid.lab import resim

    with monkeypatch.context() as m:
        m.setattr(path, "ENABLED", False)
        rolled = resim.simulate(models, zdd, dt, substeps)
    return rolled, resim.simulate(models, zdd, dt, substeps)
