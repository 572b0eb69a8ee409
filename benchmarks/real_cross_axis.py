"""What the shipped rigs' twins leave out: is the floors' misfit driven by the table's other motions?

    python -m benchmarks.real_cross_axis [--rig stiff_1storey|flexible_3storey|both] [--out DIR]

momentid's linear twin is a shear building driven by the table's shaking axis alone.  The table's IMU also
records its cross and vertical accelerations and its three angular rates (imported as
:data:`~momentid.core.series.TABLE_MOTION`).  Per trial of
each shipped rig (``data/mini_shake_table``), the trial's own linear twin is fitted
(:func:`momentid.twin.fit.fit_twin` from the modal identification of the rig's first trial), and its top
floor's misfit is taken in the band of +-:data:`BAND` around the mode that holds most of it.  The
question is what share of that misfit's power the table's five other channels predict linearly (the
multiple coherence of a Welch estimate, :data:`SEGMENT` samples a segment, summed over the band's bins).

Such an estimate is biased upward by about (channels / segments) even for unrelated signals.  The same
statistic with the five channels reversed in time (the same spectra, no causal link) is the reference:
a share well above it says the table moves in more than X near that mode and drives what the twin
misses (a base that rocks, or a second axis of shaking), which no physics added to an X-driven shear
twin can hold.  Single-channel shares and the band's power of the table's X and of the misfit are
printed beside it.

Then the folds of :mod:`benchmarks.real_folds`, each trial held out in turn: the linear twin refitted on
the training trials (:func:`momentid.diagnosis.twin.folds.linear_start` of the quietest, then
:func:`momentid.twin.fit.fit_twin`), and the same twin driven by ``zdd + sum_k g_k c_k``, the table's five
other motions ``c_k`` entering as base acceleration through gains ``g_k`` fitted with the twin on the
training trials (:attr:`momentid.twin.fit.FittedRig.table_motion`, the candidate ``table_motion`` of
``momentid diagnose``), replayed on the held-out trial; and the same on the fold's inner held-out trial
from the other training trials (the evidence the twin's physics are chosen by,
:func:`momentid.diagnosis.twin.folds.inner_hold_out`).  Writes
``benchmarks/results/real_cross_axis.md`` and ``.json``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import scipy.signal

from benchmarks.common import RESULTS, ROOT, save
from momentid.core.series import TABLE_MOTION

RIGS = ("stiff_1storey", "flexible_3storey")
#: Half-width of the band around the mode (relative).
BAND = 0.15
#: Welch segment (samples): about 2 s at 120 Hz.
SEGMENT = 256
#: The table IMU's motions besides its shaking axis, as the import names them.
OTHERS = TABLE_MOTION
#: Per rig, the trials the folds train on (``momentid diagnose``'s rig-state check leaves the flexible
#: rig's ``bonus_event`` out; the stiff rig's ``northridge_2`` trains and is never held out).
TRAINING = {"stiff_1storey": ("el_centro_1", "el_centro_2", "northridge_1", "northridge_2", "sine_1", "sine_2"),
            "flexible_3storey": ("northridge", "sine_1p0", "sine_1p5", "sine_2p0")}


def predictable_share(y: np.ndarray, regressors: list, fs: float, band: tuple) -> float:
    """The share of ``y``'s power in ``band`` (Hz) that ``regressors`` predict linearly (Welch)."""
    signals = [y - y.mean()] + [r - r.mean() for r in regressors]
    m = len(signals)
    f, _ = scipy.signal.csd(signals[0], signals[0], fs, nperseg=SEGMENT)
    S = np.zeros((f.size, m, m), complex)
    for i in range(m):
        for j in range(i, m):
            S[:, i, j] = scipy.signal.csd(signals[i], signals[j], fs, nperseg=SEGMENT)[1]
            S[:, j, i] = S[:, i, j].conj()
    inside = np.flatnonzero((f >= band[0]) & (f <= band[1]))
    explained = sum(float(np.real(S[q, 0, 1:] @ np.linalg.solve(S[q, 1:, 1:], S[q, 1:, 0]))) for q in inside)
    return explained / float(sum(S[q, 0, 0].real for q in inside))


