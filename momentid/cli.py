"""The ``momentid`` command line: a thin layer over the Python API.

Every user mistake ends as one line ``error: ...`` on stderr and exit code 2;
an interrupted run exits 130.  Run ``momentid COMMAND --help`` for details.
"""

from __future__ import annotations

import argparse
import signal
import sys
import warnings
from collections.abc import Sequence
from typing import TextIO

from momentid import cli_commands as commands
from momentid.cli_output import only_json_on_stdout, refuse_empty_paths
from momentid.cli_values import finite_time, positive_float, positive_int
from momentid.core.processes import Terminated, quiet_broken_pipe, sigterm_as_interrupt
from momentid.errors import MomentidError, RecoveryWarning
from momentid.estimation.design import PLAN_TIME_LIMIT_S

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


def _one_line_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                      file: TextIO | None = None, line: str | None = None) -> None:
    """A warning as one line on stderr: ``note:`` for data recovered from a damaged input, else
    ``warning:``; never the source line of the code that warned."""
    kind = "note" if issubclass(category, RecoveryWarning) else "warning"
    print(f"{kind}: {message}", file=sys.stderr)


def _os_error(exc: OSError) -> str:
    """One line for an operating-system failure (disk full, no such folder, permission)."""
    where = exc.filename if exc.filename is not None else "output"
    return f"cannot write or read {where}: {exc.strerror or exc}"


def _add_identify_options(p: argparse.ArgumentParser) -> None:
    """The options ``run`` and ``identify`` share: the estimator, mass form, instants, runs, JSON."""
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
    """The ``momentid`` command's parser: every subcommand with its options.

    Returns
    -------
    argparse.ArgumentParser
        The parser; a parsed command's ``func`` is its function in
        :mod:`momentid.cli_commands`, called with the parsed options.
    """
    parser = argparse.ArgumentParser(
        prog="momentid",
        description="A virtual shake-table laboratory: simulate added-mass runs of a shear building "
                    "on a MuJoCo rig, record them to MCAP, and identify M, C, K and Rayleigh damping "
                    "(Majcher 2025, input-output method with system momentum change).",
        epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    from momentid import __version__

    parser.add_argument("--version", action="version", version=f"momentid {__version__}")
    parser.set_defaults(json=False)   # the commands without --json
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    for add in (_add_run, _add_identify, _add_import, _add_view, _add_diagnose, _add_twin, _add_plan, _add_sweep):
        add(sub)
    return parser


def _add_run(sub: argparse._SubParsersAction) -> None:
    """The ``run`` command's options."""
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
    p.set_defaults(func=commands.command_run)


def _add_identify(sub: argparse._SubParsersAction) -> None:
    """The ``identify`` command's options."""
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
    p.set_defaults(func=commands.command_identify)


def _add_import(sub: argparse._SubParsersAction) -> None:
    """The ``import`` command's options."""
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
    p.set_defaults(func=commands.command_import)


def _add_view(sub: argparse._SubParsersAction) -> None:
    """The ``view`` command's options."""
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
    p.set_defaults(func=commands.command_view)


def _add_diagnose(sub: argparse._SubParsersAction) -> None:
    """The ``diagnose`` command's options (its description names the registry's mechanisms)."""
    from momentid import mechanisms

    library = ", ".join(kind.name for kind in mechanisms.library())
    real_rig = ", ".join(kind.name for kind in mechanisms.registry.real_rig_kinds())
    p = sub.add_parser("diagnose", help="locate a model/recording mismatch and name the missing physics",
                       description="Compare the linear shear model (identified from the recording and the nominal "
                                   "one stored in it) with the recordings, locate the mismatch, test candidate "
                                   f"mechanisms ({library}), add the best one to the MuJoCo model and replay a "
                                   "held-out run before and after. Recordings without added mass (accelerometers "
                                   "only), with stated floor masses and three trials or more: on the rig's MuJoCo "
                                   f"twin (the linear twin, and the twin with {real_rig} fitted by "
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
    p.set_defaults(func=commands.command_diagnose)


def _add_twin(sub: argparse._SubParsersAction) -> None:
    """The ``twin`` command's options."""
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
    p.add_argument("--runs", metavar="NAMES",
                   help="comma-separated trials to calibrate on (default: all but a trial of another rig state, "
                        "with a note); every trial is replayed, the others with the calibrated runs' mean sensors")
    p.add_argument("--json", action="store_true", help="print twin.json to stdout")
    p.add_argument("--no-plots", action="store_true", help="write twin.xml and twin.json only")
    _add_force(p)
    p.set_defaults(func=commands.command_twin)


def _add_plan(sub: argparse._SubParsersAction) -> None:
    """The ``plan`` command's options."""
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
    p.set_defaults(func=commands.command_plan)


def _add_sweep(sub: argparse._SubParsersAction) -> None:
    """The ``sweep`` command's options."""
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
    p.set_defaults(func=commands.command_sweep)


def _add_force(p: argparse.ArgumentParser, option: str = "-o") -> None:
    """The ``--force`` option, for the files at ``option``."""
    p.add_argument("--force", action="store_true",
                   help=f"overwrite files at {option} that momentid did not write (and replace a symbolic link "
                        "there, never the file it points to); without it such files are refused")


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``momentid`` command.

    Parameters
    ----------
    argv
        The command's arguments without the program name (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        The exit code: 0 on success; 1 when ``plan`` finds no design reaching its target; 2 for a
        refused input or no command (argparse exits with 2 itself on a usage error); 130 when
        interrupted, 128 + SIGTERM when terminated, 128 + SIGPIPE when stdout's reader went away.
    """
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
    except Terminated:   # landed after the command's own handlers, before SIGTERM's old handler came back
        print("error: terminated (SIGTERM)", file=sys.stderr)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:   # the same for Ctrl-C: never a traceback
        print("error: interrupted", file=sys.stderr)
        return 130


def _run_command(args: argparse.Namespace) -> int:
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
