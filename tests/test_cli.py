"""The command line: the two README commands, JSON output, one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from momentid.cli import main
from momentid.estimation.comparison import analytic_parameters
from momentid.lab.scenario import default_scenario_path, load_scenario

from conftest import SCENARIOS


def test_run_default_then_identify_json(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["run", "-q"]) == 0
    out = capsys.readouterr().out
    assert "out/default.mcap" in out and "largest relative error" in out
    assert main(["identify", "out/default.mcap", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    structure = load_scenario(default_scenario_path()).structure
    an = analytic_parameters(structure)
    for key in ("M", "C", "K"):
        assert np.array(result[key]).shape == (3, 3)
        # Noise-free: identified within the 1e-6 of the largest entry.
        assert np.allclose(result[key], an[key], rtol=0, atol=1e-6 * np.abs(an[key]).max())
    for key in ("mu", "kappa"):
        assert abs(result[key] - an[key]) <= 1e-6 * an[key]
    # The streamed path reads the file once and reports against the same nominal model.
    assert main(["identify", "out/default.mcap", "--stream", "--json"]) == 0
    streamed = json.loads(capsys.readouterr().out)
    assert streamed["analytic"] == result["analytic"]
    for key in ("M", "C", "K"):   # the same equations by another summation order: round-off apart
        assert np.allclose(streamed[key], result[key], rtol=0, atol=1e-9 * np.abs(an[key]).max())


def test_run_paper_harmonic_to_folder(tmp_path, capsys):
    assert main(["run", str(SCENARIOS / "paper_harmonic.toml"), "-o", str(tmp_path), "-q",
                 "--estimator", "difference", "--time", "5"]) == 0
    assert (tmp_path / "paper_harmonic.mcap").is_file()
    assert "18 equations, 16 unknowns" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["run", "nowhere.toml"], "nowhere.toml: file not found"),
        (["identify", "missing.mcap"], "missing.mcap"),
        (["identify", "{rec}", "--runs", "reference"], "expected at least two"),
        (["identify", "{rec}", "--runs", "nope,reference"], "no run named 'nope'"),
    ],
)
def test_user_mistakes_are_one_line_errors(tmp_path, capsys, argv, fragment, simulated):
    from momentid.io.recording import write_experiment
    rec = tmp_path / "rec.mcap"
    write_experiment(rec, simulated("default"))
    argv = [a.replace("{rec}", str(rec)) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and fragment in err and err.count("\n") == 1
    assert "Traceback" not in err


def test_bad_scenario_value_from_the_shell(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text((SCENARIOS / "paper_harmonic.toml").read_text().replace(
        "masses = [10.724, 10.134, 20.32]", "masses = [10.724, -10.134, 20.32]"))
    proc = subprocess.run([sys.executable, "-m", "momentid", "run", str(bad)], capture_output=True,
                          text=True, cwd=tmp_path)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.strip() == (f"error: {bad}: key 'structure.masses[1]' = -10.134 (float): "
                                   f"expected a positive number")


def test_help_explains_itself(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    text = capsys.readouterr().out
    assert "run" in text and "identify" in text and "examples:" in text
    assert main([]) == 2


def test_plan_refuses_a_non_positive_target(capsys):
    with pytest.raises(SystemExit) as info:
        main(["plan", str(SCENARIOS / "lab_noisy.toml"), "--target", "-1"])
    assert info.value.code == 2
    assert "--target: '-1': expected a positive number" in capsys.readouterr().err
