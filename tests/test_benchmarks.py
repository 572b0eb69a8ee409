"""The benchmark runner works on a tiny case and writes valid JSON (no timing assertion)."""

from __future__ import annotations

import importlib
import json
import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks.bench import main as bench_main
from benchmarks.bench import bench_scenario, run_benchmarks, stacked_regressor
from momentid.lab.scenario import default_scenario_path
from momentid.lab.simulation import simulate

ROOT = Path(__file__).resolve().parents[1]


def _check_rows(rows):
    for row in rows:
        for key in ("momentid_s", "baseline_s", "ratio"):
            assert row[key] is None or (math.isfinite(row[key]) and row[key] > 0), row


def test_every_data_stage_runs_on_a_tiny_case(tmp_path):
    report = run_benchmarks(stages=("simulate", "record", "identify", "view"),
                            scenario=default_scenario_path(), duration=0.05, repeat=1, workers=2,
                            workdir=tmp_path)
    json.dumps(report, allow_nan=False)   # JSON-safe as it stands
    stages = [r["stage"] for r in report["rows"]]
    assert stages[:2] == ["simulate", "simulate:1core"] and {"record", "identify", "view"} <= set(stages)
    _check_rows(report["rows"])
    simulate_row = report["rows"][0]
    # The raw rollout recomputes momentid's runs bit for bit; 1e-12 of each channel's peak
    # leaves room only for round-off, should MuJoCo ever sum in another order.
    assert simulate_row["extra"]["max_rel_diff_vs_rollout"] < 1e-12
    identify_row = next(r for r in report["rows"] if r["stage"] == "identify")
    # Streamed QR and one dense lstsq solve the same well-conditioned problem (condition ~1e3):
    # they agree to round-off, observed ~1e-12; 1e-8 leaves margin for other BLAS builds.
    assert identify_row["extra"]["max_rel_diff_vs_lstsq"] < 1e-8


def test_stacked_regressor_is_satisfied_by_the_analytic_model():
    sc = bench_scenario(default_scenario_path(), duration=0.2)
    experiment = simulate(sc)
    A, b, unpack = stacked_regressor(experiment)
    d = sc.structure.storeys
    assert A.shape == (3 * sc.n_samples * d, (d + 1) ** 2) and b.shape == (A.shape[0],)
    theta = np.linalg.lstsq(A, b, rcond=None)[0]
    M, C, K, mu = unpack(theta)
    s = sc.structure
    # Noise-free data satisfy eq. (3) up to integration round-off (~1e-12 in the README's run);
    # 1e-6 is the project's noise-free identification bound.
    for got, want in ((M, s.mass_matrix()), (C, s.damping_matrix()), (K, s.stiffness_matrix())):
        assert np.max(np.abs(got - want)) / np.max(np.abs(want)) < 1e-6
    assert abs(mu - s.rayleigh_mu) / s.rayleigh_mu < 1e-6


def test_cli_bench_quick_writes_json(tmp_path, capsys):
    out = tmp_path / "bench.json"
    assert bench_main(["--quick", "--stages", "identify,replay,run", "--json-out", str(out)]) == 0
    report = json.loads(out.read_text())
    assert [r["stage"] for r in report["rows"]] == ["identify", "replay", "run"]
    _check_rows(report["rows"])
    assert report["settings"]["quick"] and "ratio" in capsys.readouterr().out
    assert bench_main(["--stages", "nope"]) == 2


def test_the_diagnosis_matrix_covers_the_library():
    """``benchmarks/diagnosis.py``'s matrix names every kind the diagnosis can name (two cases each) and
    nothing else."""
    from benchmarks.diagnosis import MATRIX
    from momentid import mechanisms
    named = [m for m, _, _ in MATRIX if m not in ("none", "unexplained")]
    assert sorted(set(named)) == sorted(k.name for k in mechanisms.library())
    assert all(named.count(m) == 2 for m in set(named))


