"""A replay of each shipped rig's twin with each real-rig physics, by momentid's path, against
``mujoco.rollout`` of the same compiled models measured in the same run.

    python -m benchmarks.twin_replays [--rig both] [--repeat 5] [--batch 8]

Per shipped rig (``data/mini_shake_table/RIG``): its linear twin (the modal identification of its quietest
trial with the stated masses) and that twin with each real-rig kind in every storey at the twin fit's start
(``twin.fit.mechanism_start``; joint friction at ``diagnosis.twin.folds.FRICTION_STARTS``), ``--batch``
copies compiled at the twin's step (a Jacobian's block of perturbed models), replayed through the rig's
first trial on one thread:

* momentid: ``lab.resim.simulate`` as the twin's fit calls it, which picks the path: MuJoCo's own step map
  for a linear twin (``lab.linear_replay``), compiled RK4 for a twin whose only nonlinear forces are compiled
  laws (``lab.native_replay``: Bouc-Wen), the step map with its sliders' friction rows and its tendons'
  polynomial forces solved in the loop for a twin with those nonlinearities alone (``lab.step_replay``: joint
  friction, cubic spring, quadratic damping), else ``mujoco.rollout``;
* the baseline: the same call with the compiled paths off, ``mujoco.rollout`` of the same models, states
  and controls (the native callbacks installed where the twin has them).

Each time is the best of ``--repeat`` interleaved repetitions; the table gives the ratio momentid / rollout,
the path, and how far the two readings are apart (relative to the signal's RMS).  Writes
``twin_replays.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from benchmarks.common import RESULTS, ROOT, machine, save

DATA = ROOT / "data" / "mini_shake_table"
RIGS = ("stiff_1storey", "flexible_3storey")


def twins(rig: str) -> tuple:
    """(trial, {physics name: twin}) of ``rig``: its linear twin and one per real-rig kind at the fit's start."""
    from momentid.diagnosis.twin.folds import FRICTION_STARTS, linear_start
    from momentid.io.importer import import_folder
    from momentid.mechanisms import registry
    from momentid.twin import fit as twin_fit

    experiment = import_folder(DATA / rig)
    quietest = min(experiment.runs, key=lambda r: float(np.nanstd(r["a1"])))
    linear = linear_start(experiment, quietest.name)
    tr = twin_fit.trial(experiment.runs[0], experiment.storeys)
    storeys = tuple(range(1, experiment.storeys + 1))
    out = {"linear": linear}
    for kind in registry.real_rig_kinds():
        if kind.name == "joint_friction":
            out[kind.name] = twin_fit.friction_start(linear, storeys, *FRICTION_STARTS[0])
        else:
            out[kind.name] = twin_fit.mechanism_start(linear, kind.name, storeys, [tr])
    return tr, out


def _path(models, linear: bool) -> str:
    """The replay ``lab.resim.simulate`` takes for ``models`` (``linear``: as the twin's fit asks)."""
    from momentid.lab import native_replay, step_replay

    if linear:
        return "step map (linear_replay)"
    if native_replay.applies(models):
        return "compiled RK4 (native_replay)"
    return "step map and nonlinear inputs (step_replay)" if step_replay.applies(models) else "mujoco.rollout"


def measure(rig: str, repeat: int, batch: int) -> list[dict]:
    """One row per physics of ``rig``: best wall seconds of momentid's replay and of the rollout, their ratio,
    the path and the readings' largest difference relative to their RMS."""
    from momentid.lab import native_replay, resim, step_replay

    tr, physics = twins(rig)
    substeps = resim.substeps_for(tr.dt)
    rows = []
    for name, twin in physics.items():
        models = resim.compile_models([twin.rig()] * batch, tr.dt / substeps)
        drive = twin.drive(tr)
        linear = not twin.friction
        best = {"momentid": np.inf, "rollout": np.inf}
        out = {}
        for _ in range(repeat):
            for side in ("momentid", "rollout"):
                native_replay.ENABLED = step_replay.ENABLED = side == "momentid"
                try:
                    start = time.perf_counter()
                    out[side] = resim.simulate(models, drive, tr.dt, substeps, threads=1,
                                               linear=linear and side == "momentid")
                    best[side] = min(best[side], time.perf_counter() - start)
                finally:
                    native_replay.ENABLED = step_replay.ENABLED = True
        scale = float(np.sqrt(np.mean(out["rollout"] ** 2)))
        rows.append({"rig": rig, "physics": name, "path": _path(models, linear), "models": batch,
                     "steps": int(len(drive) * substeps), "momentid_s": best["momentid"],
                     "rollout_s": best["rollout"], "ratio": best["momentid"] / best["rollout"],
                     "max_rel_diff": float(np.max(np.abs(out["momentid"] - out["rollout"]))) / scale})
    return rows


def table(rows: list[dict], command: str) -> list[str]:
    """The markdown table of ``rows``."""
    lines = [f"`{command}` (see its docstring)", "",
             "| rig | physics | momentid's path | models x steps | momentid (s) | mujoco.rollout (s) | ratio | "
             "max difference / RMS |", "|---|---|---|---|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['rig']} | {r['physics']} | {r['path']} | {r['models']} x {r['steps']} | "
                     f"{r['momentid_s']:.3f} | {r['rollout_s']:.3f} | {r['ratio']:.2f} | {r['max_rel_diff']:.1e} |")
    m = machine()
    return lines + ["", f"load average {m['load_average_1min']:.1f} at the end on {m['cores']} cores, "
                        f"MuJoCo {m['mujoco']}, one thread each side"]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.twin_replays", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rig", choices=RIGS + ("both",), default="both")
    p.add_argument("--repeat", type=int, default=5, help="interleaved repetitions (the best is reported)")
    p.add_argument("--batch", type=int, default=8, help="models replayed together (a Jacobian's block)")
    p.add_argument("--out", default=str(RESULTS))
    args = p.parse_args(argv)
    if args.repeat < 1 or args.batch < 1:
        p.error("--repeat and --batch: expected at least 1")
    rigs = RIGS if args.rig == "both" else (args.rig,)
    rows = [row for rig in rigs for row in measure(rig, args.repeat, args.batch)]
    command = "python -m benchmarks.twin_replays " + " ".join(argv if argv is not None else [])
    save(Path(args.out), "twin_replays", {"rows": rows, "machine": machine()}, table(rows, command.strip()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
