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
import contextlib
import importlib.util
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable
from unittest import mock

import numpy as np

from momentid.errors import MomentidError

__all__ = ["Row", "STAGES", "RUN_TARGET_S", "bench_scenario", "scenario_variant_file", "run_benchmarks", "stacked_regressor",
           "add_arguments", "main"]

STAGES = ("simulate", "record", "identify", "view", "run")
#: Wall-time target of the whole default ``momentid run`` (s).
RUN_TARGET_S = 3.0
#: Record length of ``--quick`` (s): a CI-sized smoke run of every stage.
QUICK_DURATION = 0.5


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


def _timed(repeat: int, **fns: Callable[[], object]) -> dict[str, list[float]]:
    """Run every function ``repeat`` times, interleaved; their times (s)."""
    times: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(repeat):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    return times


# ----------------------------------------------------------------------------- scenarios

def _checkout_scenario(name: str) -> Path | None:
    path = Path(__file__).resolve().parents[1] / "scenarios" / f"{name}.toml"
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


def _describe(scenario) -> dict:
    return {"name": scenario.name, "source": scenario.source, "runs": len(scenario.runs),
            "duration_s": scenario.duration, "sample_rate_hz": scenario.sample_rate,
            "storeys": scenario.structure.storeys, "samples_per_run": scenario.n_samples,
            "substeps": scenario.substeps}


# ----------------------------------------------------------------------------- simulate

class _RawRig:
    """The compiled models of a scenario's runs, their initial states and
    table control sequences, prepared as :func:`momentid.simulate_run` prepares them."""

    def __init__(self, scenario):
        from momentid.lab import rig
        from momentid.lab.simulation import _initial_state, _jerk, ground_motion_of

        if rig.needs_callback(scenario.truth):
            raise MomentidError(f"{scenario.source}: the simulate benchmark needs a rig without callback "
                                f"physics, got [truth] {', '.join(m.type for m in scenario.truth if m.type in rig.CALLBACK_MECHANISMS)}: "
                                f"expected a linear rig")
        motion = ground_motion_of(scenario)
        self.n_steps = scenario.n_samples * scenario.substeps
        nodes = np.asarray(motion.acceleration(np.arange(self.n_steps + 1) * scenario.timestep), float)
        self.control = _jerk(nodes, scenario.timestep)[None, :, None]
        self.models, self.states = [], []
        for run in scenario.runs:
            spec = rig.build_spec(scenario.structure, run.added_mass, timestep=scenario.timestep,
                                  name=f"{scenario.name}_{run.name}", mechanisms=scenario.truth)
            m = rig.compile_model(spec)
            self.models.append(m)
            self.states.append(_initial_state(m, float(motion.displacement(0.0)),
                                              float(motion.velocity(0.0)), nodes[0]))
        # rollout takes several models at once only when their sizes agree
        # (the reference run has no added-mass bodies).
        groups: dict[tuple, list[int]] = {}
        for i, m in enumerate(self.models):
            groups.setdefault((m.nq, m.nv, m.nu, m.na, m.nbody, m.nsensordata), []).append(i)
        self.groups = list(groups.values())

    def rollout(self, threads: int, pooled: bool = False):
        """``mujoco.rollout`` of every model on ``threads`` threads; sensordata per run, (n_steps, nsensordata).

        ``pooled=False``: one ``rollout`` call per group of same-sized models, on
        its own thread pool.  ``pooled=True``: one single-threaded ``rollout``
        call per model, spread over a pool of ``threads`` Python threads (the
        calls release the GIL).  The benchmark keeps the faster of the two.
        """
        import mujoco
        from mujoco import rollout

        out = [None] * len(self.models)
        if pooled:
            from concurrent.futures import ThreadPoolExecutor

            def one(i):
                m = self.models[i]
                return rollout.rollout(m, mujoco.MjData(m), self.states[i][None], self.control)[1][0]

            with ThreadPoolExecutor(max_workers=threads) as pool:
                return list(pool.map(one, range(len(self.models))))
        for group in self.groups:
            models = [self.models[i] for i in group]
            datas = [mujoco.MjData(models[0]) for _ in range(min(threads, len(group)))]
            _, sensors = rollout.rollout(models, datas, np.stack([self.states[i] for i in group]),
                                         self.control)
            for k, i in enumerate(group):
                out[i] = sensors[k]
        return out

    def best_rollout(self, threads: int, repeat: int) -> float:
        """Best time (s) of the two raw strategies of :meth:`rollout`."""
        t = _timed(repeat, native=lambda: self.rollout(threads), pooled=lambda: self.rollout(threads, True))
        return min(min(v) for v in t.values())


