"""The twin's linear refit against ``mujoco.sysid`` on the same fit.

    python -m benchmarks.sysid_peer [--trials northridge,sine_1p0,sine_1p5] [--out benchmarks/results]

Needs the benchmark extra ``mujoco[sysid]`` (``pip install -e ".[sysid]"``).  The fit: the linear twin
of the shipped rig (``data/mini_shake_table/flexible_3storey``, three floors, 120 Hz) refitted by output
error to the training trials, from the modal identification of the quietest one, as ``momentid diagnose``
does for each held-out fold (:func:`momentid.diagnosis.twin.folds.linear_start`, then
:func:`momentid.twin.fit.fit_twin`): K's upper triangle, the modal damping ratios, the sensors' log-gains
and clock offsets; the residual is every trial's floor accelerations against the twin's, each trial
scaled by its own signal.

- **momentid**: :func:`momentid.twin.fit.fit_twin` (scipy's trust-region least squares; the Jacobian's
  physical columns are forward differences, each trial replayed as the linear twin's own MuJoCo step map
  (:mod:`momentid.lab.linear_replay`: the rollout's readings to round-off, in compiled code, one map
  per sample), the trials on threads, the sensors' columns exact; one BLAS thread; at most
  :data:`momentid.twin.fit.MAX_NFEV` evaluations).
- **mujoco.sysid**: :func:`mujoco.sysid.optimize` (its default ``"mujoco"`` backend,
  ``mujoco.minimize.least_squares``: Levenberg-Marquardt, every Jacobian column a forward difference,
  evaluated in one batch) of the same parameter vector within the same bounds, from the same start, its
  residual evaluated by the same batched rollouts of the same compiled twins (one ``mujoco.rollout`` per
  trial for every column of a batch), to its own convergence.

The two minimise the same sum of squares: the table gives both costs, the trials' NRMSE, the residual
evaluations (trial replays of one parameter set) and the times, and the ratio momentid / sysid of the
times measured in the same process, both after one warm-up replay of the start on every trial (the
replay loop loaded from numba's cache; without it the first fit pays about 0.5 s that the second does
not) (the target: 0.1).  Writes ``sysid_peer.json`` and ``sysid_peer.md``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from benchmarks.common import RESULTS, ROOT, machine, save

SHIPPED = ROOT / "data" / "mini_shake_table" / "flexible_3storey"
TRIALS = "northridge,sine_1p0,sine_1p5"


def sysid_fit(train, start, substeps=None, max_iters: int = 100):
    """The same fit by ``mujoco.sysid.optimize``: (model, cost, residual evaluations, iterations)."""
    from mujoco import sysid

    from momentid.twin import fit as twin_fit

    layout = twin_fit._Layout(start, ())
    lo, hi = layout.bounds()
    theta0 = np.clip(layout.pack(start), lo + 1e-9, hi - 1e-9)
    # mujoco.minimize needs finite bounds: K's entries (unbounded in momentid's fit) within ten times the
    # start's largest, either sign (never reached: both fits stay near the start)
    wide = 10.0 * np.max(np.abs(np.asarray(start.stiffness)))
    lo, hi = np.where(np.isfinite(lo), lo, -wide), np.where(np.isfinite(hi), hi, wide)
    sizes = [(t.fit_stop - t.start) * layout.d for t in train]
    evaluations = [0]

    def residual_fn(x, params):
        columns = np.asarray(x, float).reshape(theta0.size, -1)
        models = [layout.unpack(columns[:, k]) for k in range(columns.shape[1])]
        ok = [twin_fit._valid(m) for m in models]
        valid = [m for m, v in zip(models, ok) if v]
        evaluations[0] += len(valid) * len(train)
        out = np.full((sum(sizes), len(models)), twin_fit._INVALID)
        if valid:
            compiled = twin_fit._compiled_by_step(valid, train, substeps)
            runs = [twin_fit._simulate(valid, t, False, substeps, compiled[t.dt], linear=False) for t in train]
            column = 0
            for k, m in enumerate(models):
                if not ok[k]:
                    continue
                out[:, k] = np.concatenate([twin_fit._residual(m, runs[i][column], t) for i, t in enumerate(train)])
                column += 1
        return [out if np.ndim(x) > 1 else out[:, 0]], None, None

    params = sysid.ParameterDict({"theta": sysid.Parameter("theta", theta0, lo, hi)})
    opt, result = sysid.optimize(params, residual_fn, optimizer="mujoco", verbose=False, max_iters=max_iters)
    theta = opt["theta"].value
    r = residual_fn(theta, opt)[0][0]
    return layout.unpack(theta), float(r @ r), evaluations[0]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.sysid_peer", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--trials", default=TRIALS, help=f"training trials (default {TRIALS})")
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    import momentid as mi
    from momentid.core import counters
    from momentid.diagnosis.twin.folds import linear_start
    from momentid.twin import fit as twin_fit

    experiment = mi.import_folder(SHIPPED)
    names = args.trials.split(",")
    train = [twin_fit.trial(experiment.run(n), experiment.storeys) for n in names]
    quietest = min(names, key=lambda n: float(np.sqrt(np.mean(train[names.index(n)].a ** 2))))
    start = linear_start(experiment, quietest)
    for t in train:            # both fits timed warm: the replay loop loaded from numba's cache, FFT plans made
        twin_fit.nrmse(start, t)
    load = os.getloadavg()
    with counters.counting() as ours_replays:
        began = time.perf_counter()
        ours = twin_fit.fit_twin(train, start)
        ours_s = time.perf_counter() - began
        ours_n = ours_replays()
    began = time.perf_counter()
    peer, peer_cost, peer_n = sysid_fit(train, start)
    peer_s = time.perf_counter() - began
    peer_nrmse = {t.name: twin_fit.nrmse(peer, t) for t in train}
    rows = {"trials": names, "start_from": quietest, "load_average": [round(x, 1) for x in load],
            "momentid": {"seconds": ours_s, "cost": ours.cost, "replays": ours_n, "nrmse": ours.nrmse,
                         "model": ours.model.to_dict()},
            "sysid": {"seconds": peer_s, "cost": peer_cost, "replays": peer_n, "nrmse": peer_nrmse,
                      "model": peer.to_dict()},
            "ratio": ours_s / peer_s, "machine": machine()}
    lines = ["| fit | time | cost (sum of squared scaled residuals) | trial replays | NRMSE per trial |",
             "|---|---|---|---|---|"]
    for name, r in (("momentid fit_twin", rows["momentid"]), ("mujoco.sysid optimize", rows["sysid"])):
        nrmse = ", ".join(f"{k} {100 * v:.2f} %" for k, v in r["nrmse"].items())
        lines.append(f"| {name} | {r['seconds']:.1f} s | {r['cost']:.5g} | {r['replays']} | {nrmse} |")
    lines += ["", f"momentid / sysid time: {rows['ratio']:.2f} (target 0.1); trials {', '.join(names)}, start: "
                  f"the modal identification of {quietest}; load average {load[0]:.1f} on the machine's "
                  f"{os.cpu_count()} cores."]
    save(args.out, "sysid_peer", rows, lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