def evaluate(rig: str) -> list[dict]:
    """Per trial of ``rig``: the top floor's misfit band and what the table's other channels predict of it."""
    import momentid as mi
    from momentid.diagnosis.twin.folds import linear_start
    from momentid.errors import MomentidError
    from momentid.twin import fit as twin_fit

    experiment = mi.import_folder(ROOT / "data" / "mini_shake_table" / rig)
    start = linear_start(experiment, experiment.runs[0].name)
    rows = []
    for run in experiment.runs:
        tr = twin_fit.trial(run, experiment.storeys)
        if tr.motion_channels != OTHERS:
            rows.append({"rig": rig, "trial": run.name, "skipped": "the import has not the table's other motions"})
            continue
        try:
            own = twin_fit.fit_twin([tr], start)
        except MomentidError as err:
            rows.append({"rig": rig, "trial": run.name, "skipped": str(err)})
            continue
        misfit = (tr.a - twin_fit.predict(own.model, tr))[tr.start:, -1]
        fs = 1.0 / tr.dt
        f, power = scipy.signal.welch(misfit - misfit.mean(), fs, nperseg=SEGMENT)
        modes = twin_fit.twin_modes(own.model)[0] / (2 * np.pi)
        peak = float(f[np.argmax(power)])
        mode = float(modes[np.argmin(np.abs(modes - peak))])
        band = ((1 - BAND) * mode, (1 + BAND) * mode)
        others = list(tr.motion[tr.start:].T)
        share = predictable_share(misfit, others, fs, band)
        null = predictable_share(misfit, [o[::-1] for o in others], fs, band)
        single = {c: predictable_share(misfit, [o], fs, band) for c, o in zip(OTHERS, others)}
        inside = (f >= band[0]) & (f <= band[1])
        _, table_power = scipy.signal.welch(tr.zdd[tr.start:] - tr.zdd[tr.start:].mean(), fs, nperseg=SEGMENT)
        rows.append({"rig": rig, "trial": run.name, "mode_hz": mode, "band_hz": band,
                     "misfit_band_rms": float(np.sqrt(np.sum(power[inside]) * f[1])),
                     "table_x_band_rms": float(np.sqrt(np.sum(table_power[inside]) * f[1])),
                     "own_nrmse": own.nrmse[run.name], "share": share, "null_share": null, "single": single,
                     "segments": int(misfit.size // (SEGMENT // 2) - 1)})
    return rows


def folds(rig: str) -> list[dict]:
    """Per held-out trial of :data:`benchmarks.real_folds.RIGS`: the linear refit's held-out NRMSE, and the
    same twin driven by the table's other motions too (their gains fitted with it on the training trials,
    :attr:`momentid.twin.fit.FittedRig.table_motion`), and the same on the fold's inner held-out trial."""
    import momentid as mi
    from benchmarks.real_folds import RIGS as FOLDS
    from momentid.diagnosis.twin.folds import inner_hold_out, linear_start
    from momentid.twin import fit as twin_fit

    experiment = mi.import_folder(ROOT / "data" / "mini_shake_table" / rig)
    names = [n for n in TRAINING[rig] if n in {r.name for r in experiment.runs}]
    trials = {n: twin_fit.trial(experiment.run(n), experiment.storeys) for n in names}

    def scored(training, held):
        """(linear refit's NRMSE on ``held``, the same driven by the table's motions too, their gains)."""
        quiet = min(training, key=lambda n: float(np.sqrt(np.mean(trials[n].a[trials[n].start:] ** 2))))
        train = [trials[n] for n in training]
        refit = twin_fit.fit_twin(train, linear_start(experiment, quiet)).model
        moved = twin_fit.fit_twin(train, refit.driven_by(OTHERS)).model
        return twin_fit.nrmse(refit, trials[held]), twin_fit.nrmse(moved, trials[held]), moved.table_gains

    rows = []
    for held in FOLDS[rig]:
        training = [n for n in names if n != held]
        inner = inner_hold_out(trials, training)             # the selection's own evidence, as for the physics
        inner_linear, inner_with, _ = scored([n for n in training if n != inner], inner)
        linear, with_inputs, gains = scored(training, held)
        rows.append({"rig": rig, "held_out": held, "training": training, "gains": dict(zip(OTHERS, gains.tolist())),
                     "linear_refit": linear, "with_table_channels": with_inputs, "inner_held_out": inner,
                     "inner_ratio": inner_with / inner_linear})
    return rows


def folds_table(rows: list[dict]) -> list[str]:
    lines = ["| rig | held out | linear refit | the same twin, the table's other channels as base inputs | ratio | "
             f"inner held-out: ratio | gains ({', '.join(OTHERS)}) |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['rig']} | {r['held_out']} | {100 * r['linear_refit']:.1f} % | "
                     f"{100 * r['with_table_channels']:.1f} % | {r['with_table_channels'] / r['linear_refit']:.2f} | "
                     f"{r['inner_held_out']}: {r['inner_ratio']:.2f} | "
                     f"{', '.join(f'{v:.3g}' for v in r['gains'].values())} |")
    for rig in dict.fromkeys(r["rig"] for r in rows):
        ratios = [r["with_table_channels"] / r["linear_refit"] for r in rows if r["rig"] == rig]
        lines.append(f"| {rig} | mean | | | {np.mean(ratios):.2f} | | |")
    return lines


def table(rows: list[dict]) -> list[str]:
    lines = ["| rig | trial | mode (Hz) | own linear NRMSE | top misfit / table X in band (m/s^2 RMS) | "
             "predicted by the table's 5 other channels | the same, reversed in time | each alone "
             f"({', '.join(OTHERS)}) |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "skipped" in r:
            lines.append(f"| {r['rig']} | {r['trial']} | skipped: {r['skipped'][:90]} | | | | | |")
            continue
        lines.append(f"| {r['rig']} | {r['trial']} | {r['mode_hz']:.2f} | {100 * r['own_nrmse']:.1f} % | "
                     f"{r['misfit_band_rms']:.3g} / {r['table_x_band_rms']:.3g} | {r['share']:.2f} | "
                     f"{r['null_share']:.2f} | {', '.join(f'{v:.2f}' for v in r['single'].values())} |")
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.real_cross_axis", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rig", choices=[*RIGS, "both"], default="both")
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    rigs = RIGS if args.rig == "both" else (args.rig,)
    rows = [r for rig in rigs for r in evaluate(rig)]
    held = [r for rig in rigs for r in folds(rig)]
    lines = [f"`python -m benchmarks.real_cross_axis --rig {args.rig}` (see its docstring)", "", *table(rows), "",
             "Held out (the folds of `benchmarks.real_folds`):", "", *folds_table(held)]
    save(args.out, "real_cross_axis", {"trials": rows, "folds": held}, lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
