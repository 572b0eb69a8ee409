"""Randomised blind diagnosis: rigs, excitations, noise and hidden physics drawn by seed.

    nice -n 10 python -m benchmarks.diagnosis_random [--workers N] [--category NAME,...] [--cases 0,3,5]

Each case is drawn from its own seed (``SEED``, its category, its index), so a case is the same
whatever else is run: a shear frame of 3-5 storeys (floor masses, storey stiffnesses, two modal
damping ratios), an excitation (band-limited noise, a chirp or the El Centro record, each at a
random level and band), 0.5-2 % sensor noise, 4 runs x 20 s at 1 kHz with random added-mass
patterns (the last held out), and one category of hidden physics:

==================  =========================================================================
``stop``            a floor against stops fixed to the table: + side, - side or both
``gap_brace``       a storey brace engaging beyond a gap (a dead-zone spring)
``bouc_wen``        Bouc-Wen hysteresis in a storey
``stiffness_change`` a storey losing part of its stiffness at an unknown time
``loose_mass``      an added mass attached flexibly (``flexible_added_mass``)
``library_fault``   a library mechanism and a sensor fault at once
``two_storey``      two storey mechanisms of the library
``clean``           nothing
==================  =========================================================================

The physics' size is drawn relative to the rig's own response, then the rig is simulated with
and without it (noise-free sensors): a draw is kept when it changes the response (the worst run's
mean NRMSE over the floor channels) by ``CHANGE`` (5-100 %), else redrawn.

A case is **right**:

* a library mechanism (``loose_mass``, ``library_fault``, ``two_storey``): every hidden mechanism
  and fault named at its place;
* physics outside the library: the verdict ``unexplained``, the open search's force located at its
  place, the held-out NRMSE at least halved, and described as its class (a stop with its side and
  gaps within ``GAP_TOLERANCE``; a gap within it; hysteresis; a stiffness change within
  ``TIME_TOLERANCE`` of its time) with no other nonlinear term;
* a clean rig: ``none``.

A **false alarm** is a clean rig called anything but ``none``, or a sensor fault named where no
channel is faulty.  Each diagnosis's wall and CPU time are recorded (CPU time includes its forked
trials: on a shared machine it is the fair measure).  Rows are merged into
``benchmarks/results/diagnosis_random.json`` by (category, index), so partial runs add up; the
Markdown table is rebuilt from every row.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
from pathlib import Path

import numpy as np

import momentid as mi
from benchmarks.common import HIDDEN_RIG, ROOT, measured_diagnosis, run_cases, save
from benchmarks.diagnosis_compound import FAULT_KINDS
from momentid.core.analytic import modal_properties
from momentid.errors import SimulationError
from momentid.lab.scenario import parse_scenario

#: The benchmark's seed (the issue's number); a case's own seed is (SEED, category, index).
SEED = 21
#: Cases per category by default.
CASES = 10
DURATION, SAMPLE_RATE = 20.0, 1000.0
RECORD = ROOT / "data" / "records" / "elcentro_1940_ns.at2"
#: A hidden effect is kept when it changes the response by this share (worst run, mean NRMSE over
#: the floor channels, noise-free sensors): 5 % is about the noise of one channel at 2 %, x 2.5;
#: beyond 100 % the rig is another structure.
CHANGE = (0.05, 1.0)
#: Effect draws per rig before a new rig is drawn.
DRAWS = 12
#: A discovered gap is right within this share of the true one (an engineer locating the stop on a
#: drawing needs its distance to a quarter), ...
GAP_TOLERANCE = 0.25
#: ... a stiffness change within this many seconds of its time (the open search's switch grid is 0.5 s
#: before refinement).
TIME_TOLERANCE = 0.5
#: Library mechanisms paired with a fault (``library_fault``, in turn) and the storey mechanisms paired
#: with each other (``two_storey``, in turn).
LIBRARY = ("coulomb_friction", "cubic_stiffness", "extra_damper", "p_delta", "flexible_added_mass")
FAULTS = ("clock_offset", "gain", "bias")
STOREY_PAIRS = (("coulomb_friction", "cubic_stiffness"), ("extra_damper", "p_delta"),
                ("coulomb_friction", "p_delta"), ("cubic_stiffness", "extra_damper"),
                ("coulomb_friction", "extra_damper"), ("cubic_stiffness", "p_delta"))
CATEGORIES = ("stop", "gap_brace", "bouc_wen", "stiffness_change", "loose_mass", "library_fault", "two_storey",
              "clean")


# ----------------------------------------------------------------------------- rigs

def _modes(masses, stiffness) -> np.ndarray:
    from momentid.core.analytic import shear_stiffness
    M, K = np.diag(masses), shear_stiffness(stiffness)
    return modal_properties(M, np.zeros_like(M), K).frequency


def _damping_ratios(rng, f) -> list[float]:
    """Damping ratios of modes 1 and 2: 0.5-2 % for mode 1, mode 2's within a factor 1.5 of it and
    within what non-negative Rayleigh coefficients allow (``zeta_1 f_1 / f_2 <= zeta_2 <= zeta_1 f_2 / f_1``)."""
    z1 = float(rng.uniform(0.005, 0.02))
    z2 = float(np.clip(z1 * rng.uniform(1 / 1.5, 1.5), 1.001 * z1 * f[0] / f[1], 0.999 * z1 * f[1] / f[0]))
    return [round(z1, 5), round(z2, 5)]


def draw_rig(rng) -> dict:
    """A scenario table (dict, as TOML would give) of a random rig with ideal sensors."""
    n = int(rng.integers(3, 6))
    masses = np.round(rng.uniform(8.0, 14.0, n), 2)
    masses[-1] = round(float(rng.uniform(10.0, 22.0)), 2)
    stiffness = np.round(rng.uniform(1600.0, 3200.0, n), 0)
    f = _modes(masses, stiffness)
    kind = ("noise", "chirp", "record")[int(rng.integers(3))]
    if kind == "noise":
        excitation = {"type": "noise", "rms": round(float(rng.uniform(0.1, 0.4)), 3),
                      "band": [round(float(rng.uniform(0.2, 0.5)), 2),
                               round(float(min(rng.uniform(1.5, 3.0) * f[-1], 40.0)), 1)],
                      "seed": int(rng.integers(1000))}
    elif kind == "chirp":
        excitation = {"type": "chirp", "amplitude": round(float(rng.uniform(0.1, 0.3)), 3),
                      "f_start": round(float(rng.uniform(0.3, 0.7) * f[0]), 2),
                      "f_end": round(float(rng.uniform(1.3, 2.5) * f[-1]), 1),
                      "sweep": ("linear", "log")[int(rng.integers(2))]}
    else:
        excitation = {"type": "record", "file": str(RECORD), "scale": round(float(rng.uniform(0.03, 0.08)), 3)}
    every = np.round(rng.uniform(0.06, 0.15, n) * masses, 1)
    runs = [{"name": "reference", "added_mass": [0.0] * n}, {"name": "loaded", "added_mass": every.tolist()}]
    for name in ("pattern", "held_out"):
        on = rng.random(n) < 0.5
        on[int(rng.integers(n))] = True
        runs.append({"name": name, "added_mass": np.where(on, np.round(rng.uniform(0.1, 0.25, n) * masses, 1),
                                                          0.0).tolist()})
    noise = round(float(rng.uniform(0.005, 0.02)), 4)
    return {"scenario": {"name": "random", "duration": DURATION, "sample_rate": SAMPLE_RATE,
                         "seed": int(rng.integers(10000))},
            "structure": {"masses": masses.tolist(), "storey_stiffness": stiffness.tolist(), "storey_height": 0.3,
                          "damping": {"damping_ratios": _damping_ratios(rng, f), "modes": [1, 2]}},
            "excitation": excitation, "runs": runs,
            "sensors": {"set": "accel+disp", "accelerometer": {"relative_noise": 0.0},
                        "displacement": {"relative_noise": 0.0}},
            "_noise": noise}


def _scenario(rig: dict, truth=(), faults=None, noisy=False):
    data = {k: v for k, v in json.loads(json.dumps(rig)).items() if not k.startswith("_")}
    if noisy:
        for instrument in ("accelerometer", "displacement"):
            data["sensors"][instrument]["relative_noise"] = rig["_noise"]
    if truth:
        data["truth"] = {"mechanisms": [dict(m) for m in truth]}
    if faults:
        data["sensors"]["channel"] = json.loads(json.dumps(faults))
    return parse_scenario(data, source=HIDDEN_RIG)


def _simulate(rig, truth=(), faults=None, noisy=False):
    return mi.simulate(_scenario(rig, truth, faults, noisy), workers=1)


def response_change(without, with_it, d: int) -> float:
    """The worst run's mean NRMSE of the floor channels (a, q) with the effect against without."""
    worst = 0.0
    for r0, r1 in zip(without.runs, with_it.runs):
        errs = []
        for g in ("a", "q"):
            x0, x1 = r0.group(g, d), r1.group(g, d)
            if not np.all(np.isfinite(x1)):
                return math.inf
            errs += list(np.sqrt(np.mean((x1 - x0) ** 2, axis=0)) / np.sqrt(np.mean(x0 ** 2, axis=0)))
        worst = max(worst, float(np.mean(errs)))
    return worst


