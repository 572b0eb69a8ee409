"""Blind-diagnosis validation matrix and diagnosis time.

    python -m benchmarks.diagnosis [--quick] [--workers N] [--alone-only]

Every mechanism of the library at two locations and two magnitudes, under 1 % and 2 % sensor noise,
plus clean rigs (no hidden physics) and rigs with physics outside the library (answer:
``unexplained``), on the laboratory rig of ``scenarios/hidden/`` (paper structure, El Centro,
4 runs x 20 s at 1 kHz, accelerometers + displacement transducers).  For each case: the verdict,
whether mechanism and location are right, the held-out NRMSE before/after, and the diagnosis time
with ``--workers`` cases at once.  Then the issue's timing benchmark: one experiment of 4 runs x 20 s
at 1 kHz diagnosed alone on the machine (target < 60 s), for a clean rig and for the slowest kinds of
case (callback physics, re-simulated).  Writes ``benchmarks/results/diagnosis.json`` and ``diagnosis.md``.
"""

from __future__ import annotations

import json

from benchmarks.common import cost_cells, cost_summary, hidden_rig, matrix_parser, run_cases, save, timed_diagnosis

MATRIX = [  # (mechanism, truth table or channel fault, expected location), two locations x two magnitudes
    ("coulomb_friction", {"storey": 1, "force": 0.2}, {"storey": 1}),
    ("coulomb_friction", {"storey": 3, "force": 0.5}, {"storey": 3}),
    ("cubic_stiffness", {"storey": 1, "k3": 1.5e7}, {"storey": 1}),
    ("cubic_stiffness", {"storey": 2, "k3": 4e7}, {"storey": 2}),
    ("extra_damper", {"storey": 1, "c": 1.5}, {"storey": 1}),
    ("extra_damper", {"storey": 3, "c": 4.0}, {"storey": 3}),
    ("p_delta", {"storey": 1, "factor": 0.6}, {"storey": 1}),
    ("p_delta", {"storey": 2, "factor": 1.5}, {"storey": 2}),
    ("flexible_added_mass", {"floor": 3, "frequency": 6.0, "damping_ratio": 0.05}, {"floor": 3}),
    ("flexible_added_mass", {"floor": 1, "frequency": 10.0, "damping_ratio": 0.05}, {"floor": 1}),
    ("tuned_mass_damper", {"floor": 3, "mass": 1.0, "frequency": 0.78, "damping_ratio": 0.1}, {"floor": 3}),
    ("tuned_mass_damper", {"floor": 2, "mass": 0.6, "frequency": 2.4, "damping_ratio": 0.05}, {"floor": 2}),
    ("sensor_delay", {"a3": {"clock_offset": 0.005}}, {"channel": "a3"}),
    ("sensor_delay", {"zdd": {"clock_offset": 0.015}}, {"channel": "zdd"}),
    ("sensor_gain", {"a1": {"gain": 1.05}}, {"channel": "a1"}),
    ("sensor_gain", {"zdd": {"gain": 0.9}}, {"channel": "zdd"}),
    ("sensor_bias", {"a1": {"bias": 0.01}}, {"channel": "a1"}),
    ("sensor_bias", {"q2": {"bias": 0.001}}, {"channel": "q2"}),
    ("sensor_saturation", {"a2": {"saturation": 0.2}}, {"channel": "a2"}),
    ("sensor_saturation", {"q3": {"saturation": 0.005}}, {"channel": "q3"}),
    ("none", {}, {}),
    ("none", {"seed": 5}, {}),
    # physics outside the library (a storey losing stiffness mid-run): the answer must be "unexplained"
    ("unexplained", {"storey": 1, "fraction": 0.3, "time": 5.0}, {"storey": 1}),
    ("unexplained", {"storey": 3, "fraction": 0.5, "time": 8.0}, {"storey": 3}),
]


TIMED = (16, 1, 2)   # clean, strong top-storey friction, cubic stiffness: timed alone


def scenario(mechanism: str, spec: dict, noise: float, excitation: dict | None = None):
    """The matrix's rig with one case's hidden physics: ``spec`` is the ``[truth]`` table of ``mechanism``
    (a stiffness loss for ``unexplained``), its per-channel faults for a sensor kind, or for ``none`` an
    optional scenario ``seed``."""
    if mechanism.startswith("sensor_"):
        return hidden_rig(faults=spec, noise=noise, excitation=excitation)
    if mechanism == "unexplained":
        return hidden_rig([{"type": "stiffness_loss", **spec}], noise=noise, excitation=excitation)
    if mechanism != "none":
        return hidden_rig([{"type": mechanism, **spec}], noise=noise, excitation=excitation)
    return hidden_rig(noise=noise, excitation=excitation, seed=spec.get("seed"))


