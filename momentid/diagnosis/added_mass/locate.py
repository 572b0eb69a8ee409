"""Stage 4 of the added-mass diagnosis: where and how model and recordings disagree (storey, runs, time, amplitude,
signature).

The floor-equation residual ``r = (M + dM) a + C v + K q`` (what the linear
model leaves unexplained, per floor) is summed from the roof down, giving the
**storey shear residual** ``V_s = sum_(i >= s) r_i``: a force acting across
storey ``s`` alone shows in ``V_s`` alone, so the storey a mismatch lives in is
the one whose ``V_s`` stands out from what sensor noise leaves (the same sums
of a noise-only residual).  On that storey the residual is then broken down by

* run (all runs? only the loaded ones? growing with the added mass?),
* time window (the strong motion? from some instant on?),
* drift amplitude (quartiles of the storey drift),
* frequency band (at the modes, or harmonics above them),

and compared with simple shapes: the sign of the drift velocity (a step at every
reversal: friction), the drift cubed (stiffening/softening), the drift times the
weight above (P-Delta).  Every number is a ratio to the noise-only level, so 1
means "nothing there".  This describes the mismatch; naming the physics is
:mod:`momentid.diagnosis.dispatch`'s job.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import os
from typing import TYPE_CHECKING

import numpy as np

from momentid.diagnosis.thresholds import EXCESS
from momentid.mechanisms.base import drifts
from momentid.mechanisms.coulomb_friction import SCREENING_SMOOTHING

if TYPE_CHECKING:
    from matplotlib.figure import Figure
    from momentid.diagnosis.added_mass.residuals import ResidualRow

__all__ = ["Localisation", "locate", "plot_localisation", "localisation_figure"]

#: Band of "the modes": from this fraction of the lowest natural frequency to ...
MODES_BELOW = 0.7
#: ... this multiple of the highest.
MODES_ABOVE = 1.3


@dataclass(frozen=True)
class Localisation:
    """Result of :func:`locate`; every excess is residual RMS / noise-only RMS."""

    storeys: dict             # "storey<s>" -> excess of the storey shear residual
    storey: int               # the storey where it is largest (1 = lowest)
    runs: dict                # run name -> excess on that storey
    windows: list             # [{"t0", "t1", "excess"}] on that storey, pooled over runs
    amplitude: list           # [{"drift_min", "drift_max", "excess"}] drift quartiles of that storey
    bands: dict               # "below_modes" / "modes" / "above_modes" -> excess
    signature: dict           # shape -> share of the storey residual's power it carries
    words: str

    def to_dict(self) -> dict:
        """The breakdown as ``report.json``'s ``localisation`` (what :func:`localisation_figure` draws)."""
        return {"storeys": self.storeys, "storey": self.storey, "runs": self.runs, "windows": self.windows,
                "amplitude": self.amplitude, "bands": self.bands, "signature": self.signature,
                "words": self.words}


def _shear(r: np.ndarray) -> np.ndarray:
    """Storey shears from floor forces (..., d): V_s = sum over floors i >= s."""
    return np.cumsum(r[..., ::-1], axis=-1)[..., ::-1]


def _ratio(x: np.ndarray, n: np.ndarray) -> float:
    rx, rn = float(np.sqrt(np.mean(x ** 2))), float(np.sqrt(np.mean(n ** 2)))
    return rx / rn if rn > 0 else (float("inf") if rx > 0 else 1.0)


def _share(v: np.ndarray, phi: np.ndarray) -> float:
    """Share of ``v``'s power that a least-squares multiple of ``phi`` carries."""
    pp, vv = float(phi @ phi), float(v @ v)
    if pp == 0 or vv == 0:
        return 0.0
    return float((phi @ v) ** 2 / (pp * vv))