class Response:
    """What the clean rig does (noise-free): peaks and RMS per floor and storey, median over runs."""

    def __init__(self, experiment, d: int):
        q = [r.group("q", d) for r in experiment.runs]
        drift = [np.diff(np.column_stack([np.zeros(len(x)), x]), axis=1) for x in q]
        self.experiment, self.d = experiment, d
        self.peak_q = np.median([np.max(np.abs(x), axis=0) for x in q], axis=0)
        self.peak_drift = np.median([np.max(np.abs(x), axis=0) for x in drift], axis=0)
        self.rms_drift = np.median([np.sqrt(np.mean(x ** 2, axis=0)) for x in drift], axis=0)
        self.rms = {c: float(np.median([np.sqrt(np.mean(r[c] ** 2)) for r in experiment.runs]))
                    for c in experiment.runs[0].channels}


# ----------------------------------------------------------------------------- hidden physics

def _loguniform(rng, low, high) -> float:
    return float(math.exp(rng.uniform(math.log(low), math.log(high))))


def _storey_mechanism(kind: str, rng, rig, resp: Response, s: int) -> dict:
    k = rig["structure"]["storey_stiffness"][s]
    m = rig["structure"]["masses"][s]
    out = {"type": kind, "storey": s + 1}
    if kind == "coulomb_friction":
        out["force"] = round(float(rng.uniform(0.03, 0.3)) * k * float(resp.rms_drift[s]), 4)
    elif kind == "cubic_stiffness":
        out["k3"] = float(f"{float(rng.uniform(0.1, 1.0)) * k / float(resp.peak_drift[s]) ** 2:.3g}")
    elif kind == "extra_damper":
        out["c"] = round(_loguniform(rng, 0.005, 0.03) * 2 * math.sqrt(k * m), 3)
    elif kind == "p_delta":
        out["factor"] = round(float(rng.uniform(0.5, 2.0)), 3)
    return out


