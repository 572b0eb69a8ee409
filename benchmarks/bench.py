"""Benchmarks: every stage of momentid against a raw baseline timed in the same process.

``python -m benchmarks`` runs this module.  Each stage
prints momentid's time, the baseline's time and their ratio (momentid /
baseline), and ``--json-out`` writes the same rows as JSON.  Only ratios are
meaningful across machines; nothing here asserts an absolute time.

Stages and their baselines:

``simulate``
    All runs of a scenario (``simulate(workers=N)``) against one
    ``mujoco.rollout`` of the same compiled models from the same initial
    states under the same control sequences (the table drive is inside the
    model, so this is the same computation with nothing of momentid's
    around it), on N threads, the faster of two ways (one call per group of
    same-sized models on rollout's own pool, or one call per model on a
    thread pool); and ``simulate(workers=1)`` against the same
    rollout on one thread.
``replay``
    A diagnosis's replay of a run with a storey friction and a cubic storey spring (the force
    callback's Python at every RK4 stage) against ``mujoco.rollout`` of the same model and
    controls with no callback.
``record``
    ``write_experiment`` + ``read_recording`` against the ``mcap`` library
    writing the very same records (taken from momentid's file) and reading
    them back with CRC checks, without decoding them.
``identify``
    ``identify(experiment)`` against one dense ``numpy.linalg.lstsq`` of the
    stacked eq. (3) regressor matrix of all samples, built here.
``view``
    The ``.rrd`` writer of ``momentid.report.viewer`` when that module exists,
    against ``rr.send_columns`` of the same series into an ``.rrd`` file.
``run``
    The whole ``momentid run`` of the default scenario in a fresh
    interpreter (wall time), against the 3 s target.

Times are the best of ``--repeat`` interleaved repetitions: on a shared
machine the minimum is the least disturbed measurement.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from collections.abc import Callable

from benchmarks.common import Row, bench_scenario, describe_scenario, machine, scenario_variant_file
from benchmarks.stages import (RUN_TARGET_S, bench_identify, bench_record, bench_replay, bench_run, bench_simulate,
                               bench_view, stacked_regressor)
from momentid.errors import MomentidError

__all__ = ["STAGES", "RUN_TARGET_S", "bench_scenario", "scenario_variant_file", "run_benchmarks", "stacked_regressor",
           "format_report", "format_markdown", "add_arguments", "main"]

STAGES = ("simulate", "replay", "record", "identify", "view", "run")
#: Record length of ``--quick`` (s): a CI-sized smoke run of every stage.
QUICK_DURATION = 0.5


def run_benchmarks(*, stages=STAGES, scenario=None, duration: float | None = None,
                   quick: bool = False, repeat: int | None = None, workers: int | None = None,
                   blas: int | None = 1, workdir=None, log: Callable[[str], None] | None = None) -> dict:
    """Run the benchmark stages; the report as a JSON-friendly dict.

    Parameters
    ----------
    stages : iterable of str
        Any of :data:`STAGES`.
    scenario : str or Path, optional
        Scenario file for simulate, record, identify and view (default: the
        paper's 7 runs, see :func:`bench_scenario`).
    duration : float, optional
        Record length (s) replacing the scenario's; ``quick`` sets 0.5 s
        (and shortens the ``run`` stage's scenario the same way).
    repeat : int, optional
        Repetitions per measurement, the best is kept (default 3; 1 when quick).
    workers : int, optional
        Simulation worker processes (default: one per core).
    blas : int, optional
        BLAS threads for the identify stage, both sides (default 1: on a
        shared 2-core machine a second BLAS thread mostly waits; ``None``
        or 0 keeps the library's default).
    """
    from momentid.lab.simulation import available_cores, simulate

    stages = tuple(stages)
    unknown = [s for s in stages if s not in STAGES]
    if unknown:
        raise ValueError(f"unknown stage {unknown[0]!r}: expected some of {', '.join(STAGES)}")
    repeat = repeat if repeat is not None else (1 if quick else 3)
    if duration is None and quick:
        duration = QUICK_DURATION
    workers = workers if workers is not None else available_cores()
    say = log or (lambda s: None)
    report = {"machine": machine(), "settings": {"quick": quick, "repeat": repeat, "workers": workers,
                                                  "blas_threads": blas, "stages": list(stages)},
              "rows": []}
    with tempfile.TemporaryDirectory(prefix="momentid-bench-", dir=workdir) as tmp:
        tmp = Path(tmp)
        rows: list[Row] = []
        needs_data = [s for s in stages if s in ("simulate", "replay", "record", "identify", "view")]
        if needs_data:
            sc = bench_scenario(scenario, duration=duration)
            report["scenario"] = describe_scenario(sc)
            experiment = simulate(sc, workers=workers)
        for stage in stages:
            say(f"  {stage} ...")
            if stage == "simulate":
                rows += bench_simulate(sc, workers=workers, repeat=repeat)
            elif stage == "replay":
                rows += bench_replay(sc, experiment, repeat=repeat)
            elif stage == "record":
                rows += bench_record(experiment, tmp, repeat=repeat)
            elif stage == "identify":
                rows += bench_identify(experiment, repeat=repeat, threads=blas)
            elif stage == "view":
                rows += bench_view(experiment, tmp, repeat=repeat)
            elif stage == "run":
                rows += bench_run(tmp, repeat=repeat, duration=QUICK_DURATION if quick else None)
        report["rows"] = [r.to_dict() for r in rows]
    return report


def _fmt_s(x) -> str:
    return "n/a" if x is None else f"{x:.3f} s"


def format_report(report: dict) -> str:
    """The report as a plain-text table."""
    m, s = report["machine"], report["settings"]
    lines = []
    if "scenario" in report:
        sc = report["scenario"]
        lines.append(f"scenario {sc['name']}: {sc['runs']} runs x {sc['duration_s']:g} s at "
                     f"{sc['sample_rate_hz']:g} Hz, {sc['storeys']} storeys")
    lines.append(f"{m['cores']} cores, {s['workers']} simulation workers, best of {s['repeat']}, "
                 f"load average {m['load_average_1min']:.2f} at start")
    lines.append("")
    lines.append(f"{'stage':<15} {'momentid':>10} {'baseline':>10} {'ratio':>7}  baseline")
    for r in report["rows"]:
        ratio = "n/a" if r["ratio"] is None else f"{r['ratio']:.2f}"
        lines.append(f"{r['stage']:<15} {_fmt_s(r['momentid_s']):>10} {_fmt_s(r['baseline_s']):>10} "
                     f"{ratio:>7}  {r['baseline']}")
        if r["note"]:
            lines.append(f"{'':<15} {'':>10} {'':>10} {'':>7}  ({r['note']})")
    lines.append("")
    lines.append("ratio = momentid / baseline; the simulate baseline is the same rollout with "
                 "nothing of momentid's around it (target 1.5).")
    return "\n".join(lines)


def format_markdown(report: dict) -> str:
    """The report as a Markdown table (for the README)."""
    lines = ["| stage | momentid | baseline | ratio | baseline is |", "|---|---:|---:|---:|---|"]
    for r in report["rows"]:
        ratio = "n/a" if r["ratio"] is None else f"{r['ratio']:.2f}"
        lines.append(f"| {r['stage']} | {_fmt_s(r['momentid_s'])} | {_fmt_s(r['baseline_s'])} | "
                     f"{ratio} | {r['baseline']} |")
    return "\n".join(lines)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``python -m benchmarks``."""
    p.add_argument("--quick", action="store_true",
                   help=f"CI-sized: {QUICK_DURATION:g} s records, one repetition")
    p.add_argument("--stages", default=",".join(STAGES), metavar="LIST",
                   help=f"comma-separated stages (default: {','.join(STAGES)})")
    p.add_argument("--scenario", metavar="TOML",
                   help="scenario for simulate/record/identify/view (default: scenarios/"
                        "paper_harmonic.toml, the paper's 7 runs x 10 s at 1 kHz)")
    p.add_argument("--duration", type=float, metavar="S", help="record length replacing the scenario's (s)")
    p.add_argument("--repeat", type=int, metavar="N", help="repetitions, the best is kept (default 3)")
    p.add_argument("--workers", type=int, metavar="N", help="simulation workers (default: one per core)")
    p.add_argument("--blas-threads", type=int, default=1, metavar="N",
                   help="BLAS threads for the identify stage, momentid and lstsq alike (default 1; "
                        "0 = the library default); needs threadpoolctl")
    p.add_argument("--json-out", metavar="PATH", help="also write the report as JSON")
    p.add_argument("--markdown", action="store_true", help="print a Markdown table instead")


def run_from_args(args) -> int:
    stages = [s.strip() for s in args.stages.split(",") if s.strip()]
    if args.repeat is not None and args.repeat < 1:
        print(f"error: --repeat = {args.repeat}: expected at least 1 repetition", file=sys.stderr)
        return 2
    try:
        report = run_benchmarks(stages=stages, scenario=args.scenario, duration=args.duration,
                                quick=args.quick, repeat=args.repeat, workers=args.workers,
                                blas=args.blas_threads, log=lambda s: print(s, file=sys.stderr))
    except (ValueError, MomentidError) as e:  # an unknown stage, a bad scenario
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(format_markdown(report) if args.markdown else format_report(report))
    if args.json_out:
        path = Path(args.json_out)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(report, indent=2, allow_nan=False) + "\n", encoding="utf-8")
        print(f"\nwrote {path}")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.split("\n\n")[0])
    add_arguments(parser)
    return run_from_args(parser.parse_args(argv))
