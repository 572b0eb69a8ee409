"""PNG plots of a twin: each trial's recorded and twin floor accelerations, and the transfer functions.

* ``replay_<trial>.png``: per floor sensor, the recorded and the twin's readings over the scored part
  of the trial (left) and over the :data:`ZOOM_S` seconds around the largest recorded response (right);
* ``transfer.png``: per floor sensor, the magnitude of the table-to-floor transfer function, estimated
  from each calibration trial (H1: cross-spectrum over the table's auto-spectrum, where the coherence
  exceeds :data:`MIN_COHERENCE`) against the twin's (:func:`momentid.twin.replay.transfer`).
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

import numpy as np
import scipy.signal

from momentid.twin.replay import Replay, transfer

__all__ = ["plot_replay", "plot_transfer", "replay_file", "replay_files", "pyplot", "envelope", "ENVELOPE_BINS",
           "ZOOM_S", "MIN_COHERENCE", "SEGMENT"]

#: Stretches a whole-trial panel is drawn as (minimum and maximum of each): about its width in pixels.
ENVELOPE_BINS = 1500
#: Width (s) of the zoom on the largest response.
ZOOM_S = 4.0
#: Least coherence of a recorded transfer estimate shown: below it the table barely drives that band
#: (a sine trial between its harmonics), and the estimate is noise.
MIN_COHERENCE = 0.8
#: Longest Welch segment (samples): at 120 Hz, 0.03 Hz bins, a few across a 0.3 %-damped 17 Hz mode.
SEGMENT = 4096
_RECORDED, _TWIN = "0.15", "tab:orange"


def pyplot():
    """``matplotlib.pyplot`` on the Agg backend (files only, no display)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _margins(fig, rows: int) -> None:
    """Fixed margins (a tight layout costs a second draw of every tick)."""
    inch = fig.get_figheight()
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.55 / inch, top=1 - 0.6 / inch, wspace=0.12,
                        hspace=0.45 if rows > 1 else 0.2)


