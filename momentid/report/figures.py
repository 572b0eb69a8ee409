"""Figures of the report page, drawn by matplotlib as inline SVG.

:func:`svg` turns a figure into an ``<svg>`` element that can stand beside others in one page: the same
figure gives the same bytes (no date, no metadata, a fixed hash salt), its identifiers are its own
(prefixed with the figure's number), path coordinates keep 0.1 pt (a tenth of a printer's point: finer
than print) without the line-to commands SVG implies, and text stays text (selectable, small; matplotlib's
font, DejaVu Sans, or the reader's sans-serif).  The figures drawn here:

- :func:`amplitude_figure`: each run's modes against its response amplitude (the per-run trend);
- :func:`comparison_figure`: the held-out NRMSE of each model beside the noise alone;
- :func:`mismatch_figure`: where the held-out misfit sits: per sensor, the NRMSE of each model, and
  the spectrum of what the final model leaves, the band the diagnosis names shaded;
- :func:`shapes_figure`: the mode shapes floor by floor.

Overlays of records and models and transfer functions come from :mod:`momentid.twin.plots`.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
import io
import re
import textwrap
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike
import scipy.signal

from momentid.core.html import channel_words
from momentid.twin.plots import pyplot

if TYPE_CHECKING:
    from matplotlib.figure import Figure
    from momentid.diagnosis.modal.check import RunsFit
    from momentid.estimation.scaled import ModalIdentification

__all__ = ["svg", "TrendPoint", "trend_points", "amplitude_figure", "comparison_figure", "mismatch_figure",
           "shapes_figure"]

_NUMBER = re.compile(r"(-?\d+\.\d)\d+")


def _coarse_path(match: re.Match) -> str:
    """A path's data (`` d="..."``) with 0.1 pt coordinates and each ``L`` that SVG implies (a line-to
    after a move-to or a line-to) left out."""
    out, last = [], ""
    for command, numbers in re.findall(r"([A-Za-z])([^A-Za-z]*)", match.group(0)[4:-1]):
        if not (command == "L" and last in ("M", "L")):
            out.append(command)
        out.append(" ".join(_NUMBER.sub(r"\1", numbers).split()))
        last = command
    return ' d="' + " ".join(x for x in out if x) + '"'


def svg(fig: Figure, number: int) -> str:
    """The ``<svg>`` element of matplotlib figure ``fig`` (closed afterwards), figure ``number`` of its page
    (module docstring)."""
    import matplotlib

    buffer = io.StringIO()
    try:
        with matplotlib.rc_context({"svg.hashsalt": "momentid", "svg.fonttype": "none"}):
            fig.savefig(buffer, format="svg", metadata={"Date": None})
    finally:
        pyplot().close(fig)
    text = buffer.getvalue()
    text = text[text.index("<svg"):]
    text = re.sub(r"\s*<metadata>.*?</metadata>", "", text, count=1, flags=re.S)
    text = re.sub(r"font-family: [^;\"]*", "font-family: 'DejaVu Sans', sans-serif", text)
    text = re.sub(r"\n\s+", "\n", text)
    text = re.sub(r' d="[^"]*"', _coarse_path, text)
    prefix = f"f{number}-"
    text = re.sub(r'\bid="', f'id="{prefix}', text)
    text = re.sub(r'href="#', f'href="#{prefix}', text)
    return re.sub(r"url\(#", f"url(#{prefix}", text).strip()


@dataclass(frozen=True)
class TrendPoint:
    """One run's modes at its response amplitude.

    Attributes
    ----------
    run : str
    amplitude : float
        RMS top-floor acceleration relative to the table (m/s^2).
    frequency, frequency_std : ndarray, shape (d,)
        Hz.
    damping_ratio, damping_ratio_std : ndarray, shape (d,)
        1.
    """

    run: str
    amplitude: float
    frequency: np.ndarray
    frequency_std: np.ndarray
    damping_ratio: np.ndarray
    damping_ratio_std: np.ndarray


def trend_points(results: Iterable[ModalIdentification | RunsFit]) -> list[TrendPoint]:
    """:class:`TrendPoint` of per-run identifications (``ModalIdentification`` of one run each) or of the
    modal diagnosis' training fits (``RunsFit``)."""
    out = []
    for r in results:
        if hasattr(r, "omega"):    # RunsFit
            out.append(TrendPoint(r.runs[0], float(r.amplitude[0]), np.asarray(r.omega) / (2 * np.pi),
                                  np.asarray(r.frequency_std), np.asarray(r.zeta), np.asarray(r.zeta_std)))
        else:
            out.append(TrendPoint(r.runs[0], float(r.amplitude[0]), np.asarray(r.frequency),
                                  np.asarray(r.frequency_std), np.asarray(r.damping_ratio),
                                  np.asarray(r.damping_ratio_std)))
    return out


