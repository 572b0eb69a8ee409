"""Compound diagnoses: two hidden mechanisms at once.

    python -m benchmarks.diagnosis_compound [--workers N] [--cases 0,3,5]

Pairs of the library's mechanisms on the laboratory rig of ``scenarios/hidden/`` (paper structure, El
Centro, 4 runs x 20 s at 1 kHz, accelerometers + displacement transducers, 1 % noise): a storey
friction with a late table accelerometer, a cubic stiffness with a floor accelerometer's gain, an extra
damper with P-Delta, and pairs of storey forces, each at two places and magnitudes, in the same storey
and apart; plus a clean rig.  A case is right when every hidden mechanism is named at its place
(``both``); ``exact`` says no third one was named.  Writes ``benchmarks/results/diagnosis_compound.json``
and ``diagnosis_compound.md``.
"""

from __future__ import annotations

import json

from momentid import mechanisms

from benchmarks.common import cost_cells, cost_summary, hidden_rig, matrix_parser, run_cases, save, timed_diagnosis

#: Fault field of ``[sensors.channel.*]`` -> the mechanism kind that names it (the registry's).
FAULT_KINDS = {key: kind.name for key, kind in mechanisms.sensor_settings().items()}

PAIRS = [  # (hidden [truth] mechanisms, per-channel faults)
    ([{"type": "coulomb_friction", "storey": 2, "force": 0.3}], {"zdd": {"clock_offset": 0.01}}),
    ([{"type": "coulomb_friction", "storey": 1, "force": 0.5}], {"zdd": {"clock_offset": 0.004}}),
    ([{"type": "cubic_stiffness", "storey": 1, "k3": 3.5e7}], {"a1": {"gain": 1.05}}),
    ([{"type": "cubic_stiffness", "storey": 2, "k3": 2e7}], {"a3": {"gain": 0.93}}),
    ([{"type": "extra_damper", "storey": 3, "c": 3.0}, {"type": "p_delta", "storey": 1, "factor": 1.0}], {}),
    ([{"type": "extra_damper", "storey": 1, "c": 2.0}, {"type": "p_delta", "storey": 2, "factor": 1.5}], {}),
    ([{"type": "extra_damper", "storey": 2, "c": 3.0}, {"type": "p_delta", "storey": 2, "factor": 1.0}], {}),
    ([{"type": "coulomb_friction", "storey": 1, "force": 0.3}, {"type": "cubic_stiffness", "storey": 3,
                                                                 "k3": 3e7}], {}),
    ([{"type": "coulomb_friction", "storey": 2, "force": 0.2}, {"type": "cubic_stiffness", "storey": 2,
                                                                 "k3": 4e7}], {}),
    ([{"type": "coulomb_friction", "storey": 3, "force": 0.4}, {"type": "p_delta", "storey": 1, "factor": 1.0}],
     {}),
    ([{"type": "cubic_stiffness", "storey": 2, "k3": 3e7}], {"a2": {"clock_offset": 0.008}}),
    ([{"type": "extra_damper", "storey": 2, "c": 3.0}], {"q3": {"bias": 0.001}}),
    ([], {}),   # clean: nothing to name
]


def expected(truth: list, faults: dict) -> list[tuple[str, dict]]:
    """(mechanism, location) of every hidden mechanism and channel fault."""
    out = [(m["type"], {k: m[k] for k in ("storey", "floor") if k in m}) for m in truth]
    out += [(FAULT_KINDS[field], {"channel": channel}) for channel, fault in faults.items() for field in fault]
    return out


def scenario(truth: list, faults: dict, noise: float = 0.01):
    """The clean rig of ``scenarios/hidden/`` with ``truth`` mechanisms and channel ``faults``."""
    return hidden_rig(truth, faults, noise)


def _case(job):
    truth, faults = job
    d, costs = timed_diagnosis(scenario(truth, faults))
    want = expected(truth, faults)
    named = [(m.mechanism, m.location) for m in d.mechanisms]
    both = all(w in named for w in want) and (bool(want) or (d.mechanism == "none" and not named))
    return {"truth": truth, "faults": faults, "expected": want, "verdict": d.mechanism, "location": d.location,
            "named": [m.to_dict() for m in d.mechanisms], "both": both, "exact": both and len(named) == len(want),
            "nrmse_before": d.nrmse_before, "nrmse_after": d.nrmse_after, **costs}


def table(rows) -> list[str]:
    """Markdown table: hidden and named mechanisms (with parameters), the scores, NRMSE and time."""
    def yes(flag):
        return "yes" if flag else "no"

    lines = ["| hidden | named | both | exact | held-out NRMSE before -> after | time | x raw rollout | replays |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        named = "; ".join(f"{m['mechanism']} {json.dumps(m['location'])} "
                          + ", ".join(f"{k}={v:.4g}" for k, v in m["parameters"].items()) for m in r["named"])
        cells = ["; ".join(f"{m} {json.dumps(loc)}" for m, loc in r["expected"]) or "none", named or r["verdict"],
                 yes(r["both"]), yes(r["exact"]),
                 f"{100 * r['nrmse_before']:.2f} % -> {100 * r['nrmse_after']:.2f} %", cost_cells(r)]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def main(argv=None) -> int:
    p = matrix_parser("benchmarks.diagnosis_compound", __doc__)
    p.add_argument("--cases", help="comma-separated indices into PAIRS (default: all)")
    args = p.parse_args(argv)
    chosen = [int(i) for i in args.cases.split(",")] if args.cases else range(len(PAIRS))
    rows = run_cases([PAIRS[i] for i in chosen], args.workers, _case)
    pairs = [r for r in rows if r["expected"]]
    lines = table(rows) + ["", f"Every hidden mechanism named at its place: {sum(r['both'] for r in pairs)} of "
                               f"{len(pairs)} compound cases ({sum(r['exact'] for r in pairs)} with nothing else "
                               f"named); clean rigs called none: "
                               f"{sum(r['both'] for r in rows if not r['expected'])} of "
                               f"{sum(1 for r in rows if not r['expected'])}; {cost_summary(rows)} "
                               f"({args.workers} at once on 2 cores)."]
    save(args.out, "diagnosis_compound", rows, lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
