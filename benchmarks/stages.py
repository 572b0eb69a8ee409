"""The stages of ``python -m benchmarks`` (:mod:`benchmarks.bench`), each against a raw baseline timed
in the same process: simulate, record, identify, view and run (see that module's docstring)."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path
from unittest import mock

import numpy as np

from benchmarks.common import Row, blas_threads, cpu_seconds, scenario_variant_file, timed
from momentid.errors import MomentidError

__all__ = ["RawRig", "RUN_TARGET_S", "bench_simulate", "bench_record", "stacked_regressor", "bench_identify",
           "bench_view", "bench_run"]

#: Wall-time target of the whole default ``momentid run`` (s).
RUN_TARGET_S = 3.0


# ----------------------------------------------------------------------------- simulate

class RawRig:
    """The compiled models of a scenario's runs, their initial states and
    table control sequences, prepared as :func:`momentid.simulate_run` prepares them."""

    def __init__(self, scenario):
        from momentid.lab import rig
        from momentid.lab.simulation import ground_motion_of, initial_state, table_jerk

        if rig.needs_callback(scenario.truth):
            callbacks = ", ".join(m.type for m in scenario.truth if m.type in rig.CALLBACK_MECHANISMS)
            raise MomentidError(f"{scenario.source}: the simulate benchmark needs a rig without callback "
                                f"physics, got [truth] {callbacks}: expected a linear rig")
        motion = ground_motion_of(scenario)
        self.n_steps = scenario.n_samples * scenario.substeps
        nodes = np.asarray(motion.acceleration(np.arange(self.n_steps + 1) * scenario.timestep), float)
        self.control = table_jerk(nodes, scenario.timestep)[None, :, None]
        self.models, self.states = [], []
        for run in scenario.runs:
            spec = rig.build_spec(scenario.structure, run.added_mass, timestep=scenario.timestep,
                                  name=f"{scenario.name}_{run.name}", mechanisms=scenario.truth)
            m = rig.compile_model(spec)
            self.models.append(m)
            self.states.append(initial_state(m, float(motion.displacement(0.0)),
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
        t = timed(repeat, native=lambda: self.rollout(threads), pooled=lambda: self.rollout(threads, True))
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


def bench_simulate(scenario, *, workers: int, repeat: int) -> list[Row]:
    from momentid.lab.simulation import simulate

    raw = RawRig(scenario)
    steps = raw.n_steps * len(scenario.runs)
    last = {}

    cpu: dict[int, float] = {}

    def ours(w):
        def fn():
            c0 = cpu_seconds()
            last[w] = simulate(scenario, workers=w)
            cpu[w] = min(cpu.get(w, np.inf), cpu_seconds() - c0)
        return fn

    fns = {"momentid": ours(workers), "rollout": lambda: raw.rollout(workers),
           "rollout_pooled": lambda: raw.rollout(workers, True)}
    if workers > 1:
        fns["momentid_1"] = ours(1)
        fns["rollout_1"] = lambda: raw.rollout(1)
    t = {k: min(v) for k, v in timed(repeat, **fns).items()}
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


# ----------------------------------------------------------------------------- replay

#: The forces the ``replay`` stage's callback applies: a storey friction and a cubic storey spring
#: (the library's two ``callback`` kinds a diagnosis re-simulates most).
REPLAY_FORCES = (("coulomb_friction", 1, (("force", 0.3),)), ("cubic_stiffness", 2, (("k3", 3.5e7),)))


def bench_replay(scenario, experiment, *, repeat: int) -> list[Row]:
    """A diagnosis's replay of one run with callback forces against ``mujoco.rollout`` of the same
    compiled model from the same state under the same controls, with no callback installed: what the
    force callback (the kinds' compiled laws, :mod:`momentid.lab.native_forces`) costs over MuJoCo's own
    stepping."""
    import mujoco
    from mujoco import rollout

    from momentid.core.structure import Mechanism
    from momentid.lab import rig
    from momentid.lab.simulation import initial_state, replay, table_jerk

    forces = tuple(Mechanism(*f) for f in REPLAY_FORCES if f[1] <= scenario.structure.storeys)
    run = experiment.runs[0]
    h = 1.0 / run.sample_rate
    model = rig.compile_model(rig.build_spec(scenario.structure, run.added_mass, timestep=h, name="replay",
                                             mechanisms=forces))
    zdd = np.asarray(run["zdd"], float)
    nodes = np.append(zdd, zdd[-1])
    state, jerk = initial_state(model, 0.0, 0.0, nodes[0]), table_jerk(nodes, h)
    data = mujoco.MjData(model)
    t = {k: min(v) for k, v in timed(
        repeat, momentid=lambda: replay(scenario.structure, forces, run),
        rollout=lambda: rollout.rollout(model, data, state[None], jerk[None, :, None])).items()}
    calls = 4 * len(jerk)   # RK4: the callback at each of a step's four stages
    return [Row("replay", t["momentid"], t["rollout"],
                f"replay of run {run.name!r} ({len(jerk)} steps) with {', '.join(f[0] for f in REPLAY_FORCES)}",
                "mujoco.rollout of the same model and controls, no callback",
                note=f"the force callback: {1e6 * (t['momentid'] - t['rollout']) / calls:.2f} us a call "
                     f"({calls} calls), model building and the outputs' copy included",
                extra={"steps": len(jerk), "callback_calls": calls,
                       "us_per_call": 1e6 * (t["momentid"] - t["rollout"]) / calls})]


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
    t = {k: min(v) for k, v in timed(
        repeat,
        write=lambda: write_experiment(ours, experiment), read=lambda: read_recording(ours),
        raw_write=lambda: _raw_write(raw, records), raw_read=lambda: _raw_read(raw),
    ).items()}
    # The writer fsyncs every run twice (crash safety); the raw library does not.  Timed
    # once more with fsync as a no-op to show what the disk's flushes cost.
    with mock.patch("os.fsync"):
        no_sync = min(timed(repeat, x=lambda: write_experiment(ours, experiment))["x"])
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
        t = {k: min(v) for k, v in timed(repeat, **fns).items()}
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
    t = {k: min(v) for k, v in timed(repeat, **fns).items()}
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

def bench_run(workdir: Path, *, repeat: int, duration: float | None = None) -> list[Row]:
    cmd = [sys.executable, "-m", "momentid", "run", "-q", "-o", str(workdir / "out")]
    if duration is not None:
        cmd.insert(4, str(scenario_variant_file(workdir / "default.toml", {"scenario.duration": duration})))
    env = dict(os.environ, PYTHONWARNINGS="ignore")

    def run():
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, env=env)

    def startup():
        subprocess.run([sys.executable, "-c", "import momentid"], check=True, env=env)

    t = {k: min(v) for k, v in timed(repeat, run=run, startup=startup).items()}
    what = "default scenario" + (f" cut to {duration:g} s" if duration is not None else "")
    return [Row("run", t["run"], RUN_TARGET_S, f"`momentid run` wall time, {what}",
                f"target: {RUN_TARGET_S:g} s",
                note=f"of which {t['startup']:.2f} s is starting Python and importing momentid",
                extra={"import_s": t["startup"], "command": cmd[1:]})]
