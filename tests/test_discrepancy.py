"""Blind diagnosis of hidden physics (issue 5): one rig per mechanism, plus a clean rig.

Each rig in ``scenarios/hidden/`` carries physics the linear model leaves out; the
recording carries no trace of it, and ``diagnose`` sees only the recording.
"""

from __future__ import annotations

import json
import math
import pytest

import momentid as mi
from momentid import mechanisms
from momentid.cli import main
from momentid.diagnosis.data_check import DataEvidence
from momentid.diagnosis.dispatch import diagnose, write_report

from conftest import SCENARIOS, load

def expected(name: str) -> tuple[str, dict]:
    """The answer for a hidden rig, from its own ``[truth]`` (or per-channel sensor fault): the
    mechanism and where; ``unexplained`` at its place for physics outside the library
    (truth-only kinds); ``none`` for a rig with neither."""
    scenario = load(f"hidden/{name}")
    for mech in scenario.truth:
        kind = mechanisms.get(mech.type)
        return ("unexplained" if kind.truth_only else mech.type), kind.place(mech.location).location
    for channel, fault in scenario.sensors.faults:
        return fault.records[0].type, {"channel": channel}
    return "none", {}


def truth(name: str) -> dict:
    """Parameters of a hidden rig's one mechanism (or channel fault), from its scenario."""
    scenario = load(f"hidden/{name}")
    if scenario.truth:
        return dict(scenario.truth[0].parameters)
    return {mechanisms.get(r.type).setting.name: value for _, fault in scenario.sensors.faults for r in fault.records
            for _, value in r.parameters}


CASES = sorted(path.stem for path in (SCENARIOS / "hidden").glob("*.toml"))
#: Hidden rigs whose blind diagnoses run under ``-m slow`` (half a minute to a minute and a half each on 2
#: cores; the default suite must stay under 10 minutes): the open search's three, the tuned-mass damper
#: (tests/test_mechanisms.py diagnoses it in the default run, in a copy of the package), the damper
#: (test_diagnose_cli_writes_the_report diagnoses the same rig in the default run), and cubic stiffness,
#: P-Delta and the flexible added mass (each in the diagnosis matrix, ``python -m benchmarks.diagnosis``), and
#: the sensor bias (about 20 s; a bias at two channels in the diagnosis matrix).  The default run keeps a clean
#: rig, joint-free friction, and the clock offset, gain and saturation.
SLOW_CASES = {"pounding_floor3", "boucwen_storey1", "tmd_floor3", "slip_storey2", "damper_storey3",
              "cubic_storey1", "pdelta_storey1", "flexible_floor3", "bias_a2"}
#: Physics outside the library, and words the open search's description must use for it.
OPEN_CASES = {"slip_storey2": ("loses", "of its stiffness from t = 5.0 s"),
              "pounding_floor3": ("floor 3 meets a stop on the + side: gap +4.0 mm", "contact stiffness"),
              "boucwen_storey1": ("hysteretic", "softening with amplitude")}


def _marked(names) -> list:
    return [pytest.param(n, marks=pytest.mark.slow) if n in SLOW_CASES else n for n in names]


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    out = tmp_path_factory.mktemp("hidden")
    cache = {}

    def get(name):
        if name not in cache:
            sc = load(f"hidden/{name}")
            path = out / f"{name}.mcap"
            mi.run_experiment(sc, path)
            cache[name] = path
        return cache[name]
    return get


@pytest.fixture(scope="module")
def diagnoses(recordings):
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = diagnose(mi.read_recording(recordings(name)))
        return cache[name]
    return get


def test_every_kind_of_the_library_has_a_blind_case():
    answers = {expected(name)[0] for name in CASES}
    assert {kind.name for kind in mechanisms.library()} | {"none", "unexplained"} <= answers


