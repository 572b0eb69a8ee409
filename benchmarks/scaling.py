"""Scaling figures: stage times vs. record length, number of storeys and number of runs.

    python -m benchmarks.scaling                 # docs/images/scaling_*.png + benchmarks/results/scaling.json
    python -m benchmarks.scaling --quick         # small sizes, a smoke test (CI-sized)

For every size it times, best of ``--repeat``: ``simulate`` (all runs,
one worker per core), raw ``mujoco.rollout`` of the same models, states and
controls on as many threads (the faster of two ways), ``record`` (MCAP write + read back),
``identify`` and one dense ``numpy.linalg.lstsq`` of the stacked regressor
(when that matrix fits in ``--max-dense-gb``).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import bench_scenario, blas_threads, machine
from benchmarks.stages import RawRig, stacked_regressor
from momentid.errors import IdentificationError
from momentid.estimation.identification import identify
from momentid.io.recording import read_recording, write_experiment
from momentid.lab.scenario import default_scenario_path
from momentid.lab.simulation import available_cores, simulate

ROOT = Path(__file__).resolve().parents[1]
SERIES = ("simulate", "rollout_floor", "record", "identify", "lstsq")
LABELS = {"simulate": "simulate (momentid)", "rollout_floor": "raw mujoco.rollout, same models",
          "record": "record (MCAP write + read)", "identify": "identify (momentid)",
          "lstsq": "one dense lstsq (baseline)"}

COLORS = {"simulate": "tab:blue", "rollout_floor": "tab:orange", "record": "tab:green",
          "identify": "tab:red", "lstsq": "tab:purple"}


def _best(repeat: int, fn):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def measure(scenario, *, workers: int, repeat: int, workdir: Path, max_dense_bytes: float,
            blas: int | None = 1) -> dict:
    """Time every stage on ``scenario``; seconds per stage (None where not run)."""
    t_sim, experiment = _best(repeat, lambda: simulate(scenario, workers=workers))
    rig = RawRig(scenario)
    t_floor = rig.best_rollout(workers, repeat)
    path = workdir / "scaling.mcap"
    t_rec, _ = _best(repeat, lambda: (write_experiment(path, experiment), read_recording(path)))
    row = {"storeys": scenario.structure.storeys, "runs": len(scenario.runs),
           "duration_s": scenario.duration, "samples": scenario.n_samples * len(scenario.runs),
           "unknowns": (scenario.structure.storeys + 1) ** 2, "simulate": t_sim,
           "rollout_floor": t_floor, "record": t_rec, "identify": None, "lstsq": None, "note": ""}
    try:
        with blas_threads(blas):
            row["identify"], result = _best(repeat, lambda: identify(experiment))
        row["condition"] = float(result.condition)
    except IdentificationError as e:   # timed all the same: it fails only after the solve
        t0 = time.perf_counter()
        try:
            identify(experiment)
        except IdentificationError:
            pass
        row["identify"] = time.perf_counter() - t0
        row["note"] = f"refused: {e}"
    rows_A = row["samples"] * row["storeys"]
    if rows_A * row["unknowns"] * 8 <= max_dense_bytes:
        A, b, _ = stacked_regressor(experiment)
        with blas_threads(blas):
            row["lstsq"], _ = _best(repeat, lambda: np.linalg.lstsq(A, b, rcond=None))
        del A, b
    else:
        row["note"] += f" dense matrix {rows_A}x{row['unknowns']} not built"
    return row


def storey_scenario(d: int, duration: float):
    """A uniform ``d``-storey frame under band-limited noise, reference + one loaded run."""
    overrides = {
        "scenario.name": f"storeys_{d}", "scenario.duration": duration, "scenario.seed": 1,
        "structure.masses": [50.0] * d, "structure.storey_stiffness": 2.0e5,
        "structure.storey_height": 0.3,
        "structure.damping": {"damping_ratios": [0.02, 0.03], "modes": [1, min(2, d)]} if d > 1
        else {"rayleigh_mu": 0.1, "rayleigh_kappa": 0.001},
        "excitation": {"type": "noise", "rms": 0.5, "band": [0.2, 25.0], "taper": min(1.0, duration / 4)},
        "runs": [{"name": "reference", "added_mass": 0.0},
                 {"name": "loaded", "added_mass": [2.0 if i % 2 == 0 else 1.0 for i in range(d)]}],
    }
    return bench_scenario(default_scenario_path(), overrides=overrides)


def runs_scenario(n: int, duration: float):
    """The default scenario with ``n`` runs: the reference and ``n - 1`` added-mass patterns."""
    runs = [{"name": "reference", "added_mass": 0.0}]
    for k in range(1, n):
        runs.append({"name": f"added{k}", "added_mass": [0.1 * k, 0.05 * (k % 3), 0.1 * ((k + 1) % 2)]})
    return bench_scenario(default_scenario_path(), duration=duration, overrides={"runs": runs})


def _fit_slope(x, y) -> float:
    x, y = np.log(np.asarray(x, float)), np.log(np.asarray(y, float))
    return float(np.polyfit(x, y, 1)[0])


def _fit_line(x, y) -> tuple[float, float, float]:
    """Least-squares ``y = a + b x``: (a, b, R^2)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    b, a = np.polyfit(x, y, 1)
    ss = float(np.sum((y - y.mean()) ** 2)) or 1.0
    return float(a), float(b), 1.0 - float(np.sum((y - a - b * x) ** 2)) / ss


