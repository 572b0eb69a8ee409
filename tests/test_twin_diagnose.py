"""`momentid diagnose` of accelerometer-only recordings on the rig's MuJoCo twin
(momentid.diagnosis.twin.path, rig_state, twin_words)."""

from __future__ import annotations

import json
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest

from momentid.cli import main
from momentid.diagnosis.dispatch import diagnose
from momentid.estimation.rig_state import OFF_TREND_SIGMAS, check_state
from momentid.diagnosis.thresholds import EXCESS
from momentid.diagnosis.result import Diagnosis
from momentid.diagnosis.twin.words import TwinEvidence
from momentid.diagnosis.twin.path import default_hold_out
from momentid.diagnosis.verdict import Verdict
from momentid.io.recording import write_experiment

from conftest import DATA
from test_real_diagnose import lab, run

CONTRACT = ("held_out", "nrmse_before", "nrmse_after", "nrmse_linear_refit", "nrmse_linear_own", "noise_nrmse",
            "mechanisms")


def _result(name: str, f1: float, amplitude: float, shift: float = 0.0):
    """A per-run identification of a rig whose modes 2 and 3 follow mode 1 (softening joints): f2 = 3 f1,
    f3 = 4.4 f1, plus ``shift`` Hz on both (a rig re-mounted); standard errors of a real rig's fit."""
    f = np.array([f1, 3.0 * f1 + shift, 4.4 * f1 + shift])
    return SimpleNamespace(runs=(name,), frequency=f, frequency_std=np.array([0.001, 0.003, 0.003]),
                           amplitude=np.array([amplitude]))


def test_rig_state_finds_the_trial_off_the_trend():
    same = [_result("a", 3.79, 0.5), _result("b", 3.77, 1.2), _result("c", 3.75, 1.3), _result("d", 3.68, 4.6)]
    assert check_state(same).outliers == ()                     # on one line: one rig state
    odd = check_state(same + [_result("e", 3.70, 2.7, shift=0.1)])
    assert odd.outliers == ("e",)
    # 0.1 Hz off on modes 2 and 3 against errors of ~0.004 Hz (its own 0.003, the line's, mode 1's x 3)
    assert odd.sigmas["e"] > OFF_TREND_SIGMAS
    assert "run e does not belong with the others" in odd.sentence("e")
    # the default hold-out is a trial of the rig state, inside the others' amplitudes
    assert default_hold_out(same + [_result("e", 3.70, 2.7, shift=0.1)], odd) == "c"


def test_a_trial_that_shook_beyond_the_others_may_bend_their_trend():
    """The hardest trial of a rig whose joints reach macro-slip: every higher mode further along the trend
    than the others' line says, not against it (a simulated 5-storey rig's was called another rig state)."""
    same = [_result("a", 3.79, 0.5), _result("b", 3.77, 1.2), _result("c", 3.75, 1.3), _result("d", 3.73, 2.0)]
    bent = SimpleNamespace(runs=("e",), frequency=np.array([3.65, 3.0 * 3.65 + 0.05, 4.4 * 3.65 + 0.06]),
                           frequency_std=np.array([0.001, 0.003, 0.003]), amplitude=np.array([4.6]))
    state = check_state(same + [bent])
    assert state.outliers == () and state.sigmas["e"] == 0.0
    # the same trial with modes 2 and 3 moved against the trend (up while mode 1 went down): another state
    back = SimpleNamespace(runs=("e",), frequency=np.array([3.65, 3.0 * 3.73 + 0.1, 4.4 * 3.73 + 0.1]),
                           frequency_std=np.array([0.001, 0.003, 0.003]), amplitude=np.array([4.6]))
    assert check_state(same + [back]).outliers == ("e",)


def test_rig_state_needs_enough_trials():
    state = check_state([_result("a", 3.79, 0.5), _result("b", 3.77, 1.2), _result("c", 3.75, 1.3, shift=0.5)])
    assert not state.tested and state.outliers == ()          # three trials: a line through two has no scatter


def test_linear_rig_on_the_twin(tmp_path, capsys):
    experiment = lab(run("r1", 0.3, 1), run("r2", 0.6, 2), run("r3", 0.45, 3))
    path = tmp_path / "lab.mcap"
    write_experiment(path, experiment)
    out_dir = tmp_path / "rep"
    assert main(["diagnose", str(path), "-o", str(out_dir), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in CONTRACT:
        assert key in out, key
    assert out["held_out"] == "r3"          # r3's amplitude lies between r1's and r2's
    assert out["mechanism"] == "none", out["summary"]
    # A linear rig: the linear twin's held-out misfit is the noise's (the rule's EXCESS margin).
    assert out["nrmse_before"] <= EXCESS * out["noise_nrmse"]
    assert out["mechanisms"] == []
    for name in ("twin.xml", "model_augmented.xml"):
        model = mujoco.MjModel.from_xml_path(str(out_dir / name))      # stock MuJoCo loads them
        assert model.nv >= 4
    assert (out_dir / "replay.png").exists()
    assert "{" not in out["summary"]                                  # places in words, never JSON


@pytest.mark.slow    # half a minute on 2 cores: a third twin diagnosis beside the two of the default run
def test_hold_out_names_any_trial():
    experiment = lab(run("r1", 0.3, 1), run("r2", 0.6, 2), run("r3", 0.45, 3))
    diag = diagnose(experiment, hold_out="r2")
    assert isinstance(diag, Diagnosis) and isinstance(diag.evidence, TwinEvidence)
    assert diag.held_out == "r2" and diag.evidence.training == ("r1", "r3")
    assert np.isfinite(diag.nrmse_linear_own) and diag.noise_nrmse > 0


@pytest.mark.slow
def test_shipped_rig_default_hold_out(tmp_path, capsys):
    path = tmp_path / "flex3.mcap"
    assert main(["import", str(DATA / "mini_shake_table" / "flexible_3storey"), "-o", str(path)]) == 0
    capsys.readouterr()
    assert main(["diagnose", str(path), "-o", str(tmp_path / "rep"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["rig_state"]["outliers"] == ["bonus_event"]          # another day: said, not physics
    assert out["held_out"] != "bonus_event" and "bonus_event" not in out["training"]
    assert out["nrmse_after"] < out["nrmse_linear_refit"]
    # the physics chosen on the training trials alone: every candidate scored, a joint law won
    # (benchmarks/results/real_folds.md: joint friction on every fold of this rig)
    assert set(out["fits"]["selection"]) >= {"linear", "joint_friction", "quadratic_damping", "cubic_spring"}
    assert out["fits"]["chosen"].startswith("joint_friction")


@pytest.mark.slow
def test_trial_of_another_rig_state_is_said_not_physics(monkeypatch):
    import test_real_diagnose as sim

    runs = [run("r1", 0.3, 1), run("r2", 0.6, 2), run("r3", 0.45, 3)]
    monkeypatch.setattr(sim, "STIFFNESS", (450.0, 500.0, 470.0))     # storey 3 re-clamped 10 % softer
    runs.append(run("r4", 0.5, 4))
    diag = diagnose(lab(*runs), hold_out="r4")
    # modes 2 and 3 move off the line the others' modes follow against mode 1 (11.9 standard errors
    # when written); the three linear trials lie within 1
    assert diag.evidence.state.outliers == ("r4",) and diag.evidence.training == ("r1", "r2", "r3")
    assert diag.verdict is Verdict.ANOTHER_RIG_STATE and diag.mechanism == "another_rig_state"
    assert not diag.mechanisms
    assert "run r4 does not belong with the others" in diag.summary
