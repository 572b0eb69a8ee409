"""How long ``momentid twin`` takes on the shipped rig, against ``momentid identify`` of the same trials.

    python -m benchmarks.twin [--repeat 1]

Imports ``data/mini_shake_table/flexible_3storey`` (five trials, 120 Hz, three floors), then runs, in
this process and one after the other, ``momentid identify REC --runs R`` (the baseline: the twin's
calibration is this identification) and ``momentid twin REC -o DIR --runs R`` for the five trials and
for the four recorded the same day.  Reports wall and CPU seconds (this process and its forked
workers), the ratio twin / identify, where the twin's own time goes (identification, replays, files),
and the twin's per-trial NRMSE.  Writes ``benchmarks/results/twin.json`` and ``twin.md``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import resource
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "data" / "mini_shake_table" / "flexible_3storey"
SAME_DAY = "northridge,sine_1p0,sine_1p5,sine_2p0"


def _cpu() -> float:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def timed(fn):
    wall, cpu = time.perf_counter(), _cpu()
    out = fn()
    return out, time.perf_counter() - wall, _cpu() - cpu


def cli(argv) -> str | None:
    """Run ``momentid argv``; None when it succeeds, else its one-line error."""
    from momentid.cli import main

    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(argv)
    return None if code == 0 else err.getvalue().strip().splitlines()[-1]


def stages(rec: Path, runs: str, out: Path) -> dict:
    """Wall seconds of the twin's stages, called one by one."""
    from momentid.core.processes import run_forked
    from momentid.estimation.identification import identify
    from momentid.io.recording import read_recording
    from momentid.twin import build, files, parameters, replay, spec

    experiment, t_read, _ = timed(lambda: read_recording(rec))
    result, t_identify, _ = timed(lambda: identify(experiment, runs=runs.split(",")))
    params = parameters.from_identification(result, experiment)
    t = spec.timing(params, experiment.runs[0].sample_rate)
    replays, t_replay, _ = timed(lambda: tuple(run_forked(lambda r: replay.replay_run(params, r), experiment.runs)))
    xml = spec.twin_spec(params, t.timestep).to_xml()
    twin = build.Twin(params, result, t, xml, build.check_xml(xml), replays, str(rec))
    _, t_files, _ = timed(lambda: files.write_twin(twin, experiment, out))
    return {"read_s": t_read, "identify_s": t_identify, "replays_s": t_replay, "files_and_plots_s": t_files}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.twin", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeat", type=int, default=1, help="runs of each command (the fastest is kept)")
    args = p.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        rec = Path(tmp) / "flex3.mcap"
        cli(["import", str(SHIPPED), "-o", str(rec)])
        for label, runs in (("five trials", None), ("four same-day trials", SAME_DAY)):
            select = ["--runs", runs] if runs else []
            ident = min(timed(lambda: cli(["identify", str(rec), *select]))[1:] for _ in range(args.repeat))
            refused, wall, cpu = timed(lambda: cli(["twin", str(rec), "-o", f"{tmp}/{label}", *select]))
            if refused:
                row = {"calibrated_on": label, "identify_wall_s": ident[0], "twin_wall_s": wall, "refused": refused}
                rows.append(row)
                print(json.dumps(row), flush=True)
                continue
            twin = min([(wall, cpu)] + [timed(lambda: cli(["twin", str(rec), "-o", f"{tmp}/{label}", *select]))[1:]
                                        for _ in range(args.repeat - 1)])
            data = json.loads((Path(tmp) / label / "twin.json").read_text())
            row = {"calibrated_on": label, "identify_wall_s": ident[0], "identify_cpu_s": ident[1],
                   "twin_wall_s": twin[0], "twin_cpu_s": twin[1], "ratio_wall": twin[0] / ident[0],
                   "load_average": os.getloadavg()[0],
                   "stages_wall_s": stages(rec, runs or ",".join(t["run"] for t in data["trials"]), Path(tmp) / "st"),
                   "trials": [{k: t[k] for k in ("run", "calibration", "nrmse", "noise_nrmse", "nrmse_per_floor")}
                              for t in data["trials"]]}
            rows.append(row)
            print(json.dumps(row), flush=True)
    out = ROOT / "benchmarks" / "results"
    out.mkdir(parents=True, exist_ok=True)
    (out / "twin.json").write_text(json.dumps(rows, indent=1) + "\n")
    (out / "twin.md").write_text(markdown(rows))
    return 0


def markdown(rows) -> str:
    lines = ["# `momentid twin` on the shipped rig", "", "`python -m benchmarks.twin` (one process, commands one "
             "after the other; wall and CPU seconds, CPU including the forked workers).", "",
             "| calibrated on | identify wall (s) | twin wall (s) | twin / identify wall | twin CPU (s) | "
             "identification / replays / files (wall s) | load average |", "|---|---:|---:|---:|---:|---|---:|"]
    for r in rows:
        if "refused" in r:
            lines.append(f"| {r['calibrated_on']} | {r['identify_wall_s']:.1f} | {r['twin_wall_s']:.1f} | refused: "
                         f"`{r['refused']}` | | | |")
            continue
        s = r["stages_wall_s"]
        lines.append(f"| {r['calibrated_on']} | {r['identify_wall_s']:.1f} | {r['twin_wall_s']:.1f} | "
                     f"{r['ratio_wall']:.2f} | {r['twin_cpu_s']:.1f} | {s['identify_s']:.1f} / {s['replays_s']:.1f} / "
                     f"{s['files_and_plots_s']:.1f} | {r['load_average']:.1f} |")
    for r in (r for r in rows if "refused" not in r):
        lines += ["", f"Per-trial NRMSE, calibrated on {r['calibrated_on']}:", "",
                  "| trial | sensors | NRMSE (%) | noise alone (%) | per floor sensor (%) |", "|---|---|---:|---:|---|"]
        lines += [f"| {t['run']} | {'calibrated' if t['calibration'] else 'nominal'} | {100 * t['nrmse']:.2f} | "
                  f"{100 * t['noise_nrmse']:.2f} | {', '.join(f'{100 * x:.2f}' for x in t['nrmse_per_floor'])} |"
                  for t in r["trials"]]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
