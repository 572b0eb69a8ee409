"""How fast the modal identification of a real trial is, against SRIM on the same trial, in one run.

    python -m benchmarks.modal_speed [--data DIR] [--repeat 3]

Baseline: the subspace identification SRIM of ``mdof`` (PyPI, the peer the data README quotes), model
order 12, horizon 60, table X acceleration in and the three floors' X accelerations out.  Both sides
read the same trial from the same imported recording (``momentid import`` of the shipped folder, done
once before timing), both with one BLAS thread (the faster setting for both on a shared 2-core
machine); each time is the best of ``--repeat``.  Per synchronised trial: momentid's
``identify_modal`` time, SRIM's, and the ratio momentid / SRIM (below 1: momentid is faster).  Then
``momentid identify --per-run`` over every shipped trial as a subprocess (wall and CPU seconds, the
default 2 worker processes), against SRIM run on the same trials one after the other in this
process.  Writes ``benchmarks/results/modal_speed.json`` and ``.md``.

``mdof`` is a dependency of the benchmarks only (``pip install -e ".[bench]"``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT / "data" / "mini_shake_table" / "flexible_3storey"
RESULTS = ROOT / "benchmarks" / "results"
SYNCHRONISED = ("northridge", "sine_1p0", "sine_1p5", "sine_2p0")
#: SRIM settings of the comparison: order 12 (the issue's), horizon 0.5 s at 120 Hz.
SRIM_ORDER = 12
SRIM_HORIZON = 60


def srim(run, d: int):
    """mdof's SRIM of one run at :data:`SRIM_ORDER`: its modes (dict of frequency and damping)."""
    import mdof
    import mdof.modal

    dt = 1.0 / run.sample_rate
    u = run["zdd"] - np.mean(run["zdd"])
    y = run.group("a", d) - np.mean(run.group("a", d), axis=0)
    realization = mdof.sysid(u[None, :], y.T, dt=dt, order=SRIM_ORDER, horizon=SRIM_HORIZON, threads=1)
    return mdof.modal.system_modes(realization, dt)


def _best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    from threadpoolctl import threadpool_limits

    from momentid.estimation.scaled import identify_modal
    from momentid.io.importer import import_folder, write_import
    from momentid.io.recording import read_recording

    with tempfile.TemporaryDirectory() as tmp:
        recording = write_import(import_folder(args.data), Path(tmp) / "trials.mcap")
        rows = []
        with threadpool_limits(limits=1, user_api="blas"):
            for name in SYNCHRONISED:
                def ours(name=name):
                    experiment = read_recording(recording)
                    return identify_modal(experiment, [name])

                def theirs(name=name):
                    experiment = read_recording(recording)
                    return srim(experiment.run(name), experiment.storeys)

                ours()                                     # warm caches (imports, file system) once each
                theirs()
                t_ours, t_srim = _best(ours, args.repeat), _best(theirs, args.repeat)
                n = read_recording(recording).run(name).n_samples
                rows.append({"trial": name, "samples": n, "momentid_s": t_ours, "srim_s": t_srim,
                             "ratio": t_ours / t_srim})
            experiment = read_recording(recording)
            every = [r.name for r in experiment.runs]
            srim_all = _best(lambda: [srim(experiment.run(n), experiment.storeys) for n in every], 1)
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        cpu0 = _children_cpu()
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "momentid", "identify", str(recording), "--per-run"], env=env,
                       check=True, capture_output=True)
        wall = time.perf_counter() - start
        cpu = _children_cpu() - cpu0
    per_run = {"trials": every, "wall_s": wall, "cpu_s": cpu, "srim_sequential_s": srim_all,
               "ratio_wall_to_srim": wall / srim_all}
    load = os.getloadavg()[0]
    lines = ["| trial | samples | momentid identify (s) | SRIM order 12 (s) | ratio momentid / SRIM |",
             "|---|---|---|---|---|"]
    lines += [f"| {r['trial']} | {r['samples']} | {r['momentid_s']:.3f} | {r['srim_s']:.3f} | {r['ratio']:.2f} |"
              for r in rows]
    lines.append("")
    lines.append(f"`momentid identify --per-run` over {len(every)} trials ({', '.join(every)}): {wall:.2f} s wall, "
                 f"{cpu:.2f} s CPU (2 worker processes, the interpreter's start and imports included); SRIM on "
                 f"the same trials one after the other in this process: {srim_all:.2f} s (ratio "
                 f"{wall / srim_all:.2f})")
    lines.append(f"machine: {os.cpu_count()} cores, load average {load:.2f} at the end, best of {args.repeat}")
    text = "\n".join(lines)
    print(text)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "modal_speed.md").write_text("`python -m benchmarks.modal_speed` (see its docstring)\n\n" + text + "\n")
    (RESULTS / "modal_speed.json").write_text(json.dumps(
        {"machine": {"cores": os.cpu_count(), "python": platform.python_version(), "load_average_1min": load},
         "repeat": args.repeat, "trials": rows, "per_run": per_run}, indent=1))
    return 0 if all(r["ratio"] <= 1.0 for r in rows) and wall <= 10.0 else 1


if __name__ == "__main__":
    sys.exit(main())
