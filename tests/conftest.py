"""Shared fixtures: paths, the shared reference folder, cached simulations."""

from __future__ import annotations

import functools
from pathlib import Path

import pytest

import momentid as mi
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


def scenario_files() -> list[Path]:
    return sorted(SCENARIOS.glob("*.toml"))


def load(name: str) -> mi.Scenario:
    """Load scenarios/<name>.toml; skip when it needs ../shared and that is absent."""
    path = SCENARIOS / f"{name}.toml"
    text = path.read_text()
    if "shared/" in text and not SHARED.exists():
        pytest.skip(f"{path.name} reads a record from ../shared, which is absent")
    return mi.load_scenario(path)


@functools.lru_cache(maxsize=None)
def _simulated(name: str):
    return simulate(mi.load_scenario(SCENARIOS / f"{name}.toml"))


@pytest.fixture(scope="session")
def simulated():
    """``simulated(name)``: the (cached) noise-free simulation of a shipped scenario."""
    def get(name: str):
        load(name)  # skips cleanly when the scenario needs ../shared
        return _simulated(name)
    return get