def _loose_mass(rng, rig, floor: int) -> dict:
    f = _modes(rig["structure"]["masses"], rig["structure"]["storey_stiffness"])
    return {"type": "flexible_added_mass", "floor": floor + 1,
            "frequency": round(_loguniform(rng, 1.2, 5.0) * float(f[-1]), 2),
            "damping_ratio": round(float(rng.uniform(0.02, 0.1)), 3)}


def _with_mass_on(rig, floor: int) -> None:
    """Make the held-out and pattern runs carry added mass on ``floor`` (0-based), as a loose mass needs."""
    m = rig["structure"]["masses"][floor]
    for run in rig["runs"][2:]:
        if run["added_mass"][floor] == 0.0:
            run["added_mass"][floor] = round(0.15 * m, 1)


def _effect(category: str, index: int, rng, rig, resp: Response) -> tuple[list, dict, dict]:
    """One draw of the category's hidden physics: (truth records, channel faults, expected answer)."""
    n = resp.d
    if category == "stop":
        j = int(rng.integers(n))
        side = ("+", "-", "both")[int(rng.integers(3))]
        gaps = {g: (round(float(rng.uniform(0.3, 0.85)) * float(resp.peak_q[j]), 5) if side in (s, "both") else 0.0)
                for g, s in (("gap_pos", "+"), ("gap_neg", "-"))}
        stiffness = round(_loguniform(rng, 3.0, 30.0) * rig["structure"]["storey_stiffness"][j], -1)
        truth = [{"type": "contact_stop", "floor": j + 1, **gaps, "stiffness": stiffness,
                  "damping": round(float(rng.uniform(0.0, 8.0)), 2)}]
        return truth, {}, {"outside": {"class": "stop", "side": side, **gaps}, "location": {"floor": j + 1}}
    if category == "gap_brace":
        s = int(rng.integers(n))
        gap = round(float(rng.uniform(0.2, 0.7)) * float(resp.peak_drift[s]), 5)
        stiffness = round(_loguniform(rng, 0.3, 3.0) * rig["structure"]["storey_stiffness"][s], 0)
        truth = [{"type": "gap_brace", "storey": s + 1, "gap": gap, "stiffness": stiffness}]
        return truth, {}, {"outside": {"class": "gap", "gap": gap}, "location": {"storey": s + 1}}
    if category == "bouc_wen":
        s = int(rng.integers(n))
        truth = [{"type": "bouc_wen", "storey": s + 1, "alpha": round(float(rng.uniform(0.1, 0.6)), 3),
                  "yield_drift": round(float(rng.uniform(0.15, 0.6)) * float(resp.peak_drift[s]), 6),
                  "exponent": float(rng.choice([1.0, 2.0, 3.0])), "beta": round(float(rng.uniform(0.3, 0.7)), 3)}]
        return truth, {}, {"outside": {"class": "hysteresis"}, "location": {"storey": s + 1}}
    if category == "stiffness_change":
        s = int(rng.integers(n))
        t0 = round(float(rng.uniform(3.0, 14.0)), 2)
        truth = [{"type": "stiffness_loss", "storey": s + 1, "fraction": round(float(rng.uniform(0.15, 0.6)), 3),
                  "time": t0}]
        return truth, {}, {"outside": {"class": "stiffness change", "time": t0}, "location": {"storey": s + 1}}
    if category == "loose_mass":
        j = int(rng.integers(n))
        _with_mass_on(rig, j)
        truth = [_loose_mass(rng, rig, j)]
        return truth, {}, {"named": [("flexible_added_mass", {"floor": j + 1})]}
    if category == "library_fault":
        kind = LIBRARY[index % len(LIBRARY)]
        if kind == "flexible_added_mass":
            j = int(rng.integers(n))
            _with_mass_on(rig, j)
            truth = [_loose_mass(rng, rig, j)]
        else:
            truth = [_storey_mechanism(kind, rng, rig, resp, int(rng.integers(n)))]
        field = FAULTS[index % len(FAULTS)]
        channel = ("zdd", f"a{int(rng.integers(n)) + 1}", f"q{int(rng.integers(n)) + 1}")[int(rng.integers(3))]
        if field == "clock_offset":
            value = round(_loguniform(rng, 0.002, 0.015), 4)
        elif field == "gain":
            value = round(1.0 + float(rng.choice([-1.0, 1.0])) * float(rng.uniform(0.03, 0.1)), 4)
        else:
            value = float(f"{float(rng.uniform(0.05, 0.4)) * resp.rms[channel]:.3g}")
        faults = {channel: {field: value}}
        return truth, faults, {"named": _expected(truth, faults)}
    if category == "two_storey":
        pair = STOREY_PAIRS[index % len(STOREY_PAIRS)]
        truth = [_storey_mechanism(kind, rng, rig, resp, int(rng.integers(n))) for kind in pair]
        return truth, {}, {"named": _expected(truth, {})}
    return [], {}, {"named": []}