def _same_computation(scenario, rig_, experiment) -> float | None:
    """Largest |raw rollout - momentid| over every sample of every run,
    relative to the channel's peak: 0 means the baseline computed the same
    numbers (ideal sensors)."""
    from momentid.lab import rig

    worst = 0.0
    for model, sensors, run in zip(rig_.models, rig_.rollout(1), experiment.runs):
        layout = rig.sensor_layout(model)
        sensors = sensors[::scenario.substeps]
        for c, name in enumerate(run.channels):
            if name not in layout or run.values.shape[0] != sensors.shape[0]:
                return None
            col = run.values[:, c]
            peak = float(np.max(np.abs(col))) or 1.0
            worst = max(worst, float(np.max(np.abs(sensors[:, layout[name]] - col))) / peak)
    return worst


def _cpu_seconds() -> float:
    """CPU time of this process and its finished children (s)."""
    import resource

    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def bench_simulate(scenario, *, workers: int, repeat: int) -> list[Row]:
    from momentid.lab.simulation import simulate

    raw = _RawRig(scenario)
    steps = raw.n_steps * len(scenario.runs)
    last = {}

    cpu: dict[int, float] = {}

    def ours(w):
        def fn():
            c0 = _cpu_seconds()
            last[w] = simulate(scenario, workers=w)
            cpu[w] = min(cpu.get(w, np.inf), _cpu_seconds() - c0)
        return fn

    fns = {"momentid": ours(workers), "rollout": lambda: raw.rollout(workers),
           "rollout_pooled": lambda: raw.rollout(workers, True)}
    if workers > 1:
        fns["momentid_1"] = ours(1)
        fns["rollout_1"] = lambda: raw.rollout(1)
    t = {k: min(v) for k, v in _timed(repeat, **fns).items()}
    extra = {"steps": steps, "workers": workers,
             "steps_per_s": steps / t["momentid"],
             "rollout_grouped_s": t["rollout"], "rollout_thread_per_model_s": t["rollout_pooled"],
             "rollout_1_thread_s": t.get("rollout_1", t["rollout"]),
             "max_rel_diff_vs_rollout": _same_computation(scenario, raw, last[workers])}
    what = f"simulate(workers={workers}), {len(scenario.runs)} runs"
    rows = [
        Row("simulate", t["momentid"], min(t["rollout"], t["rollout_pooled"]), what,
            f"mujoco.rollout, same models, states and controls, {workers} thread(s) (best of 2 ways)",
            note="the same computation: the table drive is inside the model (no Python in the step)",
            extra=extra),
    ]
    if workers > 1:
        rows.append(Row("simulate:1core", t["momentid_1"], t["rollout_1"],
                        "simulate(workers=1)", "mujoco.rollout, same models, 1 thread",
                        note=f"per-core overhead; parallel speed-up {t['momentid_1'] / t['momentid']:.2f}x "
                             f"on {workers} workers, CPU time {cpu[workers]:.2f} s vs {cpu[1]:.2f} s serial",
                        extra={"parallel_speedup": t["momentid_1"] / t["momentid"],
                               "cpu_s_parallel": cpu[workers], "cpu_s_serial": cpu[1],
                               "cpu_per_wall_parallel": cpu[workers] / t["momentid"]}))
    return rows


# ----------------------------------------------------------------------------- record

