"""Mode 1's frequency against its amplitude in the free decays of the shipped rig and of its fitted twins.

    python -m benchmarks.real_backbones      (after python -m benchmarks.real_folds)

Each same-day trial of ``data/mini_shake_table/flexible_3storey`` ends in a free decay once the table
stops.  The top floor's acceleration relative to the table, band-passed around mode 1 (2.5-5.5 Hz,
zero phase), gives through its analytic signal the ringing's amplitude and instantaneous frequency
along the decay: the backbone of the rig's restoring force.  The same is done on each fold's augmented
twin (``benchmarks/results/real_folds.json``) re-simulated on every trial.  Writes
``benchmarks/results/real_backbones.md`` (median frequency per amplitude band) and
``real_backbones.png``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import scipy.signal

import momentid as mi
from benchmarks.real_folds import RIG, ROOT, TRIALS
from momentid.core.structure import Mechanism
from momentid.twin import fit as twin_fit

#: Mode 1's band (Hz) on this rig (3.7-3.8 Hz; modes 2 and 3 at 11 and 17 Hz).
BAND = (2.5, 5.5)
#: Amplitude bands (m/s^2 of band-passed top-floor acceleration) the backbone is summarised in.
BINS = (0.25, 0.5, 1.0, 2.0, 4.0)
#: The decay starts this long (s) after the table's last sample above TABLE_ACTIVE (m/s^2).
SETTLE = 1.0
TABLE_ACTIVE = 0.4
#: Instantaneous frequency smoothed over this many samples (0.2 s at 120 Hz).
SMOOTH = 25


def decay_backbone(a_top: np.ndarray, zdd: np.ndarray, fs: float):
    """Amplitude (m/s^2) and instantaneous frequency (Hz) of mode 1 along a trial's final free decay."""
    sos = scipy.signal.butter(4, BAND, btype="band", fs=fs, output="sos")
    x = scipy.signal.sosfiltfilt(sos, a_top - zdd)
    analytic = scipy.signal.hilbert(x)
    amplitude = np.abs(analytic)
    frequency = np.gradient(np.unwrap(np.angle(analytic))) * fs / (2 * np.pi)
    frequency = np.convolve(frequency, np.ones(SMOOTH) / SMOOTH, "same")
    start = int(np.flatnonzero(np.abs(zdd) > TABLE_ACTIVE)[-1] + SETTLE * fs)
    stop = len(x) - SMOOTH
    return amplitude[start:stop], frequency[start:stop]


def summary(amplitude, frequency) -> list:
    """Median frequency (Hz) in each amplitude band of :data:`BINS` (None where the decay never is)."""
    out = []
    for lo, hi in zip(BINS[:-1], BINS[1:]):
        sel = (amplitude >= lo) & (amplitude < hi)
        out.append(float(np.median(frequency[sel])) if sel.sum() > SMOOTH else None)
    return out


def _model(d: dict) -> twin_fit.FittedRig:
    friction = tuple(Mechanism(f.get("type", "joint_friction"), f["storey"],
                               tuple((k, v) for k, v in f.items() if k not in ("type", "storey")))
                     for f in d["friction"])
    return twin_fit.FittedRig(np.array(d["masses_kg"]), np.array(d["stiffness_n_per_m"]), np.array(d["damping_ratio"]),
                          friction, np.array(d["sensor_gain"]), np.array(d["sensor_offset_s"]))


def main(argv=None) -> int:
    out = ROOT / "benchmarks" / "results"
    folds = json.loads((out / "real_folds.json").read_text())
    substeps = folds["substeps"]
    experiment = mi.import_folder(RIG)
    rows, curves = [], {}
    for name in TRIALS:
        run = experiment.run(name)
        tr = twin_fit.trial(run, experiment.storeys)
        amp, freq = decay_backbone(tr.a[:, -1], tr.zdd, run.sample_rate)
        rows.append((name, "recorded", summary(amp, freq)))
        curves[(name, "recorded")] = (amp, freq)
        for fold in folds["folds"]:
            a = twin_fit.predict(_model(fold["augmented"]), tr, substeps)
            amp, freq = decay_backbone(a[:, -1], tr.zdd, run.sample_rate)
            label = f"twin (held out: {fold['held_out']})"
            rows.append((name, label, summary(amp, freq)))
            curves[(name, label)] = (amp, freq)
    head = " | ".join(f"{lo:g}-{hi:g}" for lo, hi in zip(BINS[:-1], BINS[1:]))
    lines = [f"| trial | source | mode-1 frequency (Hz) in the final free decay, by amplitude (m/s^2): {head} |",
             "|---|---|" + "---|" * (len(BINS) - 1)]
    for name, source, values in rows:
        cells = " | ".join("-" if v is None else f"{v:.3f}" for v in values)
        lines.append(f"| {name} | {source} | {cells} |")
    (out / "real_backbones.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    _plot(out, curves)
    return 0


def _plot(out: Path, curves) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(TRIALS), figsize=(16, 4), sharey=True)
    for ax, name in zip(axes, TRIALS):
        for (trial, source), (amp, freq) in curves.items():
            if trial != name:
                continue
            recorded = source == "recorded"
            ax.plot(amp, freq, "k-" if recorded else "--", lw=1.5 if recorded else 0.8, label=source)
        ax.set_xscale("log")
        ax.set_xlim(0.1, 8)
        ax.set_ylim(3.6, 3.9)
        ax.set_title(f"{name}: final free decay", fontsize=9)
        ax.set_xlabel("mode-1 amplitude, top floor (m/s^2)")
    axes[0].set_ylabel("instantaneous frequency (Hz)")
    axes[0].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(out / "real_backbones.png", dpi=80)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
