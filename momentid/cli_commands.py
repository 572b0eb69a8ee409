"""What each ``momentid`` command does once its options are parsed (:func:`momentid.cli.build_parser`
sets them): one function per command, taking the parsed options (an :class:`argparse.Namespace`) and
returning the exit code, 0 unless its docstring says otherwise.

Used by :mod:`momentid.cli`, which turns every expected failure into one ``error:`` line.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from momentid.cli_output import (identification_output, output_folder, output_path, replaced, report_page,
                                 write_identification_folder)
from momentid.cli_values import run_names
from momentid.core.series import json_safe
from momentid.errors import IdentificationError, MomentidError
from momentid.io.outputs import check_file, drop_link

if TYPE_CHECKING:
    from momentid.core.series import Experiment
    from momentid.estimation.identified import Identification
    from momentid.estimation.scaled import ModalIdentification

__all__ = ["command_run", "command_identify", "command_import", "command_view", "command_sweep",
           "command_diagnose", "command_twin", "command_plan"]


def _refuse_implausible(experiment: Experiment, result: Identification | ModalIdentification) -> None:
    """No answer is printed that the data contradict (units, swapped columns, masses in grams)."""
    from momentid.estimation.plausibility import implausible

    reasons = implausible(experiment, result)
    if reasons:
        raise IdentificationError(f"{experiment.source}: refused: the data contradict the identified model: "
                                  + "; ".join(reasons) + "; `momentid diagnose` locates a mismatch")


def _report(experiment: Experiment, args: argparse.Namespace, out: Path | None = None) -> int:
    """Identify ``experiment``, print the result (``--json``: one JSON object) and, with ``out`` (``identify
    -o``), write its folder (:func:`momentid.report.files.write_identification`)."""
    from momentid.estimation.comparison import compare
    from momentid.estimation.identification import identify
    from momentid.estimation.scaled import ModalIdentification

    times = args.time if args.time else None
    runs = run_names(args.runs)
    try:
        result = identify(experiment, estimator=args.estimator, runs=runs, times=times, mass=args.mass)
    except IdentificationError as exc:
        if times is not None and str(exc).startswith("times = "):  # the API's name -> the option's
            raise IdentificationError("--time " + " --time ".join(f"{x:g}" for x in times)
                                      + str(exc)[str(exc).index(":"):]) from None
        raise
    _refuse_implausible(experiment, result)

    comparison = None
    if isinstance(result, ModalIdentification):       # no added mass: modes, not the analytic comparison
        payload, text = result.to_dict(), result.table(warnings=False)   # warnings: on stderr, once
    elif experiment.structure is not None:
        comparison = compare(result, experiment.structure)
        payload = comparison.to_dict()
        text = comparison.table()
    else:
        payload = result.to_dict()
        payload["analytic"] = None
        text = "\n".join(f"{k}: {v}" for k, v in payload.items())
    if experiment.notes:  # what was recovered or repaired reading the file (also on stderr)
        payload["notes"] = list(experiment.notes)
    if args.json:
        print(json.dumps(json_safe(payload), indent=2, allow_nan=False))
    else:
        print(text)
    if out is not None:
        write_identification_folder(out, result, experiment, payload, args, comparison=comparison)
    _warn(result.warnings)
    return 0


def command_run(args: argparse.Namespace) -> int:
    """Simulate, record, identify and compare every run of a scenario (``momentid run``).

    The recording goes to ``-o``; ``--view`` then shows it in rerun.
    """
    from momentid.lab.scenario import default_scenario_path, load_scenario
    from momentid.lab.simulation import run_experiment

    path = Path(args.scenario) if args.scenario else default_scenario_path()
    scenario = load_scenario(path)
    unknown = [n for n in run_names(args.runs) or () if n not in {r.name for r in scenario.runs}]
    if unknown:   # before minutes of simulation, not after
        raise MomentidError(f"--runs {args.runs}: {path} has no run named {unknown[0]!r}; its runs are "
                            f"{', '.join(r.name for r in scenario.runs)}")
    out = output_path(args.output, scenario.name, force=args.force)
    progress, existed = not args.quiet and sys.stderr.isatty(), out.exists()
    drop_link(out)
    experiment = run_experiment(scenario, out, progress=progress, workers=args.workers)
    replaced(out, existed)
    if not args.json:
        print(f"scenario {scenario.name}: {len(experiment.runs)} runs x {scenario.duration:g} s at "
              f"{scenario.sample_rate:g} Hz -> {out}\n")
    status = _report(experiment, args)
    if args.view:
        from momentid.report.viewer import view

        view(experiment, identify_options={"estimator": args.estimator, "times": args.time or None,
                                           "runs": run_names(args.runs)})
    return status


def command_identify(args: argparse.Namespace) -> int:
    """Identify a recording and print the result (``momentid identify``).

    ``--stream`` reads it block by block, ``--per-run`` fits each run and the amplitude trend, ``-o``
    also writes the result's folder.
    """
    from momentid.io.exclusive import exclusive
    from momentid.io.recording import read_recording

    if args.stream:
        return _identify_stream(args)
    out = identification_output(args)   # checked before the work
    experiment = read_recording(args.recording)
    with exclusive(out) if out is not None else contextlib.nullcontext():   # one writer per folder
        if not args.per_run:
            return _report(experiment, args, out)
        from momentid.estimation.scaled import amplitude_trend, identify_per_run

        results = identify_per_run(experiment, run_names(args.runs))
        trend = amplitude_trend(results) if len(results) > 1 else None
        payload = trend.to_dict() if trend else {"runs": [r.to_dict() for r in results]}
        if args.json:
            print(json.dumps(json_safe(payload), indent=2, allow_nan=False))
        else:
            print("\n\n".join(r.table(warnings=False) for r in results))   # warnings: on stderr, once
            if trend is not None:
                print("\n" + trend.table())
        if out is not None:
            write_identification_folder(out, tuple(results), experiment, payload, args, trend=trend)
        for r in results:
            _warn(r.warnings, r.runs[0])
        return 0


def _identify_stream(args: argparse.Namespace) -> int:
    """``identify --stream``: the equation form read block by block (flat memory)."""
    from momentid.estimation.comparison import compare
    from momentid.estimation.identification import identify_stream

    # The stream reads each block once and keeps only the equation form's triangular factor, so the
    # options that need the whole record (or choose among runs and instants) cannot apply: refuse them
    # rather than silently compute something else.
    ignored = [f"--estimator {args.estimator}" if args.estimator not in ("auto", "equation") else "",
               "--runs" if args.runs else "", "--time" if args.time else "",
               "--per-run" if args.per_run else "", "-o (its transfer functions)" if args.output else ""]
    ignored = [o for o in ignored if o]
    if ignored:
        raise IdentificationError(f"{args.recording}: --stream computes the equation form over every sample of every "
                         f"run, block by block; it cannot honour {', '.join(ignored)}: drop --stream (which "
                         f"reads the whole record into memory) or drop {', '.join(ignored)}")
    result, meta = identify_stream(args.recording, mass=args.mass, return_structure=True)
    payload = compare(result, meta).to_dict() if meta is not None else result.to_dict()
    if result.notes:   # they name runs a damaged file lost
        payload["notes"] = list(result.notes)
    if args.json:
        print(json.dumps(json_safe(payload), indent=2))
    else:
        print(compare(result, meta).table() if meta is not None else json.dumps(json_safe(payload)))
    for note in result.notes:
        print(f"note: {note}", file=sys.stderr)
    _warn(result.warnings)
    return 0


def _warn(warnings: Iterable[str], run: str | None = None) -> None:
    """Every warning on stderr, loudly: results the data contradict are never printed silently."""
    for w in warnings:
        print(f"WARNING{f' ({run})' if run else ''}: {w}", file=sys.stderr)


def command_import(args: argparse.Namespace) -> int:
    """Turn a lab's folder of raw exports into a recording (``momentid import``).

    Prints what the import found and repaired, then where the recording went.
    """
    from momentid.io.importer import import_folder, report, summary, write_import

    out = output_path(args.output, Path(args.folder).resolve().name, force=args.force)   # before the work
    experiment = import_folder(args.folder, relabel=not args.refuse_mislabelled)
    out = output_path(args.output, Path(args.folder).resolve().name, force=args.force)   # and again now
    existed = out.exists()
    drop_link(out)
    out = write_import(experiment, out)
    replaced(out, existed)
    for line in report(experiment):
        print(line)
    print(summary(experiment, out))
    return 0


def command_view(args: argparse.Namespace) -> int:
    """Show a recording in the rerun viewer, or save it as ``.rrd`` (``momentid view``)."""
    from momentid.report.viewer import view

    if args.save is not None:
        check_file(args.save, "rerun", option="--save", force=args.force)
        drop_link(args.save)
    out = view(args.recording, save=args.save, result=args.result, exaggeration=args.exaggeration,
               run=args.run, twin=args.twin)
    if out is not None:
        print(f"{args.recording} -> {out} (open it with: rerun {out})")
    return 0


def command_sweep(args: argparse.Namespace) -> int:
    """Run every case of a sweep file and write its table (``momentid sweep``).

    Cases run on local cores or a Dask cluster; one row per case is printed.
    Returns the exit code 0 (cases that failed are rows of the table, not an error).
    """
    from momentid.io.exclusive import reserve
    from momentid.sweep import load_sweep, run_sweep, table_path, table_text

    out = table_path(args.output) if args.output else Path("out") / f"{Path(args.spec).stem}.csv"
    check_file(out, "table", force=args.force)
    sweep = load_sweep(args.spec)
    drop_link(out)
    where = f"Dask scheduler {args.address}" if args.address else "local cores"
    show = not args.quiet and sys.stderr.isatty()

    def done(row):
        if show:
            print(f"  case {row['case']}: {row['status']}", file=sys.stderr)

    with reserve(out) as slot:   # one writer per table, refused before the sweep starts
        print(f"sweep {args.spec}: {len(sweep.cases)} cases of {sweep.base} over "
              f"{', '.join(sweep.keys)} on {where}", file=sys.stderr)
        rows = run_sweep(sweep, workers=args.workers, address=args.address, on_case=done)
        slot.commit(table_text(rows, out).encode("utf-8"))
    widths = [max(len(k), 8) for k in sweep.keys]
    print(f"{'case':>5}  " + "  ".join(f"{k:>{w}}" for k, w in zip(sweep.keys, widths))
          + f"  {'max rel err':>11}  status")
    for row in rows:
        cells = "  ".join(f"{json.dumps(row['values'][k]):>{w}}" for k, w in zip(sweep.keys, widths))
        err = row.get("max_rel_error")
        err = "n/a" if err is None else f"{err:.2e}"
        print(f"{row['case']:>5}  {cells}  {err:>11}  {row['error'] or 'ok'}")
    failed = sum(r["status"] != "ok" for r in rows)
    print(f"\n{len(rows) - failed} of {len(rows)} cases identified; table written to {out}")
    return 0


def command_diagnose(args: argparse.Namespace) -> int:
    """Diagnose a recording and write its report folder (``momentid diagnose``).

    Prints the summary, or report.json with ``--json``.
    """
    from momentid.diagnosis.dispatch import diagnose, write_report
    from momentid.diagnosis.report import REPORT_FILES, report_folder
    from momentid.report.files import diagnosis_html_page
    from momentid.io.exclusive import exclusive
    from momentid.io.recording import read_recording

    out = output_folder(args.output) if args.output else Path("out") / f"{Path(args.recording).stem}_diagnosis"
    report_folder(out, force=args.force).check(REPORT_FILES)   # before minutes of work
    experiment = read_recording(args.recording)
    with exclusive(out):   # one writer per report folder, refused before minutes of work
        diag = diagnose(experiment, hold_out=args.hold_out)
        written = write_report(diag, out, force=args.force, extra=lambda folder: [
            report_page(folder, lambda made: diagnosis_html_page(diag, made, args.recording), args)])
    if args.json:
        print(json.dumps(json_safe(diag.to_dict()), indent=2))
    else:
        print(diag.summary)
        print(f"\nreport written to {out}/ ({', '.join(written)})")
    return 0


def command_twin(args: argparse.Namespace) -> int:
    """Build the calibrated MuJoCo twin of a recording and write its folder (``momentid twin``).

    Prints its summary, or twin.json with ``--json``.
    """
    from momentid.io.exclusive import exclusive
    from momentid.io.recording import read_recording
    from momentid.report.files import twin_html_page
    from momentid.twin import build_twin, write_twin
    from momentid.twin.files import file_names, output_folder as twin_folder

    out = output_folder(args.output) if args.output else Path("out") / f"{Path(args.recording).stem}_twin"
    runs = run_names(args.runs)
    twin_folder(out, force=args.force).check(())   # before the recording is read
    experiment = read_recording(args.recording)
    twin_folder(out, force=args.force).check(file_names([r.name for r in experiment.runs], not args.no_plots))
    with exclusive(out):   # one writer per twin folder, refused before the twin is built
        twin = build_twin(experiment, runs)
        page = None if args.no_plots else (
            lambda folder: [report_page(folder, lambda made: twin_html_page(twin, experiment, made), args)])
        names = write_twin(twin, experiment, out, plots=not args.no_plots, force=args.force, extra=page)
    if args.json:
        print(json.dumps(json_safe(twin.to_dict()), indent=2, allow_nan=False))
    else:
        print(twin.summary())
        print(f"\ntwin written to {out}/ ({', '.join(names)})")
    _warn(twin.warnings)
    return 0


def command_plan(args: argparse.Namespace) -> int:
    """Recommend the cheapest design that reaches ``--target`` (``momentid plan``).

    Prints the Cramér-Rao bound of the scenario's design and of every candidate design.
    Returns the exit code 0, or 1 when no candidate reaches the target.
    """
    from momentid.estimation.design import cramer_rao, plan, plan_progress_bar
    from momentid.lab.scenario import load_scenario

    scenario = load_scenario(args.scenario)
    if args.max_runs < 2:
        raise MomentidError(f"--max-runs {args.max_runs}: expected at least 2 (a reference run and one with "
                            "added mass)")
    with plan_progress_bar(not args.quiet and sys.stderr.isatty()) as progress:
        designs, best = plan(scenario, target=args.target, max_runs=args.max_runs, time_limit=args.time_limit,
                             progress=progress)
    as_designed = cramer_rao(scenario)
    if args.json:
        payload = {
            "target": args.target,
            "scenario_design": as_designed.as_dict(),
            "designs": [{"label": d.label, "excitation": d.excitation,
                         "added_mass": [[float(x) for x in r.added_mass] for r in d.runs],
                         "worst_parameter": d.bound.worst[0], "worst_relative_std": d.bound.worst[1],
                         "crlb": d.bound.as_dict()} for d in designs],
            "recommended": None if best is None else {
                "label": best.label, "excitation": best.excitation,
                "added_mass": [[float(x) for x in r.added_mass] for r in best.runs]},
        }
        print(json.dumps(json_safe(payload), indent=2))
        return 0
    name, worst = as_designed.worst
    print(f"scenario {scenario.name} as designed ({len(scenario.runs)} runs): worst relative CRLB std "
          f"{worst:.3g} ({name})\n")
    print(f"{'excitation':<24} {'design':<38} {'added kg':>9} {'worst':>7} {'rel. std':>9} {'mu':>9}")
    mu_index = designs[0].bound.names.index("mu") if designs else 0
    for d in designs:
        mark = "  <- recommended" if d is best else ""
        print(f"{d.excitation:<24} {d.label:<38} {d.added_mass_total:>9.3g} {d.bound.worst[0]:>7} "
              f"{d.bound.worst[1]:>9.3g} {d.bound.relative[mu_index]:>9.3g}{mark}")
    print()
    if best is None:
        print(f"no candidate reaches a relative standard deviation of {args.target:g} for every parameter: "
              f"lower the sensor noise, lengthen the record or add runs (--max-runs)")
        return 1
    print(f"recommended: {best.label} under {best.excitation} excitation; added masses per run (kg):")
    for r in best.runs:
        print(f"  {r.name}: {[round(float(x), 4) for x in r.added_mass]}")
    return 0