def _mcap_records(path: Path) -> list:
    """Every schema, channel, message, attachment and metadata record of ``path``, in order."""
    from mcap.records import Attachment, Channel, DataEnd, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader

    keep = (Schema, Channel, Message, Attachment, Metadata)
    out = []
    with open(path, "rb") as f:
        for record in StreamReader(f).records:
            if isinstance(record, DataEnd):
                break
            if isinstance(record, keep):
                out.append(record)
    return out


def _raw_write(path: Path, records: list) -> None:
    """The mcap library writing ``records`` as they are (one chunk per run flush is momentid's)."""
    from mcap.records import Attachment, Channel, Message, Metadata, Schema
    from mcap.writer import CompressionType, Writer

    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.NONE, enable_data_crcs=True)
        w.start(profile="", library="raw")
        schemas, channels = {}, {}
        for r in records:
            if isinstance(r, Schema):
                schemas[r.id] = w.register_schema(r.name, r.encoding, r.data)
            elif isinstance(r, Channel):
                channels[r.id] = w.register_channel(r.topic, r.message_encoding,
                                                    schemas[r.schema_id], r.metadata)
            elif isinstance(r, Message):
                w.add_message(channels[r.channel_id], r.log_time, r.data, r.publish_time,
                              sequence=r.sequence)
            elif isinstance(r, Attachment):
                w.add_attachment(r.create_time, r.log_time, r.name, r.media_type, r.data)
            elif isinstance(r, Metadata):
                w.add_metadata(r.name, r.metadata)
        w.finish()


def _raw_read(path: Path) -> int:
    """Read every message back with CRC checks (as momentid's reader does); bytes read."""
    from mcap.records import Message
    from mcap.stream_reader import StreamReader

    total = 0
    with open(path, "rb") as f:
        for record in StreamReader(f, validate_crcs=True).records:
            if isinstance(record, Message):
                total += len(record.data)
    return total


def bench_record(experiment, workdir: Path, *, repeat: int) -> list[Row]:
    from momentid.io.recording import read_recording, write_experiment

    ours, raw = workdir / "momentid.mcap", workdir / "raw.mcap"
    write_experiment(ours, experiment)
    records = _mcap_records(ours)
    t = {k: min(v) for k, v in _timed(
        repeat,
        write=lambda: write_experiment(ours, experiment), read=lambda: read_recording(ours),
        raw_write=lambda: _raw_write(raw, records), raw_read=lambda: _raw_read(raw),
    ).items()}
    # The writer fsyncs every run twice (crash safety); the raw library does not.  Timed
    # once more with fsync as a no-op to show what the disk's flushes cost.
    with mock.patch("os.fsync"):
        no_sync = min(_timed(repeat, x=lambda: write_experiment(ours, experiment))["x"])
    samples = sum(r.n_samples for r in experiment.runs)
    ours_s, raw_s = t["write"] + t["read"], t["raw_write"] + t["raw_read"]
    return [Row(
        "record", ours_s, raw_s, "write_experiment + read_recording (fsync per run, decode to arrays)",
        "mcap Writer + StreamReader(validate_crcs) of the same records, no decoding, no fsync",
        note=f"{samples / ours_s / 1e6:.2f} M samples/s write+read, "
             f"{samples / (no_sync + t['read']) / 1e6:.2f} M without fsync "
             f"({len(experiment.runs[0].channels)} channels per sample)",
        extra={"samples": samples, "samples_per_s": samples / ours_s,
               "samples_per_s_without_fsync": samples / (no_sync + t["read"]),
               "bytes": ours.stat().st_size, "write_s": t["write"], "write_without_fsync_s": no_sync,
               "read_s": t["read"], "raw_write_s": t["raw_write"], "raw_read_s": t["raw_read"],
               "workdir": str(workdir)},
    )]


# ----------------------------------------------------------------------------- identify