def _expected(truth, faults) -> list:
    out = [(m["type"], {k: m[k] for k in ("storey", "floor") if k in m}) for m in truth]
    return out + [(FAULT_KINDS[f], {"channel": c}) for c, fault in faults.items() for f in fault]


def _change(base, rig, truth, d: int) -> float:
    """:func:`response_change` of the rig with ``truth``; infinite when MuJoCo cannot step it (a pair
    of drawn mechanisms that makes the rig unstable is redrawn, like one that changes it too much)."""
    try:
        return response_change(base, _simulate(rig, truth), d)
    except SimulationError:
        return math.inf


def draw_case(category: str, index: int) -> dict:
    """The case's rig and hidden physics, redrawn until the physics changes the response by ``CHANGE``
    (each mechanism of a pair on its own, the pair together)."""
    rng = np.random.default_rng([SEED, CATEGORIES.index(category), index])
    while True:
        rig = draw_rig(rng)
        d = len(rig["structure"]["masses"])
        if category == "clean":
            return {"rig": rig, "truth": [], "faults": {}, "expected": {"named": []}, "change": 0.0}
        clean = _simulate(rig)
        resp = Response(clean, d)
        for _ in range(DRAWS):
            draft = json.loads(json.dumps(rig))
            truth, faults, expected = _effect(category, index, rng, draft, resp)
            base = clean if draft["runs"] == rig["runs"] else _simulate(draft)
            changes = [_change(base, draft, truth, d)]
            if len(truth) > 1:
                changes += [_change(base, draft, [m], d) for m in truth]
            if all(CHANGE[0] <= c <= CHANGE[1] for c in changes):
                return {"rig": draft, "truth": truth, "faults": faults, "expected": expected, "change": changes[0]}


