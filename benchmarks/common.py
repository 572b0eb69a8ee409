"""What every benchmark shares: a row of the report, interleaved timing, the machine, BLAS threads,
the benchmark scenarios, and the diagnosis matrices' scaffolding (the rig they hide physics in, a
timed diagnosis, their command line, cases run a few at a time, results saved as JSON and Markdown)."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import time
import tomllib
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from collections.abc import Callable

import numpy as np

__all__ = ["ROOT", "RESULTS", "HIDDEN_RIG", "Row", "timed", "cpu_seconds", "machine", "blas_threads", "bench_scenario",
           "describe_scenario", "scenario_variant_file", "hidden_rig", "timed_diagnosis",
           "measured_diagnosis", "raw_rollout_seconds", "cost_cells", "cost_summary", "matrix_parser", "run_cases",
           "save"]

#: The repository, and the folder benchmark results are written to.
ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
#: The laboratory rig of ``scenarios/hidden/`` the diagnosis matrices hide their physics in.
HIDDEN_RIG = ROOT / "scenarios" / "hidden" / "clean.toml"


@dataclass
class Row:
    """One line of the report: momentid's time against a baseline's (s)."""

    stage: str
    momentid_s: float | None
    baseline_s: float | None
    momentid: str
    baseline: str
    note: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def ratio(self) -> float | None:
        """momentid / baseline (below 1: momentid is faster)."""
        if self.momentid_s is None or not self.baseline_s:
            return None
        return self.momentid_s / self.baseline_s

    def to_dict(self) -> dict:
        out = asdict(self)
        out["ratio"] = self.ratio
        return out


def timed(repeat: int, **fns: Callable[[], object]) -> dict[str, list[float]]:
    """Run every function ``repeat`` times, interleaved; their times (s)."""
    times: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(repeat):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    return times


def _checkout_scenario(name: str) -> Path | None:
    path = ROOT / "scenarios" / f"{name}.toml"
    return path if path.exists() else None


def bench_scenario(path=None, *, duration: float | None = None, overrides: dict | None = None):
    """A scenario for benchmarking: ``path`` (default: the paper's 7 runs,
    ``scenarios/paper_harmonic.toml`` in a checkout, else the embedded
    default) with its duration and any ``{"table.key": value}`` replaced."""
    from momentid.lab.scenario import default_scenario_path, load_scenario

    path = Path(path) if path is not None else (_checkout_scenario("paper_harmonic")
                                                 or default_scenario_path())
    changes = dict(overrides or {})
    if duration is not None:
        changes["scenario.duration"] = duration
    return load_scenario(path, overrides=changes)


def describe_scenario(scenario) -> dict:
    """The scenario in a report: name, source, runs, duration, rate, storeys."""
    return {"name": scenario.name, "source": scenario.source, "runs": len(scenario.runs),
            "duration_s": scenario.duration, "sample_rate_hz": scenario.sample_rate,
            "storeys": scenario.structure.storeys, "samples_per_run": scenario.n_samples,
            "substeps": scenario.substeps}


def cpu_seconds() -> float:
    """CPU time of this process and its finished children (s)."""
    import resource

    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def machine() -> dict:
    """The machine a report was measured on: cores, versions, load."""
    import mujoco

    from momentid.lab.simulation import available_cores

    return {"cores": available_cores(), "python": platform.python_version(),
            "platform": platform.platform(), "numpy": np.__version__, "mujoco": mujoco.__version__,
            "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None}


@contextlib.contextmanager
def blas_threads(n: int | None):
    """Limit BLAS to ``n`` threads inside the block (when threadpoolctl is
    installed); yields what is in force, for the report."""
    if not n:
        yield "library default"
        return
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        yield "library default (threadpoolctl is not installed)"
        return
    with threadpool_limits(n, user_api="blas"):
        yield str(n)


def _toml_value(value) -> str:
    """One TOML value: a number, string, boolean or array of them."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)   # a JSON string is a TOML basic string
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return repr(value)


