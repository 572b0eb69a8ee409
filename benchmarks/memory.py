"""Memory of identification vs. record length: in-memory vs. streamed over recording blocks.

    python -m benchmarks.memory [--lengths 60 300 900 3600]

Recordings of the default structure (2 runs, band-limited table noise, 1 kHz, every channel) are
synthesised with the exact linear model (:mod:`momentid.estimation.linear`; MuJoCo would take minutes per hour of
record and give the same numbers) and written with the normal recorder.  Then each is identified twice,
measuring the peak of Python/numpy allocations with ``tracemalloc``:

* ``identify(read_recording(path))``: the whole recording in memory;
* ``identify_stream(path)``: blocks folded into per-run QR factors as they are read.

Writes ``benchmarks/results/memory.json`` and ``docs/images/memory.png``.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

import momentid as mi
from momentid.core.series import RunData
from momentid.estimation import equation_form as identify_module
from momentid.estimation.linear import discretize, outputs, simulate_linear
from momentid.lab.scenario import BandLimitedNoise

ROOT = Path(__file__).resolve().parents[1]


def synthesize(path: Path, seconds: float) -> int:
    sc = mi.load_scenario(mi.default_scenario_path())
    s = sc.structure
    fs = 1000.0
    n = int(seconds * fs) + 1
    t = np.arange(n) / fs
    motion = mi.ground_motion(BandLimitedNoise(rms=0.5, band=(0.3, 8.0), seed=1), seconds)
    zdd = motion.acceleration(t)
    with mi.RecordingWriter(path, structure=s, scenario=sc.summary()) as w:
        for name, dm in (("reference", np.zeros(3)), ("loaded", np.array([0.5, 0.5, 1.0]))):
            m = discretize(s.mass_matrix() + np.diag(dm), s.damping_matrix(dm), s.stiffness_matrix(), 1 / fs)
            y = outputs(m, simulate_linear(m, zdd))
            channels = ("zdd", "a1", "a2", "a3", "q1", "q2", "q3", "v1", "v2", "v3")
            values = np.column_stack([zdd, y["a"], y["q"], y["v"]])
            w.write_run(RunData(name, dm, t, channels, values))
            del values, y
    return n


def measure(fn):
    tracemalloc.start()
    start = time.perf_counter()
    result = fn()
    elapsed = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return result, peak / 1e6, elapsed


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.memory", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--lengths", type=float, nargs="+", default=[60, 300, 900, 3600], help="seconds per run")
    args = p.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seconds in args.lengths:
            path = Path(tmp) / f"rec_{int(seconds)}.mcap"
            n = synthesize(path, seconds)
            full, mem_full, t_full = measure(lambda: mi.identify(mi.read_recording(path), estimator="equation"))
            stream, mem_stream, t_stream = measure(lambda: identify_module.identify_stream(path))
            agree = float(np.max(np.abs(full.theta - stream.theta)) / np.max(np.abs(full.theta)))
            row = {"seconds": seconds, "samples_per_run": n, "file_mb": path.stat().st_size / 1e6,
                   "in_memory_peak_mb": mem_full, "streamed_peak_mb": mem_stream,
                   "in_memory_s": t_full, "streamed_s": t_stream, "relative_difference": agree}
            rows.append(row)
            print(json.dumps(row), flush=True)
            path.unlink()
    out = ROOT / "benchmarks" / "results"
    out.mkdir(parents=True, exist_ok=True)
    (out / "memory.json").write_text(json.dumps(rows, indent=1))
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.5, 4))
    x = [r["seconds"] / 60 for r in rows]
    ax.loglog(x, [r["in_memory_peak_mb"] for r in rows], "o-", label="identify(read_recording(...))")
    ax.loglog(x, [r["streamed_peak_mb"] for r in rows], "s-", label="identify_stream(...)")
    ax.loglog(x, [r["file_mb"] for r in rows], "k:", label="recording size")
    ax.set(xlabel="record length per run (min), 2 runs, 1 kHz, 10 channels", ylabel="peak memory (MB)",
           title="Identification memory vs. record length")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "images" / "memory.png", dpi=110)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