# ----------------------------------------------------------------------------- judging

def _place_ok(found: dict, want: dict) -> bool:
    """The discovered place is the truth's (a floor-1 force against the table *is* storey 1)."""
    same = {json.dumps(want, sort_keys=True)}
    if want == {"floor": 1}:
        same.add(json.dumps({"storey": 1}))
    return json.dumps(found, sort_keys=True) in same


def _close(found, true, tolerance=GAP_TOLERANCE) -> bool:
    return found is not None and abs(found - true) <= tolerance * true


def described(physics: dict, want: dict) -> bool:
    """Whether the discovered physics is the truth's class, with its side, gaps or time."""
    cls = physics.get("class")
    if want["class"] == "stop":
        if cls == "gap" and want["side"] == "both":   # floor 1 against the table is storey 1: a dead zone
            return all(_close(physics["gap"], want[g]) for g in ("gap_pos", "gap_neg"))
        return (cls == "stop" and physics.get("side") == want["side"]
                and all(_close(physics.get(g), want[g]) for g in ("gap_pos", "gap_neg") if want[g] > 0))
    if want["class"] == "gap":
        return cls == "gap" and _close(physics["gap"], want["gap"])
    if want["class"] == "stiffness change":
        return cls == "stiffness change" and abs(physics["time"] - want["time"]) <= TIME_TOLERANCE
    return cls == want["class"]