def envelope(t: np.ndarray, x: np.ndarray, bins: int = ENVELOPE_BINS):
    """``(t, x)`` reduced to each of ``bins`` equal stretches' minimum and maximum, in time order: the
    same picture as every sample at a plot's width (a column of pixels shows a stretch's range)."""
    if t.size <= 2 * bins:
        return t, x
    edges = np.linspace(0, t.size, bins + 1).astype(int)
    lo = np.minimum.reduceat(x, edges[:-1])
    hi = np.maximum.reduceat(x, edges[:-1])
    mid = t[(edges[:-1] + edges[1:]) // 2]
    return np.repeat(mid, 2), np.column_stack([lo, hi]).ravel()


def replay_file(run: str) -> str:
    """File name of a trial's replay plot: ``replay_<name>.png`` for a name of letters, digits, ``-``
    and ``_``; any other name has those characters as ``_`` and the first 8 hex digits of its SHA-1
    appended, so two trials never share a plot ("trial 1", "trial_1")."""
    safe = re.sub(r"[^A-Za-z0-9_-]", "_", run)
    if safe != run or not run:
        safe += "-" + hashlib.sha1(run.encode("utf-8")).hexdigest()[:8]
    return f"replay_{safe}.png"


def replay_files(runs) -> dict[str, str]:
    """Each trial's replay plot file name (:func:`replay_file`), in trial order."""
    return {run: replay_file(run) for run in runs}


def plot_replay(replay: Replay, path: Path) -> Path:
    """Recorded and twin floor accelerations of one trial, whole and zoomed; returns ``path``."""
    plt = pyplot()
    d = replay.recorded.shape[1]
    s = replay.start
    t, rec, twin = replay.time, replay.recorded, replay.twin
    peak = s + int(np.argmax(np.max(np.abs(rec[s:] - rec[s:].mean(axis=0)), axis=1)))
    zoom = (t >= t[peak] - ZOOM_S / 2) & (t <= t[peak] + ZOOM_S / 2)
    fig, axes = plt.subplots(d, 2, figsize=(13, 2.3 * d + 0.8), sharex="col", squeeze=False,
                             gridspec_kw={"width_ratios": [3, 2]})
    for j in range(d):
        row = d - 1 - j                    # top floor on top
        for col, keep in enumerate((slice(s, None), zoom)):
            ax = axes[row, col]
            thin = envelope if col == 0 else (lambda a, b: (a, b))
            ax.plot(*thin(t[keep], rec[keep, j]), color=_RECORDED, lw=0.6, label="recorded")
            ax.plot(*thin(t[keep], twin[keep, j]), color=_TWIN, lw=0.6, alpha=0.85, label="twin")
            ax.set_ylabel(f"floor {j + 1} sensor (m/s²)" if col == 0 else "")
            ax.grid(alpha=0.3)
        axes[row, 0].set_title(f"floor {j + 1} sensor: NRMSE {100 * replay.nrmse_floors[j]:.1f} %", fontsize=9,
                               loc="left")
    axes[0, 1].set_title(f"the {ZOOM_S:g} s around the largest response", fontsize=9, loc="left")
    axes[0, 0].legend(loc="upper right", fontsize=8)
    for col in range(2):
        axes[-1, col].set_xlabel("time (s)")
    sensors = "sensors calibrated on this trial" if replay.calibrated else "nominal sensors (trial not calibrated on)"
    fig.suptitle(f"trial {replay.run}: recorded and twin floor accelerations, NRMSE {100 * replay.nrmse:.1f} % "
                 f"(sensor noise alone: {100 * replay.noise_nrmse:.1f} %); {sensors}", fontsize=10)
    _margins(fig, d)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _recorded_transfer(run, d: int, start: int):
    """H1 estimate of ``a_j / zdd`` for one trial: frequencies (Hz), magnitudes (nf, d) (NaN where the
    coherence is below :data:`MIN_COHERENCE`)."""
    fs = run.sample_rate
    zdd = run["zdd"][start:]
    nperseg = int(min(SEGMENT, 2 ** np.floor(np.log2(max(zdd.size // 4, 16)))))
    f, pzz = scipy.signal.welch(zdd, fs=fs, nperseg=nperseg)
    out = np.empty((f.size, d))
    for j in range(d):
        a = run[f"a{j + 1}"][start:]
        _, pza = scipy.signal.csd(zdd, a, fs=fs, nperseg=nperseg)
        _, coherence = scipy.signal.coherence(zdd, a, fs=fs, nperseg=nperseg)
        out[:, j] = np.where(coherence >= MIN_COHERENCE, np.abs(pza) / np.maximum(pzz, 1e-300), np.nan)
    return f, out


def plot_transfer(twin, experiment, path: Path) -> Path:
    """Magnitude of each floor sensor's transfer from the table: every calibration trial's estimate
    and the twin's; returns ``path``."""
    plt = pyplot()
    p = twin.parameters
    d = p.storeys
    fs = min(r.sample_rate for r in experiment.runs)
    top = max([*twin.modes.frequency, *(e.frequency for e in p.extra_modes)])
    f_max = min(1.5 * top, 0.45 * fs)
    f = np.linspace(0.0, f_max, 2000)[1:]
    model = np.abs(transfer(p, f))
    fig, axes = plt.subplots(d, 1, figsize=(10, 2.4 * d + 0.8), sharex=True, squeeze=False)
    colours = plt.get_cmap("tab10")
    for k, replay in enumerate(r for r in twin.replays if r.calibrated):
        fr, h = _recorded_transfer(experiment.run(replay.run), d, replay.start)
        keep = fr <= f_max
        for j in range(d):
            axes[d - 1 - j, 0].semilogy(fr[keep], h[keep, j], color=colours(k % 10), lw=0.8, alpha=0.8,
                                        label=f"recorded: {replay.run}")
    for j in range(d):
        ax = axes[d - 1 - j, 0]
        ax.semilogy(f, model[:, j], color="black", lw=1.4, label="twin (nominal sensors)")
        ax.set_ylabel(f"floor {j + 1} / table")
        ax.set_title(f"floor {j + 1} sensor over table sensor: magnitude", fontsize=9, loc="left")
        ax.grid(alpha=0.3, which="both")
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("frequency (Hz)")
    fig.suptitle(f"table-to-floor transfer functions: recorded (coherence >= {MIN_COHERENCE:g}) and twin",
                 fontsize=10)
    _margins(fig, d)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
