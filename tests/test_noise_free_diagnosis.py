"""Noise-free recordings are not a mismatch (issue 22 point 1).

A simulated record without sensor noise satisfies every relation between its channels only to what
its samples leave open between them (``momentid.diagnosis.added_mass.kinematic_check.inter_sample``) and to
round-off; measured against a noise level near zero, that used to read as an inconsistency of 7e9x
and the verdict ``unexplained``.  Every shipped noise-free scenario must diagnose as ``none`` with
consistent sensors.
"""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

import momentid as mi
from momentid.cli import main
from momentid.diagnosis.added_mass.kinematic_check import kinematic_check
from momentid.diagnosis.added_mass.residuals import fit_linear_model
from momentid.diagnosis.added_mass.screening import screen_replay
from momentid.diagnosis.thresholds import EXCESS

from conftest import scenario_files

#: Shipped scenarios whose sensors are ideal (noise-free virtual data).
NOISE_FREE = [p for p in scenario_files() if mi.load_scenario(p).sensors.ideal]


def test_the_shipped_scenarios_include_noise_free_ones():
    assert {p.stem for p in NOISE_FREE} >= {"default", "paper_harmonic", "tall_noise"}


@pytest.mark.parametrize("path", NOISE_FREE, ids=lambda p: p.stem)
def test_noise_free_channels_are_consistent_and_replays_match(path):
    """The two checks that judged round-off a mismatch, on each noise-free scenario (a few s each)."""
    experiment = mi.simulate(mi.load_scenario(path))
    model = fit_linear_model(experiment)
    check = kinematic_check(model.train.runs, model.storeys, model.f_top)
    # EXCESS: the diagnosis's own threshold (noise alone gives about 1); the floor keeps these near 0.2-0.6
    assert check.consistent, check.excess
    replay = screen_replay(model.result, model.train.runs, model.storeys, model.band)
    assert max(replay.excess.values()) <= EXCESS, replay.excess


def test_a_real_fault_on_noise_free_data_still_shows(simulated):
    """The floor is a resolution, not a blindfold: a 1 % gain on the table channel of noise-free data
    (far above the (omega h)^2 / 12 ~ 1e-5 it leaves open) is still inconsistent, named on zdd."""
    experiment = mi.simulate(mi.load_scenario(NOISE_FREE[0]))
    runs = tuple(replace(r, values=r.values * [1.01 if c == "zdd" else 1.0 for c in r.channels])
                 for r in experiment.runs)
    check = kinematic_check(runs, experiment.storeys, 10.0)
    assert not check.consistent and check.fits[0].channel == "zdd"   # fits: best explained first


def _diagnose_cli(path, tmp_path, capsys) -> dict:
    rec = tmp_path / "rec.mcap"
    assert main(["run", str(path), "-q", "-o", str(rec)]) == 0
    capsys.readouterr()
    assert main(["diagnose", str(rec), "-o", str(tmp_path / "report"), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def _slow_but_default(paths):
    return [pytest.param(p, id=p.stem, marks=[] if p.stem == "default" else [pytest.mark.slow]) for p in paths]


@pytest.mark.parametrize("path", _slow_but_default(NOISE_FREE))
def test_diagnose_on_noise_free_data_says_none(path, tmp_path, capsys):
    """The whole command (10-30 s per scenario: the default scenario in the default run, the others slow)."""
    report = _diagnose_cli(path, tmp_path, capsys)
    assert report["mechanism"] == "none", report["summary"]
    assert report["sensor_check"]["consistent"], report["sensor_check"]["excess"]