def amplitude_figure(points: Sequence[TrendPoint], *, held: str | None = None, set_apart: Sequence[str] = (),
                     lines: dict | None = None) -> Figure:
    """Each run's mode frequencies (top row) and damping ratios (bottom row) against its response
    amplitude, one column per mode, with standard errors.

    Parameters
    ----------
    points : sequence of TrendPoint
    held : str, optional
        The held-out run (drawn hollow, labelled).
    set_apart : sequence of str
        Runs of another rig state (drawn as crosses).
    lines : dict, optional
        ``{"frequency": (d, 2), "damping_ratio": (d, 2)}`` intercepts and slopes of fitted lines
        (Hz and Hz per m/s^2; 1 and 1 per m/s^2), drawn over the training amplitudes.

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = pyplot()
    d = len(points[0].frequency)
    fig, axes = plt.subplots(2, d, figsize=(3.6 * d + 1.2, 5.2), squeeze=False, sharex=True)
    x = np.array([p.amplitude for p in points])
    for m in range(d):
        for row, (key, scale, unit) in enumerate((("frequency", 1.0, "Hz"), ("damping_ratio", 100.0, "%"))):
            ax = axes[row, m]
            for p in points:
                style = dict(fmt="o", color="tab:blue", ms=5, capsize=2)
                if p.run == held:
                    style.update(mfc="white", color="tab:red")
                elif p.run in set_apart:
                    style.update(fmt="x", color="0.4")
                ax.errorbar(p.amplitude, scale * getattr(p, key)[m], yerr=scale * getattr(p, key + "_std")[m],
                            **style)
                ax.annotate(p.run, (p.amplitude, scale * getattr(p, key)[m]), fontsize=7, xytext=(3, 3),
                            textcoords="offset points")
            if lines is not None and key in lines:
                c = np.asarray(lines[key])[m]
                xs = np.linspace(x.min(), x.max(), 2)
                ax.plot(xs, scale * (c[0] + c[1] * xs), color="0.3", lw=0.8, ls="--")
            ax.set_title(f"mode {m + 1}: {'frequency' if row == 0 else 'damping ratio'} ({unit})", fontsize=9,
                         loc="left")
            ax.margins(x=0.2, y=0.15)          # room for the runs' names
            ax.grid(alpha=0.3)
        axes[1, m].set_xlabel("RMS response (m/s²)")
    fig.suptitle("each run's modes against its response amplitude (± one standard error)", fontsize=10)
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.11, top=0.87, hspace=0.35, wspace=0.3)
    return fig


def comparison_figure(rows: Sequence[tuple[str, float]], noise: float, trial: str) -> Figure:
    """The held-out NRMSE of each model on ``trial`` (``rows``: ``(label, nrmse)``, fractions) as bars, the
    ``noise`` alone (a fraction) as a line."""
    plt = pyplot()
    labels = [textwrap.fill(label, 34) for label, _ in rows]
    values = np.array([100 * v for _, v in rows])
    fig, ax = plt.subplots(figsize=(9, 0.6 * len(rows) + 1.3))
    y = np.arange(len(rows))[::-1]
    ax.barh(y, values, color=plt.get_cmap("tab10")(np.arange(len(rows)) % 10), height=0.6)
    for yi, v in zip(y, values):
        ax.text(v, yi, f" {v:.2f} %", va="center", fontsize=8)
    if np.isfinite(noise):   # the data check runs no noise estimate
        ax.axvline(100 * noise, color="black", lw=1, ls="--", label=f"sensor noise alone {100 * noise:.2f} %")
        ax.legend(fontsize=8, loc="lower right")
    ax.set_yticks(y, labels, fontsize=8)
    ax.set_xlabel(f"held-out trial {trial}: floor-acceleration NRMSE (%)")
    ax.set_xlim(0, 1.18 * max(float(values.max()), 100 * noise))
    ax.grid(alpha=0.3, axis="x")
    fig.subplots_adjust(left=0.3, right=0.97, bottom=0.8 / fig.get_figheight() + 0.05, top=0.95)
    return fig


def mismatch_figure(time: np.ndarray, measured: np.ndarray, models: dict, channel_nrmse: dict,
                    band: Sequence[float] | None = None, unit: str = "m/s²") -> Figure:
    """Where the held-out misfit sits.

    Parameters
    ----------
    time : ndarray, shape (n,)
        s (evenly sampled).
    measured : ndarray, shape (n, d)
    models : dict
        Label -> replay (n, d); the last one is the final model, whose residual spectrum is drawn.
    channel_nrmse : dict
        Sensor -> {label -> NRMSE (fraction)}, drawn as grouped bars.
    band : sequence of two float, optional
        The band (Hz) the diagnosis names, shaded.
    unit : str

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = pyplot()
    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 3.8), gridspec_kw={"width_ratios": [2, 3]})
    sensors = list(channel_nrmse)
    labels = list(next(iter(channel_nrmse.values())))
    width = 0.8 / len(labels)
    for k, label in enumerate(labels):
        left.bar(np.arange(len(sensors)) + (k - (len(labels) - 1) / 2) * width,
                 [100 * channel_nrmse[s][label] for s in sensors], width, label=label)
    left.set_xticks(np.arange(len(sensors)), [channel_words(s) for s in sensors], fontsize=8)
    left.set_ylabel("held-out NRMSE (%)")
    left.legend(fontsize=7)
    left.grid(alpha=0.3, axis="y")
    left.set_title("per sensor", fontsize=9, loc="left")
    fs = 1.0 / float(np.median(np.diff(time)))
    name, final = list(models.items())[-1]
    nperseg = int(min(1024, 2 ** np.floor(np.log2(max(measured.shape[0] // 4, 16)))))
    for j in range(measured.shape[1]):
        f, p = scipy.signal.welch(measured[:, j] - final[:, j], fs=fs, nperseg=nperseg)
        right.semilogy(f, p, lw=0.9, label=f"floor {j + 1} sensor")
    if band is not None:
        right.axvspan(band[0], band[1], color="tab:red", alpha=0.12, label="the band the diagnosis names")
    right.set_xlabel("frequency (Hz)")
    right.set_ylabel(f"PSD ({unit})²/Hz")
    right.set_title(f"spectrum of what the {name} leaves (recorded minus replay)", fontsize=9, loc="left")
    right.legend(fontsize=7)
    right.grid(alpha=0.3, which="both")
    fig.suptitle("where the held-out misfit sits", fontsize=10)
    fig.subplots_adjust(left=0.06, right=0.98, bottom=0.16, top=0.86, wspace=0.22)
    return fig


def shapes_figure(shapes: ArrayLike, frequency: ArrayLike, damping_ratio: ArrayLike | None = None) -> Figure:
    """Mode shapes (columns of ``shapes`` (d, modes), floor 1 first) against the floor, the table at 0; each
    titled with its ``frequency`` (Hz) and, when given, ``damping_ratio``."""
    plt = pyplot()
    shapes = np.asarray(shapes, float)
    d = shapes.shape[0]
    fig, axes = plt.subplots(1, shapes.shape[1], figsize=(2.6 * shapes.shape[1] + 0.8, 3.0), sharey=True,
                             squeeze=False)
    floors = np.arange(d + 1)
    for i, ax in enumerate(axes[0]):
        ax.plot(np.concatenate([[0.0], shapes[:, i]]), floors, "o-", color="tab:blue")
        ax.axvline(0, color="0.5", lw=0.6)
        words = f"mode {i + 1}: {frequency[i]:.3f} Hz"
        if damping_ratio is not None:
            words += f", {100 * damping_ratio[i]:.2f} %"
        ax.set_title(words, fontsize=9)
        ax.grid(alpha=0.3)
    axes[0, 0].set_yticks(floors, ["table", *(f"floor {j}" for j in range(1, d + 1))], fontsize=8)
    fig.subplots_adjust(left=0.12, right=0.98, bottom=0.12, top=0.85, wspace=0.15)
    return fig