def judge(case: dict, d) -> dict:
    """Right, false alarm, and why a case is wrong, from the diagnosis ``d``."""
    expected = case["expected"]
    named = [(m.mechanism, m.location) for m in d.mechanisms]
    hidden_faults = {json.dumps(loc, sort_keys=True) for kind, loc in expected.get("named", []) if "channel" in loc}
    wrong_faults = [n for n in named if "channel" in n[1] and json.dumps(n[1], sort_keys=True) not in hidden_faults]
    why = []
    if "outside" in expected:
        found = d.discovered
        if named:
            why.append("named " + ", ".join(f"{m} {json.dumps(loc)}" for m, loc in named))
        elif d.mechanism != "unexplained":
            why.append(f"verdict {d.mechanism}")
        if found is None:
            why.append("nothing discovered")
        else:
            if not _place_ok(found.location, expected["location"]):
                why.append(f"discovered at {json.dumps(found.location)}")
            if found.nrmse_after * 2 > found.nrmse_before:
                why.append(f"held-out NRMSE {100 * found.nrmse_before:.1f} -> {100 * found.nrmse_after:.1f} %")
            if not described(found.physics, expected["outside"]):
                why.append(f"described as {json.dumps(found.physics)}")
    else:
        want = expected["named"]
        missing = [w for w in want if w not in named]
        if missing:
            why.append("missed " + ", ".join(f"{m} {json.dumps(loc)}" for m, loc in missing))
        extra = [n for n in named if n not in want]
        if extra:
            why.append("also named " + ", ".join(f"{m} {json.dumps(loc)}" for m, loc in extra))
        if not want and d.mechanism != "none":
            why.append(f"verdict {d.mechanism} {json.dumps(d.location)}")
    false_alarm = bool(wrong_faults) or (not expected.get("named") and "outside" not in expected
                                         and d.mechanism != "none")
    return {"right": not why, "false_alarm": false_alarm, "why": "; ".join(why)}


def _case(job) -> dict:
    """One case's row; a case that raises is a row saying so (wrong), not the end of the benchmark."""
    try:
        return run_case(*job)
    except Exception as exc:   # noqa: BLE001  (the row names it; the other cases go on)
        return {"category": job[0], "index": job[1], "storeys": 0, "excitation": {"type": "-"}, "noise": 0.0,
                "truth": [], "faults": {}, "change": 0.0, "expected": {}, "verdict": "error", "location": {},
                "named": [], "discovered": None, "nrmse_before": math.nan, "nrmse_after": math.nan, "right": False,
                "false_alarm": False, "why": f"{type(exc).__name__}: {exc}", "seconds": 0.0, "cpu_seconds": 0.0,
                "code": _code()}


def run_case(category: str, index: int) -> dict:
    """Draw, simulate, diagnose and judge case ``index`` of ``category``: its row of the table."""
    case = draw_case(category, index)
    experiment = _simulate(case["rig"], case["truth"], case["faults"], noisy=True)
    d, costs = measured_diagnosis(experiment)
    rig = case["rig"]
    excitation = {k: v for k, v in rig["excitation"].items() if k != "file"}
    return {"category": category, "index": index, "storeys": len(rig["structure"]["masses"]),
            "excitation": excitation, "noise": rig["_noise"], "truth": case["truth"], "faults": case["faults"],
            "change": case["change"], "expected": case["expected"], "verdict": d.mechanism, "location": d.location,
            "named": [m.to_dict() for m in d.mechanisms],
            "discovered": d.discovered.to_dict() if d.discovered is not None else None,
            "nrmse_before": d.nrmse_before, "nrmse_after": d.nrmse_after, **judge(case, d),
            **costs, "code": _code()}


def _code() -> str:
    """The commit the case ran on (``+`` when the worktree had changes beyond the results' tables)."""
    try:
        head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--untracked-files=no", "--",
                                ".", ":!benchmarks/results"],
                               capture_output=True, text=True, check=True).stdout.strip()
        return head + ("+" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


# ----------------------------------------------------------------------------- the table

def _truth_words(r: dict) -> str:
    parts = [f"{m['type']} " + json.dumps({k: v for k, v in m.items() if k != "type"}) for m in r["truth"]]
    parts += [f"{c} {json.dumps(f)}" for c, f in r["faults"].items()]
    return "; ".join(parts) or "none"


def _answer(r: dict) -> str:
    if r["named"]:
        return "; ".join(f"{m['mechanism']} {json.dumps(m['location'])}" for m in r["named"])
    found = r["discovered"]
    if found:
        numbers = ", ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}"
                            for k, v in found["physics"].items())
        return (f"{r['verdict']}, discovered {json.dumps(found['location'])} {numbers}; "
                f"{100 * found['nrmse_before']:.1f} -> {100 * found['nrmse_after']:.1f} %")
    return f"{r['verdict']} {json.dumps(r['location']) if r['location'] else ''}".strip()