def case(job) -> dict:
    """One case of the matrix: (mechanism, spec, expected location, noise[, excitation]) -> its row."""
    mechanism, spec, location, noise, *excitation = job
    d, costs = timed_diagnosis(scenario(mechanism, spec, noise, *excitation))
    right = d.mechanism == mechanism and d.location == location
    return {"truth": mechanism, "spec": spec, "noise": noise, "verdict": d.mechanism, "location": d.location,
            "expected_location": location, "correct": right, "parameters": d.parameters,
            "nrmse_before": d.nrmse_before, "nrmse_after": d.nrmse_after, **costs,
            "excitation": (excitation[0] or {}).get("type", "record") if excitation else "record"}


def table(rows, *, spec=False) -> list[str]:
    """Markdown table of the cases (``spec``: with the hidden parameters and the excitation)."""
    lines = ["| truth | where | excitation | noise | verdict | right | held-out NRMSE before -> after | time "
             "| x raw rollout | replays |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        where = json.dumps(r["expected_location"]) if r["expected_location"] else "-"
        truth = f"{r['truth']} {json.dumps(r['spec'])}" if spec else r["truth"]
        lines.append(f"| {truth} | {where} | {r['excitation']} | {100 * r['noise']:g} % | {r['verdict']} "
                     f"{json.dumps(r['location']) if r['location'] else ''} | {'yes' if r['correct'] else 'no'} | "
                     f"{100 * r['nrmse_before']:.2f} % -> {100 * r['nrmse_after']:.2f} % | {cost_cells(r)} |")
    return lines


def main(argv=None) -> int:
    p = matrix_parser("benchmarks.diagnosis", __doc__)
    p.add_argument("--quick", action="store_true", help="1 %% noise only")
    p.add_argument("--alone-only", action="store_true",
                   help="re-time only the cases timed alone (on a quiet machine), keeping the matrix of "
                        "OUT/diagnosis.json")
    args = p.parse_args(argv)
    noises = [0.01] if args.quick else [0.01, 0.02]
    jobs = [(m, s, loc, n) for n in noises for m, s, loc in MATRIX]
    if args.alone_only:
        rows = json.loads((args.out / "diagnosis.json").read_text())["matrix"]
    else:
        rows = run_cases(jobs, args.workers, case)
    found = [r for r in rows if r["truth"] not in ("none", "unexplained")]
    clean = [r for r in rows if r["truth"] == "none"]
    outside = [r for r in rows if r["truth"] == "unexplained"]
    lines = table(rows)
    ratio_ok = [r for r in found if r["correct"] and r["nrmse_after"] * 3 <= r["nrmse_before"]]
    lines += ["", f"Right mechanism and location: {sum(r['correct'] for r in found)} of {len(found)}; "
                  f"of those, held-out NRMSE at least 3x lower: {len(ratio_ok)}; false alarms on clean rigs: "
                  f"{sum(not r['correct'] for r in clean)} of {len(clean)}; physics outside the library called "
                  f"unexplained at the right place: {sum(r['correct'] for r in outside)} of {len(outside)}; "
                  f"{cost_summary(rows)}."]
    alone = []
    for i in TIMED:
        mechanism, spec, location = MATRIX[i]
        row = case((mechanism, spec, location, 0.01))
        alone.append({"truth": mechanism, "spec": spec, "correct": row["correct"],
                      **{k: row[k] for k in ("seconds", "replays", "rollout_seconds", "ratio")}})
        print(json.dumps(alone[-1]), flush=True)
    lines += ["", "Diagnosis time alone (one experiment, 4 runs x 20 s at 1 kHz, 1 % noise, nothing else running): "
              + ", ".join(f"{r['truth']} {json.dumps(r['spec'])} {r['seconds']:.0f} s ({r['ratio']:.0f}x raw rollout, "
                         f"{r['replays']} replays)" for r in alone) + "."]
    save(args.out, "diagnosis", {"matrix": rows, "alone": alone}, lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