def _toml_text(data: dict, prefix: str = "") -> str:
    """Parsed scenario TOML written back as text (tables, arrays of tables, values)."""
    def is_tables(v):
        return isinstance(v, list) and v and all(isinstance(x, dict) for x in v)

    lines = [f"{k} = {_toml_value(v)}" for k, v in data.items() if not isinstance(v, dict) and not is_tables(v)]
    for key, value in data.items():
        if isinstance(value, dict):
            lines += ["", f"[{prefix}{key}]", _toml_text(value, f"{prefix}{key}.")]
        elif is_tables(value):
            for item in value:
                lines += ["", f"[[{prefix}{key}]]", _toml_text(item, f"{prefix}{key}.")]
    return "\n".join(lines)


def scenario_variant_file(out: Path, overrides: dict, base=None) -> Path:
    """Write ``base`` (default: the embedded default scenario) with ``overrides``
    (``{"dotted.key": value}``, :func:`momentid.lab.scenario.set_key`) to the
    TOML file ``out``, for commands that read a scenario file."""
    from momentid.io.toml_reader import load_toml
    from momentid.lab.scenario import default_scenario_path, load_scenario, set_key

    base = Path(base) if base is not None else default_scenario_path()
    data = load_toml(base)
    for key, value in overrides.items():
        set_key(data, key, value)
    out = Path(out)
    out.write_text(_toml_text(data) + "\n", encoding="utf-8")
    load_scenario(out)   # refuse here, naming the file, what the command would refuse later
    return out




def hidden_rig(truth=(), faults=None, noise: float = 0.01, excitation: dict | None = None, seed: int | None = None):
    """:data:`HIDDEN_RIG` with ``truth`` (``[[truth.mechanisms]]`` tables) and per-channel ``faults``
    (``{channel: {field: value}}``), sensor noise ``noise`` (relative RMS, both kinds of sensor), the
    ``excitation`` table (default: the rig's El Centro record) and the scenario ``seed``."""
    from momentid.lab.scenario import parse_scenario

    data = tomllib.loads(HIDDEN_RIG.read_text())
    if excitation is None:
        data["excitation"]["file"] = str((HIDDEN_RIG.parent / data["excitation"]["file"]).resolve())
    else:
        data["excitation"] = dict(excitation)
    data["sensors"]["accelerometer"]["relative_noise"] = noise
    data["sensors"]["displacement"]["relative_noise"] = noise
    if faults:
        data["sensors"]["channel"] = {k: dict(v) for k, v in faults.items()}
    if truth:
        data["truth"] = {"mechanisms": [dict(m) for m in truth]}
    if seed is not None:
        data["scenario"]["seed"] = seed
    return parse_scenario(data, source=HIDDEN_RIG)


def raw_rollout_seconds(experiment, repeat: int = 3, structure=None, cpu: bool = False) -> float:
    """Best of ``repeat`` times (s) of one raw ``mujoco.rollout`` of the experiment's first run through its
    linear rig (``structure``, default the experiment's nominal one; no mechanism, no callback, one
    thread): the unit a diagnosis's time is stated in, measured in the same process right after it.
    ``cpu``: the CPU time of this process instead of the wall time."""
    import mujoco
    from mujoco import rollout

    from momentid.lab import rig
    from momentid.lab.simulation import initial_state, table_jerk

    run = experiment.runs[0]
    h = 1.0 / run.sample_rate
    structure = experiment.structure if structure is None else structure
    model = rig.compile_model(rig.build_spec(structure, run.added_mass, timestep=h, name="raw"))
    nodes = np.append(run["zdd"], run["zdd"][-1])
    state, control = initial_state(model, 0.0, 0.0, nodes[0]), table_jerk(nodes, h)[:, None]
    data, best = mujoco.MjData(model), np.inf
    clock = time.process_time if cpu else time.perf_counter
    for _ in range(repeat):
        start = clock()
        rollout.rollout(model, data, state[None], control[None])
        best = min(best, clock() - start)
    return best