def stacked_regressor(experiment):
    """The eq. (3) least-squares problem of every sample of every run as one dense matrix.

    Unknowns ``theta = [diag M (d), C upper triangle (d(d+1)/2), K upper
    triangle, mu]``; rows ``M_jj a_j + sum_k C_jk v_k + sum_k K_jk q_k +
    mu dm_j v_j = -dm_j a_j`` for every floor ``j`` of every sample.

    Returns
    -------
    A : ndarray, shape (samples * d, (d + 1)**2)
    b : ndarray, shape (samples * d,)
    unpack : callable
        ``theta -> (M, C, K, mu)``.
    """
    d = experiment.storeys
    iu = np.triu_indices(d)
    nsym = iu[0].size
    sym = np.empty((d, d), dtype=int)
    sym[iu] = sym[iu[::-1]] = np.arange(nsym)
    p = d + 2 * nsym + 1
    blocks, rhs = [], []
    for run in experiment.runs:
        a, v, q = (run.group(g, d) for g in ("a", "v", "q"))
        dm = np.asarray(run.added_mass, float)
        rows = np.zeros((a.shape[0], d, p))
        rows[:, np.arange(d), np.arange(d)] = a
        for j in range(d):
            rows[:, j, d + sym[j]] = v
            rows[:, j, d + nsym + sym[j]] = q
        rows[:, :, p - 1] = v * dm
        blocks.append(rows.reshape(-1, p))
        rhs.append((-a * dm).reshape(-1))

    def unpack(theta):
        C, K = theta[d + sym], theta[d + nsym + sym]
        return np.diag(theta[:d]), C, K, float(theta[p - 1])

    return np.vstack(blocks), np.concatenate(rhs), unpack


def _max_rel_diff(result, theta_parts) -> float:
    M, C, K, mu = theta_parts
    return max(float(np.max(np.abs(x - y)) / (np.max(np.abs(y)) or 1.0))
               for x, y in ((result.M, M), (result.C, C), (result.K, K), (result.mu, mu)))


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


def bench_identify(experiment, *, repeat: int, max_matrix_bytes: float = 2e9,
                   threads: int | None = 1) -> list[Row]:
    from momentid.estimation.identification import identify

    d = experiment.storeys
    samples = sum(r.n_samples for r in experiment.runs)
    p = (d + 1) ** 2
    last = {}

    def ours():
        last["result"] = identify(experiment)

    fns = {"momentid": ours}
    A = None
    if samples * d * p * 8 <= max_matrix_bytes:
        A, b, unpack = stacked_regressor(experiment)
        fns["lstsq"] = lambda: last.__setitem__("theta", np.linalg.lstsq(A, b, rcond=None)[0])
    with blas_threads(threads) as in_force:
        t = {k: min(v) for k, v in _timed(repeat, **fns).items()}
    extra = {"samples": samples, "samples_per_s": samples / t["momentid"], "storeys": d,
             "unknowns": p, "equations": samples * d, "blas_threads": in_force}
    if A is None:
        note = f"dense matrix {samples * d}x{p} would take {samples * d * p * 8 / 1e9:.1f} GB: not built"
    else:
        extra["matrix_shape"] = list(A.shape)
        extra["max_rel_diff_vs_lstsq"] = _max_rel_diff(last["result"], unpack(last["theta"]))
        note = (f"{samples / t['momentid'] / 1e6:.2f} M samples/s; same M, C, K, mu as lstsq to "
                f"{extra['max_rel_diff_vs_lstsq']:.1e}; BLAS threads: {in_force}")
    return [Row("identify", t["momentid"], t.get("lstsq"), "identify(experiment)",
                f"one dense numpy.linalg.lstsq of the stacked {samples * d}x{p} eq. (3) matrix",
                note=note, extra=extra)]


# ----------------------------------------------------------------------------- view

def _raw_rrd(experiment, path: Path) -> None:
    import rerun as rr

    rec = rr.RecordingStream("momentid_bench")
    rec.save(str(path))
    for run in experiment.runs:
        index = [rr.TimeColumn("t", duration=run.time)]
        for c, name in enumerate(run.channels):
            rec.send_columns(f"runs/{run.name}/{name}", indexes=index,
                             columns=rr.Scalars.columns(scalars=run.values[:, c]))
    rec.flush()
    rec.disconnect()


def _visualize_writer():
    """The ``.rrd`` writer of ``momentid.report.viewer``, if that module exists."""
    if importlib.util.find_spec("momentid.report.viewer") is None:
        return None
    import momentid.report.viewer as vis

    for name in ("write_rrd", "save_rrd", "to_rrd", "experiment_to_rrd"):
        if callable(getattr(vis, name, None)):
            return getattr(vis, name)
    return None