def locate(rows: Sequence[ResidualRow], d: int, f_modes: tuple[float, float], *, window_s: float | None = None
           ) -> Localisation:
    """Break the equation residual down by storey, run, time, amplitude, band and shape.

    Parameters
    ----------
    rows : sequence of ResidualRow
        Per run (:class:`~momentid.diagnosis.added_mass.residuals.ResidualRow`): the band-limited signals
        (``'a'``, ``'v'``, ``'q'``, each (n, d)), the floor residual (n, d) of the model and the
        same residual of a noise-only input (n, d).
    d : int
        Storeys.
    f_modes : (float, float)
        Lowest and highest natural frequency (Hz) of the model.
    window_s : float, optional
        Time-window length (s); a tenth of the shortest run by default (at least 1 s).

    Returns
    -------
    Localisation
    """
    V = [_shear(row.residual) for row in rows]
    N = [_shear(row.noise) for row in rows]
    Vall, Nall = np.concatenate(V), np.concatenate(N)
    storeys = {f"storey{s + 1}": _ratio(Vall[:, s], Nall[:, s]) for s in range(d)}
    s = int(np.argmax([storeys[f"storey{k + 1}"] for k in range(d)]))
    runs = {row.run.name: _ratio(v[:, s], n[:, s]) for row, v, n in zip(rows, V, N)}

    fs = rows[0].run.sample_rate
    n_min = min(v.shape[0] for v in V)
    w = int(round((window_s or max(1.0, n_min / fs / 10)) * fs))
    windows = []
    for k0 in range(0, n_min - w // 2, w):
        k1 = min(k0 + w, n_min)
        windows.append({"t0": k0 / fs, "t1": k1 / fs,
                        "excess": _ratio(np.concatenate([v[k0:k1, s] for v in V]),
                                         np.concatenate([n[k0:k1, s] for n in N]))})

    drift = np.concatenate([drifts(row.signals["q"])[:, s] for row in rows])
    edges = np.quantile(np.abs(drift), [0.0, 0.25, 0.5, 0.75, 1.0])
    amplitude = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (np.abs(drift) >= lo) & (np.abs(drift) <= hi)
        amplitude.append({"drift_min": float(lo), "drift_max": float(hi),
                          "excess": _ratio(Vall[m, s], Nall[m, s])})

    bands = _bands(V, N, s, fs, f_modes)

    dvel = np.concatenate([drifts(row.signals["v"])[:, s] for row in rows])
    v = Vall[:, s] - np.mean(Vall[:, s])
    eps = SCREENING_SMOOTHING * float(np.sqrt(np.mean(dvel ** 2))) or 1.0
    above = np.concatenate([np.full(row.signals["q"].shape[0], float(np.sum(row.run.added_mass[s:])))
                            for row in rows])
    signature = {"drift_velocity_sign": _share(v, np.tanh(dvel / eps)),
                 "drift_velocity": _share(v, dvel),
                 "drift": _share(v, drift),
                 "drift_cubed": _share(v, drift ** 3),
                 "drift_x_added_weight_above": _share(v, drift * above)}
    loc = Localisation(storeys=storeys, storey=s + 1, runs=runs, windows=windows, amplitude=amplitude,
                       bands=bands, signature=signature, words="")
    return Localisation(**{**loc.__dict__, "words": _words(loc, rows)})


def _bands(V, N, s, fs, f_modes) -> dict:
    lo, hi = MODES_BELOW * f_modes[0], MODES_ABOVE * f_modes[1]
    out = {"below_modes": [0.0, 0.0], "modes": [0.0, 0.0], "above_modes": [0.0, 0.0]}
    for v, n in zip(V, N):
        f = np.fft.rfftfreq(v.shape[0], 1 / fs)
        pv, pn = np.abs(np.fft.rfft(v[:, s])) ** 2, np.abs(np.fft.rfft(n[:, s])) ** 2
        for name, m in (("below_modes", f < lo), ("modes", (f >= lo) & (f <= hi)), ("above_modes", f > hi)):
            out[name][0] += float(pv[m].sum())
            out[name][1] += float(pn[m].sum())
    return {k: (float(np.sqrt(a / b)) if b > 0 else 1.0) for k, (a, b) in out.items()}


def _lone_floor(rows) -> int | None:
    """The floor above the first whose equation residual stands out alone (more than twice every other
    floor's excess over noise, and above :data:`EXCESS`); None when none does.  A
    force on floor ``j`` alone (an attachment, a damper hung there) shows in the shear of every storey
    up to ``j``: the storeys cannot say where it is, the floors can."""
    r = np.concatenate([row.residual for row in rows])
    n = np.concatenate([row.noise for row in rows])
    floors = [_ratio(r[:, j], n[:, j]) for j in range(r.shape[1])]
    j = int(np.argmax(floors))
    others = floors[:j] + floors[j + 1:]
    if j == 0 or floors[j] <= EXCESS or not others or floors[j] <= 2 * max(others):
        return None
    return j + 1


def _words(loc: Localisation, rows) -> str:
    """One sentence in the lab's words."""
    worst = loc.storeys[f"storey{loc.storey}"]
    if worst <= EXCESS:
        return "No storey's residual stands out from the noise."
    others = [v for k, v in loc.storeys.items() if k != f"storey{loc.storey}"]
    where = (f"concentrated in storey {loc.storey}" if not others or worst > 2 * max(others)
             else f"largest in storey {loc.storey}")
    parts = [f"Mismatch {where} ({worst:.1f}x noise)"]
    floor = _lone_floor(rows)
    if floor is not None:   # a force on one floor above the first: every storey below it carries it
        parts = [f"Mismatch on floor {floor} alone (the shear of every storey below it carries it, storey "
                 f"{loc.storey} most: {worst:.1f}x noise)"]
    sig = loc.signature
    shapes = {"drift_velocity_sign": "jumps with the sign of the drift velocity (a step at every reversal)",
              "drift_cubed": "grows with the drift cubed",
              "drift_x_added_weight_above": "grows with the drift times the added weight above",
              "drift_velocity": "follows the drift velocity",
              "drift": "follows the drift"}
    best = max(shapes, key=lambda k: sig[k])
    if sig[best] > 0.3:
        parts.append(shapes[best])
    amp = [b["excess"] for b in loc.amplitude]
    if amp[-1] > 2 * max(amp[0], 1.0):
        parts.append("largest at the largest drifts")
    mass = {row.run.name: float(np.sum(row.run.added_mass)) for row in rows}
    hit = [name for name, x in loc.runs.items() if x > EXCESS]
    if len(hit) == len(loc.runs):
        names = sorted(loc.runs, key=lambda k: mass[k])
        ex = [loc.runs[k] for k in names]
        if len(ex) > 2 and ex[-1] > 1.5 * ex[0] and all(b >= a for a, b in zip(ex, ex[1:])):
            parts.append("present in all runs, growing with the added mass")
        else:
            parts.append("present in all runs")
    elif hit and all(mass[k] > 0 for k in hit):
        parts.append("only in the runs with added mass (" + ", ".join(hit) + ")")
    elif hit:
        parts.append("in runs " + ", ".join(hit))
    win = [w["excess"] for w in loc.windows]
    if len(win) >= 4:
        k = int(np.argmax([np.mean(win[i:]) / max(np.mean(win[:i]), 1e-12) for i in range(1, len(win))])) + 1
        if np.mean(win[:k]) <= EXCESS < np.mean(win[k:]) and min(win[k:]) > 1.5 * max(win[:k]):
            parts.append(f"from t = {loc.windows[k]['t0']:.0f} s on")
    if loc.bands["above_modes"] > 2 * EXCESS and loc.bands["above_modes"] > 0.5 * loc.bands["modes"]:
        parts.append("with harmonics above the modes")
    return ", ".join(parts) + "."


def localisation_figure(where: dict, title: str = "") -> Figure:
    """The storey shear residual over noise by storey, run, time and drift amplitude (a matplotlib figure).

    Parameters
    ----------
    where : dict
        :meth:`Localisation.to_dict` (as stored in ``report.json``).
    title : str
        Default: the localisation in words.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 4, figsize=(14, 3.2))
    s = where["storey"]
    names = list(where["storeys"])
    ax[0].bar([n.replace("storey", "") for n in names], [where["storeys"][n] for n in names],
              color=["C3" if n == f"storey{s}" else "C0" for n in names])
    ax[0].set_xlabel("storey")
    ax[0].set_title("by storey")
    runs = list(where["runs"])
    ax[1].bar(runs, [where["runs"][r] for r in runs], color="C1")
    ax[1].set_title(f"storey {s}: by run")
    ax[1].tick_params(axis="x", rotation=30)
    mid = [(w["t0"] + w["t1"]) / 2 for w in where["windows"]]
    ax[2].plot(mid, [w["excess"] for w in where["windows"]], "o-", color="C2")
    ax[2].set_xlabel("time in run (s)")
    ax[2].set_title(f"storey {s}: by time window")
    amp = where["amplitude"]
    ax[3].bar([f"{1e3 * a['drift_min']:.2g}-\n{1e3 * a['drift_max']:.2g}" for a in amp],
              [a["excess"] for a in amp], color="C4")
    ax[3].tick_params(axis="x", labelsize=7)
    ax[3].set_xlabel("|drift| quartile (mm)")
    ax[3].set_title(f"storey {s}: by drift amplitude")
    for a in ax:
        a.axhline(EXCESS, color="grey", ls=":", lw=1)
        a.set_ylabel("residual / noise")
        a.set_yscale("log")
        a.set_ylim(bottom=0.5)   # 1 = the noise level: keep it in view
    fig.suptitle(title or where["words"], fontsize=9)
    fig.tight_layout()
    return fig


def plot_localisation(where: dict, path: str | os.PathLike, title: str = "") -> None:
    """``locate.png``: :func:`localisation_figure` as a PNG."""
    import matplotlib.pyplot as plt

    fig = localisation_figure(where, title)
    fig.savefig(path, dpi=90)
    plt.close(fig)