def measured_diagnosis(experiment, structure=None) -> tuple:
    """``diagnose(experiment)`` and what it cost: its wall and CPU seconds (this process and the workers it
    forked), the replays it made (in this process, its threads and its forked workers:
    :func:`momentid.core.counters.counting`), one raw rollout of a run of its rig, wall and CPU
    (:func:`raw_rollout_seconds`, measured right after), and the diagnosis in raw rollouts: ``ratio``
    (wall / wall) and ``cpu_ratio`` (CPU / CPU, the steadier of the two on a loaded machine, where a
    diagnosis waits for the cores).  ``structure``: the linear rig of the raw rollout when the experiment
    states none (an accelerometer-only lab's)."""
    from momentid.core import counters
    from momentid.diagnosis.dispatch import diagnose

    with counters.counting() as replays:
        start, cpu = time.perf_counter(), cpu_seconds()
        d = diagnose(experiment)
        seconds, cpu = time.perf_counter() - start, cpu_seconds() - cpu
        n = replays()
    raw = raw_rollout_seconds(experiment, structure=structure)
    raw_cpu = raw_rollout_seconds(experiment, structure=structure, cpu=True)
    return d, {"seconds": seconds, "cpu_seconds": cpu, "replays": n, "rollout_seconds": raw,
               "rollout_cpu_seconds": raw_cpu, "ratio": seconds / raw, "cpu_ratio": cpu / raw_cpu}


def cost_cells(r: dict) -> str:
    """A row's diagnosis time, that time in raw rollouts of one run, and its replays (table cells)."""
    if "ratio" not in r:
        return f"{r['seconds']:.0f} s | - | -"
    cpu = f" / CPU {r['cpu_ratio']:.0f}x" if "cpu_ratio" in r else ""
    return f"{r['seconds']:.0f} s | {r['ratio']:.0f}x{cpu} | {r['replays']}"


def cost_summary(rows: list[dict]) -> str:
    """Median and max of the rows' diagnosis times, in seconds and raw rollouts, and their replays."""
    def med(key):
        values = sorted(r[key] for r in rows if key in r)
        return values[len(values) // 2] if values else float("nan"), max(values, default=float("nan"))
    (s, s_max), (x, x_max), (c, c_max), (n, n_max) = med("seconds"), med("ratio"), med("cpu_ratio"), med("replays")
    return (f"diagnosis time median {s:.0f} s, max {s_max:.0f} s; in raw rollouts of one run median {x:.0f}x, "
            f"max {x_max:.0f}x (CPU: median {c:.0f}x, max {c_max:.0f}x); replays median {n:.0f}, max {n_max:.0f}; "
            f"load average {os.getloadavg()[0]:.1f} at the end on {os.cpu_count()} cores")


def timed_diagnosis(scenario):
    """The diagnosis of ``scenario``'s simulated recordings and its costs (:func:`measured_diagnosis`),
    the simulation not counted."""
    import momentid as mi

    return measured_diagnosis(mi.simulate(scenario))


def matrix_parser(module: str, doc: str) -> argparse.ArgumentParser:
    """The command line of a diagnosis matrix ``python -m MODULE``: ``--workers`` (cases at once) and
    ``--out`` (the results folder)."""
    p = argparse.ArgumentParser(prog=f"python -m {module}", description=doc,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--workers", type=int, default=2, help="cases diagnosed at once (default 2)")
    p.add_argument("--out", type=Path, default=RESULTS, help="results folder (default: benchmarks/results)")
    return p


def run_cases(jobs, workers: int, case: Callable) -> list[dict]:
    """Run every case of a diagnosis matrix (``case(job) -> row``), ``workers`` at a time, printing each
    row as it comes."""
    with ProcessPoolExecutor(max_workers=workers) as pool:
        rows = []
        for row in pool.map(case, jobs):
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


def save(out: Path, name: str, data, lines: list[str]) -> None:
    """Write ``out/<name>.json`` (``data``) and ``out/<name>.md`` (``lines``), and print the table."""
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{name}.json").write_text(json.dumps(data, indent=1))
    (out / f"{name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
