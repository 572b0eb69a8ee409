"""The ``momentid`` command line: a thin layer over the Python API.

Every user mistake ends as one line ``error: ...`` on stderr and exit code 2;
an interrupted run exits 130.  Run ``momentid COMMAND --help`` for details.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import signal
import sys
import warnings
from pathlib import Path

from momentid.core.processes import Terminated, quiet_broken_pipe, sigterm_as_interrupt
from momentid.core.series import json_safe
from momentid.estimation.design import PLAN_TIME_LIMIT_S
from momentid.errors import IdentificationError, MomentidError, RecoveryWarning
from momentid.cli_output import (identification_output, only_json_on_stdout, output_folder, output_path,
                                 refuse_empty_paths, replaced, report_page, write_identification_folder)
from momentid.cli_values import finite_time, positive_float, positive_int, run_names
from momentid.io.outputs import check_file, drop_link

__all__ = ["main", "only_json_on_stdout"]

_EPILOG = """examples:
  momentid run                                        # the embedded default scenario
  momentid run scenarios/paper_harmonic.toml -o out/  # any scenario file
  momentid identify out/paper_harmonic.mcap           # identification from the recording alone
  momentid identify out/paper_harmonic.mcap --json    # machine-readable result
  momentid view out/paper_harmonic.mcap               # the rerun viewer (--save out.rrd: a file)
  momentid plan scenarios/lab_noisy.toml              # runs and masses for a target accuracy (CRLB)
  momentid import lab_data/ -o lab.mcap               # a real rig's exports (CSV, Xsens DOT) -> recording
  momentid diagnose lab.mcap -o report/               # locate a mismatch, name the missing physics
  momentid twin lab.mcap -o twin/                     # the calibrated MuJoCo twin of the rig
"""


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as one line on stderr: ``note:`` for data recovered from a damaged input, else
    ``warning:``; never the source line of the code that warned."""
    kind = "note" if issubclass(category, RecoveryWarning) else "warning"
    print(f"{kind}: {message}", file=sys.stderr)


def _os_error(exc: OSError) -> str:
    """One line for an operating-system failure (disk full, no such folder, permission)."""
    where = exc.filename if exc.filename is not None else "output"
    return f"cannot write or read {where}: {exc.strerror or exc}"


def _refuse_implausible(experiment, result) -> None:
    """No answer is printed that the data contradict (units, swapped columns, masses in grams)."""
    from momentid.estimation.plausibility import implausible

    reasons = implausible(experiment, result)
    if reasons:
        raise IdentificationError(f"{experiment.source}: refused: the data contradict the identified model: "
                                  + "; ".join(reasons) + "; `momentid diagnose` locates a mismatch")


def _report(experiment, args, out: Path | None = None) -> int:
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


def _cmd_run(args) -> int:
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


def _cmd_identify(args) -> int:
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


def _identify_stream(args) -> int:
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


def _warn(warnings, run: str | None = None) -> None:
    """Every warning on stderr, loudly: results the data contradict are never printed silently."""
    for w in warnings:
        print(f"WARNING{f' ({run})' if run else ''}: {w}", file=sys.stderr)


def _cmd_import(args) -> int:
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


def _cmd_view(args) -> int:
    from momentid.report.viewer import view

    if args.save is not None:
        check_file(args.save, "rerun", option="--save", force=args.force)
        drop_link(args.save)
    out = view(args.recording, save=args.save, result=args.result, exaggeration=args.exaggeration,
               run=args.run, twin=args.twin)
    if out is not None:
        print(f"{args.recording} -> {out} (open it with: rerun {out})")
    return 0


def _cmd_sweep(args) -> int:
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


def _cmd_diagnose(args) -> int:
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


def _cmd_twin(args) -> int:
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


