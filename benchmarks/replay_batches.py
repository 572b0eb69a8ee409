"""A diagnosis's batch of replays three ways: one after the other, forked workers, threads.

    python -m benchmarks.replay_batches [--repeat 3] [--out benchmarks/results]

The batch: the misfits of four sizes of a force at storey 2 of ``scenarios/hidden/``'s rig (paper
structure, El Centro, 20 s at 1 kHz, noise-free), each a replay of the search run through the augmented
model (:meth:`momentid.diagnosis.added_mass.resimulation.Refitter.misfits`: a size search's opening and
curvature points), for a callback force (``coulomb_friction``, its compiled law native) and for a force
in the MJCF (``extra_damper``).  Each way is timed best of ``--repeat``, interleaved, in one process,
with the raw ``mujoco.rollout`` of one such run (no force) as the unit; the values must be equal bit for
bit.  The diagnosis takes threads where the forces run natively
(:func:`~momentid.diagnosis.added_mass.resimulation.side_by_side`).  Writes ``replay_batches.json`` and
``.md``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from benchmarks.common import RESULTS, hidden_rig, machine, raw_rollout_seconds, save

CASES = (("coulomb_friction", {"force": 0.3}), ("extra_damper", {"c": 2.0}))
FACTORS = (0.8, 0.9, 1.1, 1.2)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.replay_batches", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    import momentid as mi
    from momentid import mechanisms
    from momentid.core.processes import run_forked, run_threaded
    from momentid.diagnosis.added_mass.augmented import Entry
    from momentid.diagnosis.added_mass.residuals import fit_linear_model
    from momentid.diagnosis.added_mass.resimulation import Refitter

    load = os.getloadavg()
    rows = []
    for name, params in CASES:
        kind = mechanisms.get(name)
        experiment = mi.simulate(hidden_rig([{"type": name, "storey": 2, **params}], noise=0.0))
        refitter = Refitter(fit_linear_model(experiment), None)
        key = kind.fitted.name
        trials = [(refitter.linear_structure, [Entry(kind, kind.place(2), {**params, key: params[key] * f})])
                  for f in FACTORS]

        def job(trial):
            return refitter.misfit(*trial)
        job(trials[0])   # compiled laws loaded, caches warm
        ways = {"serial": lambda: [job(t) for t in trials], "forked": lambda: run_forked(job, trials),
                "threads": lambda: run_threaded(job, trials)}
        best, values = {w: float("inf") for w in ways}, {}
        for _ in range(args.repeat):
            for way, fn in ways.items():
                start = time.perf_counter()
                values[way] = fn()
                best[way] = min(best[way], time.perf_counter() - start)
        raw = raw_rollout_seconds(experiment)
        rows.append({"force": name, "replays": len(trials), "seconds": best, "raw_rollout_seconds": raw,
                     "equal": values["serial"] == values["forked"] == values["threads"]})
    out = {"rows": rows, "load_average": [round(x, 1) for x in load], "repeat": args.repeat, "machine": machine()}
    lines = ["| force | replays | one after the other | forked workers | threads | in raw rollouts (serial / forked "
             "/ threads) | equal |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        s, raw = r["seconds"], r["raw_rollout_seconds"]
        lines.append(f"| {r['force']} | {r['replays']} | {s['serial']:.3f} s | {s['forked']:.3f} s | "
                     f"{s['threads']:.3f} s | {s['serial'] / raw:.1f} / {s['forked'] / raw:.1f} / "
                     f"{s['threads'] / raw:.1f} | {'yes' if r['equal'] else 'NO'} |")
    lines += ["", f"Best of {args.repeat}, interleaved; load average {load[0]:.1f} on the machine's "
                  f"{os.cpu_count()} cores (shared)."]
    save(args.out, "replay_batches", out, lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