def plot(rows: list[dict], x_key: str, xlabel: str, title: str, path: Path, *, per_sample=False,
         loglog=True, unit="unit", guides=()) -> dict:
    """Plot every series against ``x_key``: log-log with fitted slopes, or
    linear axes with straight-line fits ``t = a + b x`` and their R^2."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    fits = {}
    xs_all = [r[x_key] for r in rows]
    for name in SERIES:
        pts = [(r[x_key], r[name] / (r["samples"] if per_sample else 1)) for r in rows if r.get(name)]
        if len(pts) < 2:
            continue
        x, y = zip(*pts)
        style = "--" if name in ("rollout_floor", "lstsq") else "-"
        if loglog:
            fits[name] = {"slope": _fit_slope(x, y)}
            label = f"{LABELS[name]}  (slope {fits[name]['slope']:.2f})"
            ax.plot(x, y, style, marker="o", color=COLORS[name], label=label)
        else:
            a, b, r2 = _fit_line(x, y)
            fits[name] = {"intercept": a, "per_unit": b, "r2": r2}
            ax.plot(x, y, "o", color=COLORS[name],
                    label=f"{LABELS[name]}  ({b * 1e3:.3g} ms per {unit} + {a * 1e3:.3g} ms, R\u00b2 {r2:.3f})")
            xx = np.array([0.0, max(x)])
            ax.plot(xx, a + b * xx, style, color=COLORS[name], linewidth=1)
    for r in rows:
        if r["note"].startswith("refused") and r.get("identify"):
            y = r["identify"] / (r["samples"] if per_sample else 1)
            ax.plot([r[x_key]], [y], "x", color="black", markersize=9)
            ax.annotate("identify refused:\ncondition > 1e10", (r[x_key], y), fontsize=7,
                        textcoords="offset points", xytext=(-70, -22))
    for power, label in guides:
        x0, x1 = min(xs_all), max(xs_all)
        ref = [r for r in rows if r.get("identify")]
        y0 = ref[0]["identify"] / (ref[0]["samples"] if per_sample else 1)
        ax.plot([x0, x1], [y0, y0 * (x1 / x0) ** power], ":", color="grey", label=label)
    if loglog:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xticks(xs_all)
        ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    else:
        ax.set_xlim(left=0)
        ax.set_ylim(bottom=0)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("seconds per sample" if per_sample else "seconds (best of repeats)")
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return fits


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.scaling", description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="small sizes (a smoke test)")
    p.add_argument("--repeat", type=int, default=None, help="repetitions, best kept (default 3; quick 1)")
    p.add_argument("--workers", type=int, default=None, help="simulation workers (default: one per core)")
    p.add_argument("--images", default=str(ROOT / "docs" / "images"), help="folder of the PNG figures")
    p.add_argument("--json-out", default=str(ROOT / "benchmarks" / "results" / "scaling.json"))
    p.add_argument("--blas-threads", type=int, default=1,
                   help="BLAS threads for identify and lstsq (default 1; 0 = library default)")
    p.add_argument("--max-dense-gb", type=float, default=1.0,
                   help="largest dense regressor matrix the lstsq baseline builds (GB)")
    args = p.parse_args(argv)
    repeat = args.repeat or (1 if args.quick else 3)
    workers = args.workers or available_cores()
    if args.quick:
        lengths, storeys, runs = [0.5, 1.0, 2.0], [1, 3, 5], [2, 3, 4]
        storey_len, runs_len = 0.5, 0.5
    else:
        lengths, storeys, runs = [1, 2, 5, 10, 20, 40], [1, 2, 3, 5, 10, 20, 30, 50], [2, 3, 5, 7, 10, 14, 20]
        storey_len, runs_len = 4.0, 2.0
    images = Path(args.images)
    kw = dict(workers=workers, repeat=repeat, max_dense_bytes=args.max_dense_gb * 1e9, blas=args.blas_threads)
    out = {"machine": machine(), "workers": workers, "repeat": repeat, "quick": args.quick,
           "blas_threads": args.blas_threads}

    def run(label, scenarios):
        rows = []
        for sc in scenarios:
            print(f"{label}: {sc.structure.storeys} storeys, {len(sc.runs)} runs, {sc.duration:g} s ...",
                  file=sys.stderr, flush=True)
            with tempfile.TemporaryDirectory(prefix="momentid-scaling-") as tmp:
                rows.append(measure(sc, workdir=Path(tmp), **kw))
            r = rows[-1]
            print("   " + ", ".join(f"{k} {r[k]:.3g} s" for k in SERIES if r.get(k)), file=sys.stderr)
        return rows

    out["length"] = run("length", [bench_scenario(default_scenario_path(), duration=float(t))
                                   for t in lengths])
    out["length_fits"] = plot(out["length"], "duration_s", "record length per run (s); 3 runs, 3 storeys",
                              "Time vs. record length (default scenario)", images / "scaling_length.png",
                              loglog=False, unit="s of record")
    out["storeys"] = run("storeys", [storey_scenario(d, storey_len) for d in storeys])
    out["storeys_fits"] = plot(
        out["storeys"], "storeys", f"storeys d (2 runs x {storey_len:g} s; (d+1)^2 unknowns)",
        "Time per sample vs. number of storeys", images / "scaling_storeys.png", per_sample=True,
        guides=((2, "~ d^2 (reference)"), (3, "~ d^3 (reference)")))
    out["runs"] = run("runs", [runs_scenario(n, runs_len) for n in runs])
    out["runs_fits"] = plot(out["runs"], "runs", f"number of runs ({runs_len:g} s each, 3 storeys)",
                            f"Time vs. number of runs ({workers} simulation workers)", images / "scaling_runs.png",
                            loglog=False, unit="run")
    path = Path(args.json_out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    print(f"wrote {path} and {images}/scaling_{{length,storeys,runs}}.png")
    for key in ("length", "storeys", "runs"):
        fits = out[f"{key}_fits"]
        print(f"{key:>8}: " + ", ".join(
            f"{k} slope {v['slope']:.2f}" if "slope" in v else
            f"{k} {v['per_unit'] * 1e3:.3g} ms/unit (R2 {v['r2']:.3f})" for k, v in fits.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
