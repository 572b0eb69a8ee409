"""Shared fixtures: paths, the shared reference folder, cached simulations."""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import pytest

import momentid as mi
from momentid.scenario import Sensors
from momentid.simulate import simulate

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"
#: The workplace's read-only reference folder, beside the checkout.
SHARED = ROOT.parent / "shared"


def shared_file(*parts: str) -> Path:
    """A file under ../shared, or skip the test when it is absent."""
    path = SHARED.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"{path} is not available (../shared is absent)")
    return path


def scenario_files(recursive: bool = False) -> list[Path]:
    """Shipped scenarios; ``recursive`` adds the hidden-physics rigs in ``scenarios/hidden/``."""
    return sorted(SCENARIOS.rglob("*.toml") if recursive else SCENARIOS.glob("*.toml"))


def load(name: str) -> mi.Scenario:
    """Load scenarios/<name>.toml; skip when it needs ../shared and that is absent."""
    path = SCENARIOS / f"{name}.toml"
    text = path.read_text()
    if "shared/" in text and not SHARED.exists():
        pytest.skip(f"{path.name} reads a record from ../shared, which is absent")
    return mi.load_scenario(path)


@functools.lru_cache(maxsize=None)
def _simulated(name: str, ideal: bool):
    scenario = mi.load_scenario(SCENARIOS / f"{name}.toml")
    if ideal:
        scenario = dataclasses.replace(scenario, sensors=Sensors())
    return simulate(scenario)


@pytest.fixture(scope="session")
def simulated():
    """``simulated(name, ideal=False)``: the (cached) simulation of a shipped scenario;
    ``ideal=True`` records every channel exactly (noise-free virtual data)."""
    def get(name: str, ideal: bool = False):
        load(name)  # skips cleanly when the scenario needs ../shared
        return _simulated(name, ideal)
    return get