@pytest.mark.parametrize("name", _marked(CASES))
def test_blind_diagnosis(recordings, diagnoses, name):
    experiment = mi.read_recording(recordings(name))
    # Nothing in the recording gives the answer away.
    assert "truth" not in experiment.scenario_text and "sensors.channel" not in experiment.scenario_text
    assert "faults" not in str(experiment.scenario.get("sensors", {}))
    diag = diagnoses(name)
    mechanism, location = expected(name)
    assert (diag.mechanism, diag.location) == (mechanism, location), diag.summary
    if mechanism in ("none", "unexplained"):   # the model is left linear
        assert diag.nrmse_after == diag.nrmse_before
        assert diag.mechanisms == () and diag.to_dict()["mechanisms"] == []
    else:
        # One hidden mechanism: exactly one entry, the verdict itself (no spurious second one).
        assert [(m.mechanism, m.location) for m in diag.mechanisms] == [(mechanism, location)], diag.summary
        assert diag.to_dict()["mechanisms"][0]["parameters"] == diag.parameters
        if isinstance(diag.evidence, DataEvidence):
            # Named from the channel alone (nothing fitted): the nominal model's replay with the fault on its
            # reading comes down to what the 1 % sensor noise leaves.
            assert diag.nrmse_after < diag.nrmse_before < 2 * 0.01, diag.summary
        else:
            # The target: held-out NRMSE at least 3x lower after augmentation.
            assert diag.nrmse_after * 3 <= diag.nrmse_before, diag.summary


@pytest.mark.parametrize("name", _marked(sorted(OPEN_CASES)))
def test_open_search_models_physics_outside_the_library(diagnoses, name, tmp_path):
    diag = diagnoses(name)
    mechanism, location = expected(name)
    assert (diag.mechanism, diag.location) == (mechanism, location) == ("unexplained", location), diag.summary
    found = diag.discovered
    assert found is not None and found.location == location, diag.summary
    # The target: the held-out run's NRMSE at least 2x lower with the discovered force.
    assert found.nrmse_after * 2 <= found.nrmse_before, diag.summary
    assert all(words in found.description for words in OPEN_CASES[name]), found.description
    assert found.description in diag.summary
    report = diag.to_dict()["discovered"]
    assert set(report) == {"location", "description", "terms", "physics", "nrmse_before", "nrmse_after",
                           "replaces"}
    assert report["physics"]["class"] == found.physics["class"]
    assert [t["term"] for t in report["terms"]][:2] == ["x", "v"]
    write_report(diag, tmp_path)
    assert (tmp_path / "discovered.png").stat().st_size > 10_000


def test_a_clean_rig_has_nothing_to_discover(diagnoses):
    # The open search runs on "unexplained" only: a clean rig has nothing to discover.
    assert diagnoses("clean").discovered is None and diagnoses("clean").to_dict()["discovered"] is None


def test_fitted_parameters_and_uncertainty(diagnoses):
    diag = diagnoses("friction_storey2")
    force, err, true_force = diag.parameters["force"], diag.std["force"], truth("friction_storey2")["force"]
    # Truth 0.3 N; the regression alone gave 0.25 N (noisy drift velocities), re-simulation
    # observed 0.29995 +/- 0.002: within 2 % and within 3 std.
    assert abs(force - true_force) < 0.02 * true_force and abs(force - true_force) < 3 * err
    diag = diagnoses("delay_a2")
    delay = truth("delay_a2")["clock_offset"]
    # 10 ms hidden clock offset, read from a2 against zdd + q2'' (observed within 0.2 %): 2 %.
    assert abs(diag.parameters["delay"] - delay) < 0.02 * delay and 0 < diag.std["delay"] < 1e-3


@pytest.mark.slow
def test_fitted_parameters_of_the_slow_cases(diagnoses):
    diag = diagnoses("cubic_storey1")
    k3, err, true_k3 = diag.parameters["k3"], diag.std["k3"], truth("cubic_storey1")["k3"]
    # Truth 3.5e7 N/m^3, refined by re-simulation (observed within 0.2 %); its std (~1e4) covers
    # noise, not the small bias of replaying from a noisy table channel: accept 2 %.
    assert abs(k3 - true_k3) < 0.02 * true_k3 and 0 < err < 0.02 * true_k3
    diag = diagnoses("flexible_floor3")
    attachment = truth("flexible_floor3")
    # Truth 6 Hz, damping ratio 0.05; replays from a noisy table channel bias the damping ratio up by
    # a few percent: 1 % on the frequency, 15 % on the damping ratio.
    assert abs(diag.parameters["frequency"] - attachment["frequency"]) < 0.01 * attachment["frequency"]
    assert abs(diag.parameters["damping_ratio"] - attachment["damping_ratio"]) < 0.15 * attachment["damping_ratio"]
    assert set(diag.std) == {"frequency", "damping_ratio"}