@pytest.mark.parametrize("name", sorted(p.stem for p in (ROOT / "benchmarks").glob("*.py") if p.stem != "__main__"))
def test_every_benchmark_module_imports(name):
    """A benchmark is run rarely (an hour and more): a module moved under it would otherwise go unseen."""
    importlib.import_module(f"benchmarks.{name}")


def test_predictable_share_finds_a_driven_misfit_and_not_an_unrelated_one():
    """The cross-axis benchmark's statistic: a misfit that is a filtered copy of one of five channels plus
    as much unrelated power in the band is half predictable; five unrelated channels predict about their
    number over the Welch segments (its known upward bias, which the time-reversed reference measures)."""
    import scipy.signal

    from benchmarks.real_cross_axis import SEGMENT, predictable_share

    rng = np.random.default_rng(0)
    fs, n = 120.0, 2400
    channels = [rng.standard_normal(n) for _ in range(5)]
    b, a = scipy.signal.butter(2, [20 / 60, 24 / 60], "band")
    driven = scipy.signal.lfilter(b, a, channels[3])
    misfit = driven + scipy.signal.lfilter(b, a, rng.standard_normal(n))     # as much again, unrelated
    band = (19.0, 25.0)
    # half the misfit's power is the driven part; the estimate adds its bias (5 channels / 17 segments, 0.29)
    # of the other half: about 0.65; measured 0.56-0.69 over four seeds
    assert 0.45 < predictable_share(misfit, channels, fs, band) < 0.8
    unrelated = predictable_share(rng.standard_normal(n), channels, fs, band)
    assert unrelated < 1.5 * 5 / (n // (SEGMENT // 2) - 1)         # measured 0.29-0.32, the bias 0.29


def test_pole_families_find_the_column_found_at_most_orders():
    """The SRIM stability diagram's columns: a pole found at every order wins over a wandering one found at a
    few, a pole beyond the band is left out, and a README figure is counted only where a pole lies within 1 %."""
    from benchmarks.srim_comparison import orders_near, pole_families

    rng = np.random.default_rng(3)
    poles = []
    for k in range(14):
        rows = [(22.0 * (1 + 0.002 * rng.standard_normal()), 0.004), (30.0, 0.01)]   # 30 Hz: beyond 10 %
        if k % 4 == 0:                                       # a weaker pole at 4 of the 14 orders
            rows.append((21.6 * (1 + 0.001 * rng.standard_normal()), 0.001))
        poles.append(np.array(rows))
    families = pole_families(poles, 22.03)
    assert [n for _, _, n in families] == [14, 4]
    assert abs(families[0][0] / 22.0 - 1) < 0.002           # the median of 14 draws with 0.2 % scatter
    assert abs(families[1][0] / 21.6 - 1) < 0.002
    assert orders_near(poles, 21.61) == 4 and orders_near(poles, 22.0) == 14 and orders_near(poles, 25.0) == 0


def test_twin_replays_take_the_compiled_paths_and_read_as_the_rollout():
    """``benchmarks.twin_replays`` on the stiff rig: every real-rig physics' twin replays in compiled code, and
    every replay reads what ``mujoco.rollout`` reads (1e-9 of the RMS: round-off, measured 1e-13)."""
    from benchmarks.twin_replays import measure

    rows = {r["physics"]: r for r in measure("stiff_1storey", repeat=1, batch=2)}
    assert rows["linear"]["path"].startswith("step map") and rows["bouc_wen"]["path"].startswith("compiled RK4")
    assert all(rows[p]["path"].startswith("step map and nonlinear inputs")
               for p in ("joint_friction", "cubic_spring", "quadratic_damping"))
    assert all(r["max_rel_diff"] < 1e-9 for r in rows.values())
    _check_rows([{"momentid_s": r["momentid_s"], "baseline_s": r["rollout_s"], "ratio": r["ratio"]}
                 for r in rows.values()])