def _cell(r: dict, key: str, unit: str = "") -> str:
    return f"{r[key]:.0f}{unit}" if key in r else "-"


def _median(rows: list[dict], key: str, unit: str = "") -> str:
    values = sorted(r[key] for r in rows if key in r)
    return f"{values[len(values) // 2]:.0f}{unit}" if values else "-"


def table(rows: list[dict]) -> list[str]:
    """Summary per category, then one line per case."""
    lines = ["| category | cases | right | false alarms | median time (wall / CPU) | max time (wall / CPU) "
             "| median x raw rollout (wall / CPU) | median replays |", "|---|---|---|---|---|---|---|---|"]
    for cat in CATEGORIES:
        rs = [r for r in rows if r["category"] == cat]
        if not rs:
            continue
        wall, cpu = sorted(r["seconds"] for r in rs), sorted(r["cpu_seconds"] for r in rs)
        right = [r["right"] for r in rs]
        lines.append(f"| {cat} | {len(rs)} | {sum(right)} ({100 * np.mean(right):.0f} %)"
                     f" | {sum(r['false_alarm'] for r in rs)}"
                     f" | {wall[len(wall) // 2]:.0f} s / {cpu[len(cpu) // 2]:.0f} s"
                     f" | {wall[-1]:.0f} s / {cpu[-1]:.0f} s"
                     f" | {_median(rs, 'ratio', 'x')} / {_median(rs, 'cpu_ratio', 'x')} | {_median(rs, 'replays')} |")
    lines += ["", "| case | storeys | excitation | noise | hidden (change) | answer | right | why not | wall / CPU "
              "| x raw rollout (wall / CPU) | replays |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        exc = r["excitation"]["type"]
        lines.append(f"| {r['category']} {r['index']} | {r['storeys']} | {exc} | {100 * r['noise']:.2f} % | "
                     f"{_truth_words(r)} ({100 * r['change']:.0f} %) | {_answer(r)} | "
                     f"{'yes' if r['right'] else 'no'} | "
                     f"{r['why']} | {r['seconds']:.0f} / {r['cpu_seconds']:.0f} s | "
                     f"{_cell(r, 'ratio', 'x')} / {_cell(r, 'cpu_ratio', 'x')} | {_cell(r, 'replays')} |")
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.diagnosis_random", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--workers", type=int, default=1, help="cases diagnosed at once (default 1: times alone)")
    p.add_argument("--category", help="comma-separated categories (default: all): " + ", ".join(CATEGORIES))
    p.add_argument("--cases", help=f"comma-separated case indices (default: 0..{CASES - 1})")
    p.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    p.add_argument("--fresh", action="store_true", help="start a new table instead of merging into OUT's")
    args = p.parse_args(argv)
    cats = args.category.split(",") if args.category else list(CATEGORIES)
    unknown = sorted(set(cats) - set(CATEGORIES))
    if unknown:
        p.error(f"--category {','.join(unknown)}: expected some of {', '.join(CATEGORIES)}")
    indices = [int(i) for i in args.cases.split(",")] if args.cases else list(range(CASES))
    rows = run_cases([(c, i) for c in cats for i in indices], args.workers, _case)
    path = args.out / "diagnosis_random.json"
    if path.is_file() and not args.fresh:
        new = {(r["category"], r["index"]) for r in rows}
        rows = [r for r in json.loads(path.read_text()) if (r["category"], r["index"]) not in new] + rows
    rows.sort(key=lambda r: (CATEGORIES.index(r["category"]), r["index"]))
    save(args.out, "diagnosis_random", rows, table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