def test_a_sensor_saturation_is_named_at_its_channel_with_its_level(diagnoses):
    """Issue 30's proof of one sensor-fault model: the kind is one file (mechanisms/sensor_saturation.py),
    the lab clips the channel from ``[sensors.channel.a2] saturation``, and the diagnosis names it from the
    recorded channel itself (the data check, not a refusal), at its channel, the level within the issue's 5 %
    (observed exact: the reading is held at the level itself)."""
    diag = diagnoses("saturation_a2")
    assert (diag.mechanism, diag.location) == ("sensor_saturation", {"channel": "a2"}), diag.summary
    level = truth("saturation_a2")["saturation"]
    assert abs(diag.parameters["level"] - level) < 0.05 * level
    assert "sensor saturation at channel a2" in diag.summary and diag.to_dict()["path"] == "data check"
    # the report page's answer (main's report.html) on the data check, which estimates no noise: no "nan %"
    assert "sensor saturation" in diag._repr_html_() and "nan" not in diag._repr_html_()


@pytest.mark.slow    # a whole diagnosis through the CLI, 40-75 s on 2 cores; the default run keeps the CLI's
# report folder (tests/test_noise_free_diagnosis.py) and the damper's diagnosis (benchmarks.diagnosis)
def test_diagnose_cli_writes_the_report(recordings, tmp_path, capsys):
    rec = recordings("damper_storey3")
    assert main(["diagnose", str(rec), "-o", str(tmp_path / "report"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["mechanism"] == "extra_damper" and report["location"] == {"storey": 3}
    assert set(report) >= {"mechanism", "location", "parameters", "nrmse_before", "nrmse_after"}
    # 3 N*s/m hidden; 5 % for noise
    assert math.isclose(report["parameters"]["c"], truth("damper_storey3")["c"], rel_tol=0.05)
    assert {"localisation", "sensor_check", "selection"} <= set(report)
    saved = json.loads((tmp_path / "report" / "report.json").read_text())
    assert saved["mechanism"] == "extra_damper"
    xml = (tmp_path / "report" / "model_augmented.xml").read_text()
    assert "<mujoco" in xml
    assert (tmp_path / "report" / "replay.png").stat().st_size > 10_000
    assert (tmp_path / "report" / "locate.png").stat().st_size > 10_000
    import rerun as rr
    store = rr.chunk.RrdReader(str(tmp_path / "report" / "diagnosis.rrd")).store()
    paths = {str(c.entity_path) for c in store.stream().to_chunks()}
    assert {"/a1/recorded", "/a1/linear", "/a1/augmented", "/q3/augmented", "/report"} <= paths
    assert main(["diagnose", str(tmp_path / "missing.mcap")]) == 2


def test_mismatch_is_located_and_described(diagnoses):
    where = diagnoses("friction_storey2").evidence.localisation
    assert where.storey == 2 and where.storeys["storey2"] > 10 * max(where.storeys["storey1"], where.storeys["storey3"])
    assert "sign of the drift velocity" in where.words and "present in all runs" in where.words
    # Sensors agree with each other on a structural mechanism.
    assert diagnoses("friction_storey2").evidence.sensor_check["consistent"]
    check = diagnoses("delay_a2").evidence.sensor_check
    assert not check["consistent"] and check["fits"][0]["channel"] == "a2"


@pytest.mark.slow
def test_growing_and_late_mismatches_are_described(diagnoses):
    assert "grows with the drift cubed" in diagnoses("cubic_storey1").evidence.localisation.words
    slip = diagnoses("slip_storey2").evidence.localisation
    # The slip starts 5 s into every run; windows are 2 s long, so the first mismatched one starts at 4 s.
    assert slip.storey == 2 and "from t = 4 s on" in slip.words
    assert all(w["excess"] < 1.5 for w in slip.windows[:2])   # noise level before the slip
