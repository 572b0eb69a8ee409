"""Plots of a twin: each trial's recorded and twin floor accelerations, and the transfer functions.

* ``replay_<trial>.png``: per floor sensor, the recorded and the twin's readings over the scored part
  of the trial (left) and over the :data:`ZOOM_S` seconds around the largest recorded response (right);
* ``transfer.png``: per floor sensor, the magnitude of the table-to-floor transfer function, estimated
  from each calibration trial (H1, :func:`momentid.estimation.frf.measured_transfer`, where the
  coherence reaches :data:`MIN_COHERENCE`) against the twin's (:func:`momentid.twin.replay.transfer`).

The ``*_figure`` functions return the matplotlib figure (the report page draws them as SVG); the
``plot_*`` functions save it as PNG.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
import hashlib
import re
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

from momentid.estimation.noise import quiet_lead_in
from momentid.estimation.frf import MIN_COHERENCE, SEGMENT, measured_transfer
from momentid.twin.replay import Replay, transfer

if TYPE_CHECKING:
    from matplotlib.figure import Figure
    from momentid.core.series import Experiment
    from momentid.twin.build import Twin
    from momentid.twin.parameters import TwinParameters

__all__ = ["plot_replay", "plot_transfer", "replay_figure", "transfer_figure", "overlay_figure", "replay_file",
           "replay_files", "pyplot", "envelope", "ENVELOPE_BINS", "ZOOM_S", "MIN_COHERENCE", "SEGMENT"]

#: Stretches a whole-trial panel is drawn as (minimum and maximum of each): about its width in pixels.
ENVELOPE_BINS = 1500
#: Width (s) of the zoom on the largest response.
ZOOM_S = 4.0
_RECORDED, _TWIN = "0.15", "tab:orange"


def pyplot() -> ModuleType:
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


def envelope(t: np.ndarray, x: np.ndarray, bins: int = ENVELOPE_BINS) -> tuple[np.ndarray, np.ndarray]:
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


def replay_files(runs: Iterable[str]) -> dict[str, str]:
    """Each trial's replay plot file name (:func:`replay_file`), in trial order."""
    return {run: replay_file(run) for run in runs}