def bench_view(experiment, workdir: Path, *, repeat: int) -> list[Row]:
    if importlib.util.find_spec("rerun") is None:
        return [Row("view", None, None, "-", "-", note="rerun-sdk is not installed")]
    writer, failure = _visualize_writer(), None
    fns = {"raw": lambda: _raw_rrd(experiment, workdir / "raw.rrd")}
    if writer is not None:
        import momentid.report.viewer as vis

        # Identification and scene preparation happen once, outside the timing: this stage is
        # the .rrd writing (the identify stage times the identification).
        try:
            scene = vis.prepare(experiment) if hasattr(vis, "prepare") else experiment
            writer(scene, workdir / "momentid.rrd")
        except MomentidError as e:   # e.g. a record too short to identify: time the raw side only
            writer, failure = None, f"{type(e).__name__}: {e}"
        else:
            fns["momentid"] = lambda: writer(scene, workdir / "momentid.rrd")
    t = {k: min(v) for k, v in _timed(repeat, **fns).items()}
    values = sum(r.values.size for r in experiment.runs)
    if writer is not None:
        note = (f"momentid's file also holds the animated rig, equation residuals and a blueprint; "
                f"raw: {values / t['raw'] / 1e6:.1f} M scalars/s")
    elif failure:
        note = f"momentid.report.viewer failed ({failure}): only the raw baseline is timed"
    else:
        note = "momentid.report.viewer has no .rrd writer yet: only the raw baseline is timed"
    return [Row("view", t.get("momentid"), t["raw"],
                f"momentid.report.viewer.{writer.__name__}" if writer is not None else "n/a",
                "rr.send_columns of every channel of every run into an .rrd file",
                note=note, extra={"scalars": values})]


# ----------------------------------------------------------------------------- run

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


def bench_run(workdir: Path, *, repeat: int, duration: float | None = None) -> list[Row]:
    cmd = [sys.executable, "-m", "momentid", "run", "-q", "-o", str(workdir / "out")]
    if duration is not None:
        cmd.insert(4, str(scenario_variant_file(workdir / "default.toml", {"scenario.duration": duration})))
    env = dict(os.environ, PYTHONWARNINGS="ignore")

    def run():
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, env=env)

    def startup():
        subprocess.run([sys.executable, "-c", "import momentid"], check=True, env=env)

    t = {k: min(v) for k, v in _timed(repeat, run=run, startup=startup).items()}
    what = "default scenario" + (f" cut to {duration:g} s" if duration is not None else "")
    return [Row("run", t["run"], RUN_TARGET_S, f"`momentid run` wall time, {what}",
                f"target: {RUN_TARGET_S:g} s",
                note=f"of which {t['startup']:.2f} s is starting Python and importing momentid",
                extra={"import_s": t["startup"], "command": cmd[1:]})]


# ----------------------------------------------------------------------------- runner

def _machine() -> dict:
    import mujoco

    from momentid.lab.simulation import available_cores

    return {"cores": available_cores(), "python": platform.python_version(),
            "platform": platform.platform(), "numpy": np.__version__, "mujoco": mujoco.__version__,
            "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None}


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
    report = {"machine": _machine(), "settings": {"quick": quick, "repeat": repeat, "workers": workers,
                                                  "blas_threads": blas, "stages": list(stages)},
              "rows": []}
    with tempfile.TemporaryDirectory(prefix="momentid-bench-", dir=workdir) as tmp:
        tmp = Path(tmp)
        rows: list[Row] = []
        needs_data = [s for s in stages if s in ("simulate", "record", "identify", "view")]
        if needs_data:
            sc = bench_scenario(scenario, duration=duration)
            report["scenario"] = _describe(sc)
            experiment = simulate(sc, workers=workers)
        for stage in stages:
            say(f"  {stage} ...")
            if stage == "simulate":
                rows += bench_simulate(sc, workers=workers, repeat=repeat)
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