def _cmd_plan(args) -> int:
    from momentid.estimation.design import cramer_rao, plan, plan_progress_bar
    from momentid.lab.scenario import load_scenario

    scenario = load_scenario(args.scenario)
    if args.max_runs < 2:
        raise MomentidError(f"--max-runs {args.max_runs}: expected at least 2 (a reference run and one with added mass)")
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
            "recommended": None if best is None else {"label": best.label, "excitation": best.excitation,
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


def _add_identify_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--estimator", choices=("auto", "equation", "difference", "eiv", "modal"), default="auto",
                   help="'auto' (default): 'modal' when no run adds mass, else 'equation' for noise-free "
                        "data and 'eiv' for noisy data; 'modal': modes (and K, C from stated masses) from "
                        "runs without added mass; 'equation': every "
                        "run on its own, all samples in one least-squares problem (method.md eq. 3); "
                        "'difference': each run minus the reference run (the paper's eq. 2), needs "
                        "identical table motion; 'eiv': errors-in-variables maximum likelihood, unbiased "
                        "by sensor noise, with standard errors")
    p.add_argument("--mass", choices=("diagonal", "full"), default="diagonal",
                   help="identify a diagonal (default) or full symmetric mass matrix")
    p.add_argument("--time", type=finite_time, action="append", metavar="T",
                   help="use only the sample nearest time T (s); repeat for several instants "
                        "(e.g. --estimator difference --time 5 reproduces the paper's system)")
    p.add_argument("--runs", metavar="NAMES", help="comma-separated run names to use (default: all)")
    p.add_argument("--json", action="store_true",
                   help="print one JSON object (M, C, K, mu, kappa, analytic, ...) instead of the table")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="momentid",
        description="A virtual shake-table laboratory: simulate added-mass runs of a shear building "
                    "on a MuJoCo rig, record them to MCAP, and identify M, C, K and Rayleigh damping "
                    "(Majcher 2025, input-output method with system momentum change).",
        epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    from momentid import __version__, mechanisms
    parser.add_argument("--version", action="version", version=f"momentid {__version__}")
    parser.set_defaults(json=False)   # the commands without --json
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    p = sub.add_parser("run", help="simulate every run of a scenario, record it, identify, compare",
                       description="Simulate every added-mass run of SCENARIO on the MuJoCo rig, "
                                   "write the MCAP recording, identify M, C, K, mu, kappa from it "
                                   "and compare them with the scenario's analytic model.")
    p.add_argument("scenario", nargs="?", help="scenario TOML file (default: the embedded default scenario)")
    p.add_argument("-o", "--output", metavar="PATH",
                   help="output folder (the recording is PATH/<name>.mcap) or a .mcap file (default: out/)")
    _add_force(p)
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.add_argument("-j", "--workers", type=positive_int, metavar="N",
                   help="simulate up to N runs at once in worker processes (default: one per core; "
                        "1 = in this process)")
    _add_identify_options(p)
    p.add_argument("--view", action="store_true",
                   help="after identification, show the recording in the rerun viewer (momentid view)")
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser("identify", help="identify M, C, K, mu, kappa (or, without added mass, the modes) "
                                        "from a recording",
                       description="Identify M, C, K, mu and kappa from an MCAP recording alone and "
                                   "compare with the nominal model stored in it.  When no run adds mass "
                                   "(most real labs), identify the natural frequencies, damping ratios "
                                   "and mode shapes with standard errors, M^-1 K and M^-1 C, and K and C "
                                   "in SI units when the lab states its floor masses.  Every result the "
                                   "data contradict (unstable mode, non-positive mass, capped fit) is "
                                   "printed with a WARNING on stderr.")
    p.add_argument("recording", help="MCAP recording written by momentid (or any rig following "
                                     "docs/recording-format.md)")
    _add_identify_options(p)
    p.add_argument("--stream", action="store_true",
                   help="equation form read block by block: flat memory for records of any length "
                        "(needs a, v, q of every floor)")
    p.add_argument("--per-run", action="store_true",
                   help="runs without added mass: one modal fit per run, and how mode 1's frequency and "
                        "damping change with the response amplitude across runs (a linear rig shows no trend)")
    p.add_argument("-o", "--output", metavar="DIR",
                   help="also write DIR/report.html (one self-contained page: the answer, tables, figures, "
                        "provenance), DIR/modes.uff and DIR/frf.uff (UFF datasets 55 and 58: the modes and the "
                        "measured table-to-floor transfer functions) and DIR/identification.json (what --json "
                        "prints), beside any other files in DIR; see docs/reports.md")
    _add_force(p)
    p.set_defaults(func=_cmd_identify)

    p = sub.add_parser("import", help="turn a lab's raw exports (CSV per run, Xsens DOT IMU files) into a recording",
                       description="Write DIR (experiment.toml: [structure] as the lab states it, "
                                   "[sensors] format, [[runs]] with their files and optional added_mass) "
                                   "as a recording.  format = \"csv\" (default): one CSV per run with t, "
                                   "zdd, a1..ad, optional q1..qd, v1..vd in SI units; format = "
                                   "\"xsens-dot\": one Xsens DOT export per sensor (table, floors), aligned "
                                   "on their clocks or from the data, shaking axis, sign, gravity and "
                                   "offset found per sensor and reported.  Files may be gzip-compressed.  "
                                   "See docs/recording-format.md and docs/real-data.md.")
    p.add_argument("folder", metavar="DIR", help="folder with experiment.toml and the runs' data files")
    p.add_argument("--refuse-mislabelled", action="store_true",
                   help="refuse the import when physics places a sensor on another floor than listed (or "
                        "finds it mounted reversed), instead of relabelling it with a note (the default)")
    p.add_argument("-o", "--output", metavar="PATH",
                   help="output folder (the recording is PATH/<folder name>.mcap) or a .mcap file "
                        "(default: out/)")
    _add_force(p)
    p.set_defaults(func=_cmd_import)

    p = sub.add_parser("view", help="inspect a recording in the rerun viewer",
                       description="Show a recording in the rerun viewer, ready to read: per run a 3D "
                                   "view of the table and floors moving with the recorded (exaggerated) "
                                   "displacements and every sensor over time, plus the identified vs. "
                                   "analytic parameters, modes and the equation residual. Spawns the "
                                   "viewer (or uses one already listening); --save writes a .rrd instead.")
    p.add_argument("recording", help="MCAP recording written by momentid")
    p.add_argument("--save", metavar="OUT.rrd", help="write a .rrd file (open later with `rerun OUT.rrd`) "
                                                     "instead of opening a viewer; needs no display")
    p.add_argument("--exaggeration", type=float, metavar="X",
                   help="draw displacements X times their size in 3D (default: about a fifth of the "
                        "building height for the largest one, a 1-2-5 number)")
    p.add_argument("--run", metavar="NAME", help="the run whose tab opens first (default: the first run)")
    p.add_argument("--result", metavar="JSON",
                   help="show this result of `momentid identify --json` instead of identifying again")
    p.add_argument("--twin", metavar="DIR",
                   help="a folder of `momentid twin`: beside each run, the twin moving and every floor sensor "
                        "recorded and as the twin reads it (the recording is not identified again)")
    _add_force(p, "--save")
    p.set_defaults(func=_cmd_view)

    p = sub.add_parser("diagnose", help="locate a model/recording mismatch and name the missing physics",
                       description="Compare the linear shear model (identified from the recording and the nominal "
                                   "one stored in it) with the recordings, locate the mismatch, test candidate "
                                   "mechanisms (" + ", ".join(kind.name for kind in mechanisms.library()) + "), "
                                   "add the best one to the MuJoCo model and "
                                   "replay a held-out run before and after. Recordings without added mass (accelerometers "
                                   "only), with stated floor masses and three trials or more: on the rig's MuJoCo twin "
                                   "(the linear twin, and the twin with " + ", ".join(
                                       kind.name for kind in mechanisms.registry.real_rig_kinds()) + " fitted by "
                                   "re-simulation over the training trials, checked on a held-out trial; a trial of "
                                   "another rig state is said, not called physics; DIR/twin.xml and "
                                   "DIR/model_augmented.xml); otherwise the modal model fitted on the other runs is "
                                   "checked on a held-out run against the noise level, and amplitude dependence is "
                                   "tested.")
    p.add_argument("recording", help="MCAP recording (momentid run or momentid import)")
    p.add_argument("-o", "--output", metavar="DIR",
                   help="report folder (default: out/<recording>_diagnosis)")
    _add_force(p)
    p.add_argument("--json", action="store_true", help="print report.json to stdout")
    p.add_argument("--hold-out", metavar="RUN", default=None,
                   help="recordings without added mass: the run to hold out for the before/after check "
                        "(default: on the twin, the last trial of the others' rig state inside their amplitudes; "
                        "else the last run)")
    p.set_defaults(func=_cmd_diagnose)

    p = sub.add_parser("twin", help="the calibrated MuJoCo twin of a rig: MJCF, parameters, replay of every trial",
                       description="Identify the recording (accelerometers only: the modal fit with sensor gains and "
                                   "clock offsets; K and C from the stated floor masses, mass-normalised without), "
                                   "build its MJCF twin on momentid's rig (identified K and C as tendons, each "
                                   "sensor's gain, bias and clock offset as a sensor model), replay every trial "
                                   "through MuJoCo under its recorded table acceleration and write DIR/twin.xml, "
                                   "DIR/twin.json (parameters, per-trial NRMSE) and plots.  Refuses (exit 2) one "
                                   "trial, a trial without table sensor, or an identification the data contradict. "
                                   "See docs/twin.md.")
    p.add_argument("recording", help="MCAP recording (momentid import, or momentid run)")
    p.add_argument("-o", "--output", metavar="DIR", help="the twin's folder (default: out/<recording>_twin); only "
                                                         "the twin's files are written, each whole, the folder's "
                                                         "other files left alone")
    p.add_argument("--runs", metavar="NAMES", help="comma-separated trials to calibrate on (default: all but a trial of "
                                                   "another rig state, with a note); every "
                                                   "trial is replayed, the others with the calibrated runs' mean sensors")
    p.add_argument("--json", action="store_true", help="print twin.json to stdout")
    p.add_argument("--no-plots", action="store_true", help="write twin.xml and twin.json only")
    _add_force(p)
    p.set_defaults(func=_cmd_twin)

    p = sub.add_parser("plan", help="recommend added-mass runs and excitation from the Cramér-Rao bound",
                       description="Evaluate the Cramér-Rao lower bound of the scenario's experiment and of "
                                   "candidate designs (added-mass patterns, 2..N runs, the scenario's excitation "
                                   "or band-limited noise over the modes) with the scenario's sensor noise, and "
                                   "recommend the cheapest design whose every parameter reaches the target "
                                   "relative standard deviation.")
    p.add_argument("scenario", help="scenario TOML file; its [sensors] give the noise")
    p.add_argument("--target", type=positive_float, default=0.01,
                   help="target relative standard deviation of every parameter (default 0.01)")
    p.add_argument("--max-runs", type=positive_int, default=4, help="largest number of runs to consider")
    p.add_argument("--time-limit", type=positive_float, default=PLAN_TIME_LIMIT_S, metavar="SECONDS",
                   help=f"refuse, before it starts, a plan estimated to take longer on this machine (default "
                        f"{PLAN_TIME_LIMIT_S:g} s; the estimate times its first candidate run)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_plan)

    p = sub.add_parser("sweep", help="a campaign: scenario variants x seeds, identified and scored",
                       description="Run every case of a sweep file (a base scenario and a grid of values "
                                   "for dotted scenario keys, e.g. scenario.seed = [0, 1, 2]): simulate, "
                                   "identify and compare each with its analytic model, on every local core "
                                   "or a Dask cluster, and write one row per case (identified parameters, "
                                   "relative errors).")
    p.add_argument("spec", help="sweep TOML file ([sweep] base = scenario file, [grid] key = [values])")
    p.add_argument("-o", "--output", metavar="PATH",
                   help="result table, .csv or .json (default: out/<spec name>.csv)")
    p.add_argument("-j", "--workers", type=positive_int, metavar="N",
                   help="local worker processes (default: one per core)")
    p.add_argument("--address", metavar="ADDR",
                   help="run on the Dask cluster whose scheduler is at ADDR (e.g. tcp://host:8786; needs "
                        "pip install 'momentid[cluster]' here and momentid on the workers)")
    p.add_argument("-q", "--quiet", action="store_true", help="no per-case progress lines")
    _add_force(p)
    p.set_defaults(func=_cmd_sweep)

    return parser


def _add_force(p, option: str = "-o") -> None:
    p.add_argument("--force", action="store_true",
                   help=f"overwrite files at {option} that momentid did not write (and replace a symbolic link "
                        "there, never the file it points to); without it such files are refused")


def main(argv=None) -> int:
    try:
        parser = build_parser()
        args = parser.parse_args(argv)   # --help and usage errors print too
        args.argv = list(sys.argv[1:] if argv is None else argv)    # the exact command (report provenance)
        if args.command is None:
            parser.print_help()
            return 2
        with sigterm_as_interrupt():
            return _run_command(args)
    except BrokenPipeError:
        return quiet_broken_pipe()


def _run_command(args) -> int:
    """Run the chosen command; every expected failure is one ``error:`` line and an exit code."""
    try:
        from momentid.lab.rig import mujoco_warnings_counted_not_printed

        with (only_json_on_stdout(args.json), warnings.catch_warnings(),
              mujoco_warnings_counted_not_printed()):
            warnings.showwarning = _one_line_warning
            warnings.simplefilter("always", RecoveryWarning)  # every recovered file says so, every time
            refuse_empty_paths(args)
            return args.func(args)
    except BrokenPipeError:
        raise   # an OSError, but no error of the command: main() keeps it quiet
    except MomentidError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # disk full, an output folder that cannot exist (/proc/x), permissions
        print(f"error: {_os_error(exc)}", file=sys.stderr)
        return 2
    except Terminated:
        print("error: terminated (SIGTERM)", file=sys.stderr)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