def overlay_figure(t: np.ndarray, recorded: np.ndarray, models: dict, start: int, *, title: str,
                   panel_titles: Sequence[str] | None = None, unit: str = "m/s²", label: str = "floor {j} sensor",
                   bins: int = ENVELOPE_BINS) -> Figure:
    """Recorded channels against model replays: per channel (top floor on top), the record from sample
    ``start`` on (left, drawn as :func:`envelope` of ``bins`` stretches) and the :data:`ZOOM_S` seconds
    around the largest recorded response (right).

    Parameters
    ----------
    t : ndarray, shape (n,)
        s.
    recorded : ndarray, shape (n, d)
    models : dict
        Label -> ``(values (n, d), colour)``, drawn in order over the recorded channels.
    start : int
        First sample shown on the left (after a quiet lead-in).
    title : str
    panel_titles : sequence of str, optional
        One per channel, over its left panel.
    unit : str
        Of the channels.
    label : str
        A channel's axis label, ``{j}`` its number (1-based).
    bins : int

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = pyplot()
    d = recorded.shape[1]
    s = start
    peak = s + int(np.argmax(np.max(np.abs(recorded[s:] - recorded[s:].mean(axis=0)), axis=1)))
    zoom = (t >= t[peak] - ZOOM_S / 2) & (t <= t[peak] + ZOOM_S / 2)
    fig, axes = plt.subplots(d, 2, figsize=(13, 2.3 * d + 0.8), sharex="col", squeeze=False,
                             gridspec_kw={"width_ratios": [3, 2]})
    for j in range(d):
        row = d - 1 - j                    # top floor on top
        for col, keep in enumerate((slice(s, None), zoom)):
            ax = axes[row, col]
            thin = (lambda a, b: envelope(a, b, bins)) if col == 0 else (lambda a, b: (a, b))
            ax.plot(*thin(t[keep], recorded[keep, j]), color=_RECORDED, lw=0.6, label="recorded")
            for name, (values, colour) in models.items():
                ax.plot(*thin(t[keep], values[keep, j]), color=colour, lw=0.6, alpha=0.85, label=name)
            ax.set_ylabel(f"{label.format(j=j + 1)} ({unit})" if col == 0 else "")
            ax.grid(alpha=0.3)
        if panel_titles is not None:
            axes[row, 0].set_title(panel_titles[j], fontsize=9, loc="left")
    axes[0, 1].set_title(f"the {ZOOM_S:g} s around the largest response", fontsize=9, loc="left")
    axes[0, 0].legend(loc="upper right", fontsize=8)
    for col in range(2):
        axes[-1, col].set_xlabel("time (s)")
    fig.suptitle(title, fontsize=10)
    _margins(fig, d)
    return fig


def replay_figure(replay: Replay, bins: int = ENVELOPE_BINS) -> Figure:
    """Recorded and twin floor accelerations of one trial, whole and zoomed (:func:`overlay_figure`)."""
    sensors = "sensors calibrated on this trial" if replay.calibrated else "nominal sensors (trial not calibrated on)"
    return overlay_figure(
        replay.time, replay.recorded, {"twin": (replay.twin, _TWIN)}, replay.start, bins=bins,
        title=f"trial {replay.run}: recorded and twin floor accelerations, NRMSE {100 * replay.nrmse:.1f} % "
              f"(sensor noise alone: {100 * replay.noise_nrmse:.1f} %); {sensors}",
        panel_titles=[f"floor {j + 1} sensor: NRMSE {100 * x:.1f} %" for j, x in enumerate(replay.nrmse_floors)])


def plot_replay(replay: Replay, path: Path) -> Path:
    """:func:`replay_figure` as a PNG; returns ``path``."""
    return _save(replay_figure(replay), path)


def _save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=110)
    pyplot().close(fig)
    return path


def transfer_figure(params: TwinParameters | None, experiment: Experiment, runs: Iterable[str], top: float, *,
                    model: str = "twin (nominal sensors)",
                    title: str = "table-to-floor transfer functions: recorded (coherence >= {c:g}) and twin") -> Figure:
    """Magnitude of each floor sensor's transfer from the table: each run's H1 estimate after its quiet
    lead-in and the model's (:func:`momentid.twin.replay.transfer` of ``params``).

    Parameters
    ----------
    params : TwinParameters or None
        None: the recorded estimates alone.
    experiment : Experiment
    runs : sequence of str
        The runs whose estimates are drawn.
    top : float
        The highest modelled resonance (Hz): the plot runs to 1.5 x it (below 0.45 x the sample rate).
    model, title : str
        The model curve's label and the figure's title (``{c}``: the coherence threshold).

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = pyplot()
    d = experiment.storeys
    fs = min(r.sample_rate for r in experiment.runs)
    f_max = min(1.5 * top, 0.45 * fs)
    f = np.linspace(0.0, f_max, 2000)[1:]
    curve = None if params is None else np.abs(transfer(params, f))
    fig, axes = plt.subplots(d, 1, figsize=(10, 2.4 * d + 0.8), sharex=True, squeeze=False)
    colours = plt.get_cmap("tab10")
    for k, name in enumerate(runs):
        run = experiment.run(name)
        measured = measured_transfer(run, d, quiet_lead_in(run))
        keep = measured.frequency <= f_max
        shown = measured.shown()
        for j in range(d):
            axes[d - 1 - j, 0].semilogy(measured.frequency[keep], shown[keep, j], color=colours(k % 10), lw=0.8,
                                        alpha=0.8, label=f"recorded: {name}")
    for j in range(d):
        ax = axes[d - 1 - j, 0]
        if curve is not None:
            ax.semilogy(f, curve[:, j], color="black", lw=1.4, label=model)
        ax.set_ylabel(f"floor {j + 1} / table")
        ax.set_title(f"floor {j + 1} sensor over table sensor: magnitude", fontsize=9, loc="left")
        ax.grid(alpha=0.3, which="both")
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("frequency (Hz)")
    fig.suptitle(title.format(c=MIN_COHERENCE), fontsize=10)
    _margins(fig, d)
    return fig


def plot_transfer(twin: Twin, experiment: Experiment, path: Path) -> Path:
    """Every calibration trial's transfer estimate and the twin's (:func:`transfer_figure`) as a PNG;
    returns ``path``."""
    top = max([*twin.modes.frequency, *(e.frequency for e in twin.parameters.extra_modes)])
    return _save(transfer_figure(twin.parameters, experiment, [r.run for r in twin.replays if r.calibrated], top),
                 path)
