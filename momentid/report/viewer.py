"""Inspect an experiment in the rerun viewer.

One rerun recording per experiment, with a blueprint made in code so it
opens ready to read:

- one tab per run (``/runs/<run>/...``): a 3D view of the shake table and the
  floors as boxes moving with the recorded displacements (or, for a real
  rig that records accelerations only, displacements reconstructed from
  them by band-limited double integration: :func:`displacements_from_accelerations`),
  drawn exaggerated
  by a factor stated in the view's title, on its scale bar and in the
  experiment notes; beside it the time series of that run (base
  acceleration, floor accelerations, displacements, velocities) and the
  per-floor equation residual of the identified model;
- identified vs. analytic parameters as a markdown table, a bar chart of
  their relative errors (bar k is row k of the table), and the natural
  frequencies and damping ratios of both models.

Every run shares the timeline ``time`` (seconds of experiment time, each run
starting at its own t = 0), so switching tabs keeps the time cursor and the
runs can be compared at the same instant.  Whole series are sent with
``send_columns``; ``rerun`` is imported inside the functions, so the rest of
momentid works without it.

Entity paths::

    /experiment                       markdown: scenario, runs, exaggeration, notes
    /runs/<run>/rig/base              table box; Transform3D x = X z(t)
    /runs/<run>/rig/base/floor<i>     floor slab; Transform3D x = X q_i(t), at its height
    /runs/<run>/rig/base/storey<i>    columns of storey i, sheared by the storey drift
    /runs/<run>/rig/scale             arrow: a true displacement and its drawn length
    /runs/<run>/sensors/<channel>     Scalars, one per recorded channel (zdd, z, a1, q1, ...)
    /runs/<run>/reconstructed/<c>     Scalars, z and q1..qd reconstructed from accelerations (m)
    /runs/<run>/residual/r<i>         Scalars, equation residual of floor i (N)
    /identification/parameters        markdown table of the parameters
    /identification/modes             markdown table of frequencies and damping ratios
    /identification/rel_error         BarChart of the relative errors
"""

from __future__ import annotations

import json
import math
import os
import shutil
import socket
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.signal

from momentid.core.series import Experiment, RunData, channel_unit
from momentid.errors import IdentificationError, SensorDataError, ViewerError
from momentid.io.exclusive import write_whole

__all__ = ["Scene", "auto_exaggeration", "displacements_from_accelerations", "DISPLACEMENT_HIGHPASS", "load_result", "check_result", "prepare", "blueprint",
           "log_scene", "write_rrd", "show", "view", "rig_samples", "log_rig", "TIMELINE", "APPLICATION_ID", "RIG_RATE"]

#: The timeline of every run: seconds of experiment time.
TIMELINE = "time"
APPLICATION_ID = "momentid"
#: The 3D rig is drawn at most this often (Hz): every k-th sample, exact at those instants
#: (the viewer animates at screen rate; the time series keep every sample).
RIG_RATE = 100.0
_PALETTE = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
            (140, 86, 75), (227, 119, 194), (188, 189, 34), (23, 190, 207), (127, 127, 127)]
#: High-pass corner (Hz) of displacements reconstructed from accelerations.  Double
#: integration multiplies a sensor's slowly wandering bias by 1/(2 pi f)^2: below this
#: corner that drift swamps the motion.  0.3 Hz keeps a 1 Hz table sine (the slowest shipped
#: trial) and every mode of a bench-top rig, and is the lower edge of the import's alignment band.
DISPLACEMENT_HIGHPASS = 0.3
#: Order of the zero-phase high-pass (the magnitude of a Butterworth of this order, squared).
DISPLACEMENT_ORDER = 4
_BASE_COLOR = (110, 110, 110)
_TABLE_COLOR = (120, 120, 130)
#: Time-series views of a run tab: (title, base channel, floor prefix).
_SERIES_VIEWS = (
    ("base acceleration zdd", "zdd", None),
    ("floor absolute accelerations a", None, "a"),
    ("displacements: table z, floors q relative to it", "z", "q"),
    ("velocities: table zd, floors v relative to it", "zd", "v"),
)


@dataclass
class Scene:
    """Everything shown for one experiment, computed once.

    Attributes
    ----------
    experiment : Experiment
    exaggeration : float
        Drawn displacement / true displacement in the 3D views.
    active_run : int
        Index of the run whose tab opens first.
    result : Identification or None
    comparison : Comparison or None
        Only with a result and a nominal structure in the recording.
    residuals : dict of str to ndarray, shape (n, d)
        Equation residual (N) per run, when the run has ``a``, ``q``, ``v``.
    notes : list of str
        What could not be shown, and why.
    overlay : object, optional
        A layer shown beside each run and in the side column (the twin: :class:`momentid.twin.overlay.TwinOverlay`):
        ``spatial_views(scene, run)``, ``series_views(scene, run)``, ``side_views()`` give its blueprint views,
        ``log(rec, scene, run)`` and ``log_static(rec)`` its data.
    """

    experiment: Experiment
    exaggeration: float
    active_run: int = 0
    result: object = None
    comparison: object = None
    residuals: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    reconstructed: dict = field(default_factory=dict)
    overlay: object = None

    @property
    def heights(self) -> np.ndarray:
        """Storey heights (m): the structure's, else the lab statement's, else 0.3 m each."""
        d = self.experiment.storeys
        s, stated = self.experiment.structure, self.experiment.statement
        for heights in (s.storey_heights if s is not None else None,
                        stated.storey_heights if stated is not None else None):
            if heights is not None and len(heights) == d:
                return np.asarray(heights, float)
        return np.full(d, 0.3)

    def drawn(self, run: RunData) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Table displacement z (n,) and floor displacements q (n, d) relative to it (m) as drawn:
        recorded, else reconstructed from the accelerations, else None."""
        d = self.experiment.storeys
        z_rec, q_rec = self.reconstructed.get(run.name, (None, None))
        z = run["z"] if run.has("z") else z_rec
        q = _floor_group(run, "q", d)
        return z, (q if q is not None else q_rec)


def displacements_from_accelerations(acc: np.ndarray, dt: float,
                                     highpass: float = DISPLACEMENT_HIGHPASS) -> np.ndarray:
    """Displacements from accelerations by band-limited double integration, without drift.

    In the frequency domain ``X(f) = -A(f) / (2 pi f)^2 H(f)`` with ``H`` the
    zero-phase high-pass ``1 / (1 + (highpass / f)^(2 n))`` (the squared
    magnitude of an order-``n`` Butterworth, :data:`DISPLACEMENT_ORDER`), so a
    constant or slowly drifting bias gives no ramp.  The record is zero-padded
    to twice its length against wrap-around after removing the least-squares
    line (a sensor's bias and its linear drift); ``nan`` samples count as 0 m/s^2.

    Parameters
    ----------
    acc : ndarray, shape (n,) or (n, k)
        Accelerations (m/s^2), time-first.
    dt : float
        Sample interval (s).
    highpass : float
        Corner (Hz) below which motion is dropped.

    Returns
    -------
    ndarray, same shape as ``acc``
        Displacements (m).
    """
    a = scipy.signal.detrend(np.nan_to_num(np.asarray(acc, float)), axis=0)  # bias and its linear drift
    n = a.shape[0]
    f = np.fft.rfftfreq(2 * n, dt)
    gain = np.zeros_like(f)
    f_pos = f[1:]
    gain[1:] = -1.0 / ((2 * np.pi * f_pos) ** 2 * (1.0 + (highpass / f_pos) ** (2 * DISPLACEMENT_ORDER)))
    spectrum = np.fft.rfft(a, n=2 * n, axis=0)
    shape = (-1,) + (1,) * (a.ndim - 1)
    return np.fft.irfft(spectrum * gain.reshape(shape), n=2 * n, axis=0)[:n]


def _reconstruct(run: RunData, d: int) -> tuple[np.ndarray, np.ndarray] | None:
    """``(z, q)`` of a run that records ``zdd`` and ``a1..ad`` but no ``q``: from the accelerations."""
    a = _floor_group(run, "a", d)
    if a is None or not run.has("zdd") or _floor_group(run, "q", d) is not None or run.n_samples < 4:
        return None
    dt = float(run.time[1] - run.time[0])
    x = displacements_from_accelerations(np.column_stack([run["zdd"], a]), dt)
    return x[:, 0], x[:, 1:] - x[:, :1]


def _floor_group(run: RunData, prefix: str, d: int) -> np.ndarray | None:
    names = [f"{prefix}{i + 1}" for i in range(d)]
    return run.group(prefix, d) if all(run.has(n) for n in names) else None


def _nice(x: float) -> float:
    """Largest 1-2-5 number not above ``x``."""
    decade = 10.0 ** math.floor(math.log10(x))
    return next(m * decade for m in (5, 2, 1) if m * decade <= x)


#: Largest exaggeration / the default one (which draws the largest displacement at about a fifth of
#: the building height): 1e4 draws it 2000 building heights away, where nothing is left to see (and
#: beyond, the viewer's float32 positions overflow).
MAX_EXAGGERATION = 1e4


def auto_exaggeration(experiment: Experiment, heights=None, reconstructed: dict | None = None) -> float:
    """A 1-2-5 factor that draws the largest recorded displacement at about a
    fifth of the building height (never below 1).

    Parameters
    ----------
    experiment : Experiment
    heights : array_like, optional
        Storey heights (m); default 0.3 m each.
    reconstructed : dict, optional
        ``{run name: (z, q)}`` displacements drawn for runs that record none.

    Returns
    -------
    float
    """
    d = experiment.storeys
    height = float(np.sum(heights)) if heights is not None else 0.3 * d
    peak = 0.0
    for run in experiment.runs:
        z_rec, q_rec = (reconstructed or {}).get(run.name, (None, None))
        q = _floor_group(run, "q", d)
        q = q if q is not None else q_rec
        z = run["z"] if run.has("z") else z_rec if z_rec is not None else np.zeros(run.n_samples)
        absolute = z[:, None] + (q if q is not None else 0.0)
        peak = max(peak, float(np.max(np.abs(z), initial=0.0)), float(np.max(np.abs(absolute), initial=0.0)))
    if not math.isfinite(peak) or peak <= 0.0:
        return 1.0
    return max(1.0, _nice(0.2 * height / peak))


def load_result(path, experiment: Experiment):
    """Read an identification saved by ``momentid identify --json``.

    Parameters
    ----------
    path : str or Path
        The JSON file.
    experiment : Experiment
        The recording it must belong to (checked by :func:`check_result`).

    Returns
    -------
    Identification

    Raises
    ------
    ViewerError
        The file is missing or not such a JSON object, or belongs to another recording.
    """
    from momentid.estimation.identified import Identification

    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise ViewerError(f"{path}: result file not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ViewerError(f"{path}: not a JSON result of `momentid identify --json` ({exc})") from None
    missing = [k for k in ("M", "C", "K", "mu", "kappa", "runs") if not isinstance(data, dict) or k not in data]
    if missing:
        raise ViewerError(f"{path}: not a result of `momentid identify --json`: missing "
                          f"{', '.join(missing)} (expected keys M, C, K, mu, kappa, runs)")

    def number(key, default=math.nan):
        value = data.get(key)
        return default if value is None else value

    try:
        M, C, K = (np.asarray(data[k], float) for k in ("M", "C", "K"))
        d = M.shape[0] if M.ndim == 2 else -1
        if any(m.shape != (d, d) for m in (M, C, K)):
            raise ValueError(f"M, C, K have shapes {M.shape}, {C.shape}, {K.shape}, expected square and equal")
        result = Identification(
            M=M, C=C, K=K, mu=float(data["mu"]), kappa=float(data["kappa"]),
            damping_misfit=float(number("damping_misfit")), estimator=str(data.get("estimator", "?")),
            n_equations=int(number("n_equations", 0)), n_unknowns=int(number("n_unknowns", 0)),
            rank=int(number("rank", 0)), condition=float(number("condition")),
            residual_rms=float(number("residual_rms")), runs=tuple(str(r) for r in data["runs"]),
        )
    except (TypeError, ValueError) as exc:
        raise ViewerError(f"{path}: not a result of `momentid identify --json`: {exc}") from None
    check_result(result, experiment, source=str(path))
    return result


def check_result(result, experiment: Experiment, source: str = "result") -> None:
    """Refuse a result that does not belong to ``experiment`` (storeys, run names).

    Raises
    ------
    ViewerError
    """
    names = [r.name for r in experiment.runs]
    if result.storeys != experiment.storeys:
        raise ViewerError(f"{source}: the result is for {result.storeys} storeys but {experiment.source} "
                          f"records {experiment.storeys}: it belongs to another recording")
    unknown = [r for r in result.runs if r not in names]
    if unknown:
        raise ViewerError(f"{source}: runs {', '.join(unknown)} are not in {experiment.source} (its runs: "
                          f"{', '.join(names)}): the result belongs to another recording")


def prepare(experiment: Experiment, *, result=None, exaggeration: float | None = None,
            run: str | None = None, identify_options: dict | None = None, identify: bool = True) -> Scene:
    """Identify (unless ``result`` is given), compare and collect what to show.

    Parameters
    ----------
    experiment : Experiment
    result : Identification, optional
        Shown instead of identifying again; must belong to ``experiment``.
    exaggeration : float, optional
        Drawn / true displacement; default :func:`auto_exaggeration`.
    run : str, optional
        The run whose tab opens first (default: the first run).
    identify_options : dict, optional
        Keyword arguments of :func:`momentid.estimation.identification` (estimator, runs, times).
    identify : bool
        Identify when no ``result`` is given (False: show none, e.g. beside a twin that carries its own).

    Returns
    -------
    Scene

    Raises
    ------
    ViewerError
        Bad exaggeration, unknown run name, or a result of another recording.
    """
    from momentid.estimation.comparison import compare
    from momentid.estimation.equation_form import equation_residual
    from momentid.estimation.identification import identify as identify_experiment

    names = [r.name for r in experiment.runs]
    if run is not None and run not in names:
        raise ViewerError(f"{experiment.source}: no run named {run!r}; runs are {', '.join(names)}")
    if exaggeration is not None and not (math.isfinite(exaggeration) and exaggeration > 0):
        raise ViewerError(f"exaggeration must be a positive number, got {exaggeration!r}")
    scene = Scene(experiment, exaggeration=1.0, active_run=names.index(run) if run else 0)
    for r in experiment.runs:
        got = _reconstruct(r, experiment.storeys)
        if got is not None:
            scene.reconstructed[r.name] = got
    default = auto_exaggeration(experiment, scene.heights, scene.reconstructed)
    if exaggeration is not None and exaggeration > MAX_EXAGGERATION * default:
        raise ViewerError(f"exaggeration = {exaggeration!r}: would draw the largest displacement at about "
                          f"{exaggeration / default / 5:.3g} building heights; expected at most "
                          f"{MAX_EXAGGERATION * default:g} (the default here is {default:g})")
    scene.exaggeration = exaggeration if exaggeration is not None else default
    if result is not None:
        check_result(result, experiment)
    elif not identify:
        scene.notes.append("not identified: the twin's parameters are shown instead")
    else:
        try:
            result = identify_experiment(experiment, **(identify_options or {}))
        except (IdentificationError, SensorDataError) as exc:
            scene.notes.append(f"not identified: {exc}")
    scene.result = result
    if result is not None:
        if experiment.structure is not None and not _is_modal(result):
            scene.comparison = compare(result, experiment.structure)
        else:
            scene.notes.append("the recording holds no nominal structure: no analytic comparison")
        for r in experiment.runs:
            if _is_modal(result):
                break  # a modal fit of acceleration records has no eq. (3) residual to draw
            try:
                scene.residuals[r.name] = equation_residual(result, r)
            except SensorDataError as exc:
                scene.notes.append(f"no residual for run {r.name!r}: {exc}")
    d = experiment.storeys
    for r in experiment.runs:
        if r.name in scene.reconstructed:
            scene.notes.append(f"run {r.name!r} records accelerations only: the 3D view draws displacements "
                               f"reconstructed from them (double integration above {DISPLACEMENT_HIGHPASS:g} Hz, "
                               f"drift-free; slower motion is not drawn)")
            continue
        if _floor_group(r, "q", d) is None:
            scene.notes.append(f"run {r.name!r} has no q1..q{d}: its floors are drawn at rest on the table")
        if not r.has("z"):
            scene.notes.append(f"run {r.name!r} has no z: its table is drawn at rest")
    for r in experiment.runs:
        scene.notes += [f"run {r.name!r}: {n}" for n in r.meta.get("notes", ())]
    return scene


def _run_path(run: str) -> str:
    import rerun as rr

    return f"/runs/{rr.escape_entity_path_part(run)}"


def _series_paths(scene: Scene, run: RunData, base: str | None, prefix: str | None) -> list[str]:
    root = _run_path(run.name)
    chans = [base] if base else []
    chans += [f"{prefix}{i + 1}" for i in range(scene.experiment.storeys)] if prefix else []
    return [f"{root}/sensors/{c}" for c in chans if run.has(c)]


def blueprint(scene: Scene):
    """The layout: run tabs (3D + time series) beside the identification column.

    Returns
    -------
    rerun.blueprint.Blueprint
    """
    import rerun.blueprint as rrb

    def legend(visible: bool):
        return rrb.PlotLegend(rrb.Corner2D.RightTop, visible=visible)

    total = float(scene.heights.sum())
    tabs = []
    for run in scene.experiment.runs:
        root = _run_path(run.name)
        eye = rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=[0.9 * total, -1.9 * total, 0.8 * total],
                                look_target=[0.0, 0.0, 0.45 * total], eye_up=[0.0, 0.0, 1.0])
        views = [rrb.TimeSeriesView(name=f"{run.name}: {title} ({channel_unit(base or prefix + '1')})",
                                    contents=paths, plot_legend=legend(len(paths) > 1))
                 for title, base, prefix in _SERIES_VIEWS
                 if (paths := _series_paths(scene, run, base, prefix))]
        if run.name in scene.reconstructed:
            views.append(rrb.TimeSeriesView(
                name=f"{run.name}: displacements reconstructed from accelerations: table z, floors q (m)",
                origin=f"{root}/reconstructed", plot_legend=legend(True)))
        if run.name in scene.residuals:
            views.append(rrb.TimeSeriesView(name=f"{run.name}: equation residual of the identified model (N)",
                                            origin=f"{root}/residual", plot_legend=legend(True)))
        spatial = [rrb.Spatial3DView(origin=f"{root}/rig", eye_controls=eye,
                                     name=f"{run.name}: building, displacements drawn x{scene.exaggeration:g}")]
        if scene.overlay is not None:
            spatial += scene.overlay.spatial_views(scene, run, eye)
            views += scene.overlay.series_views(scene, run)
        tabs.append(rrb.Horizontal(
            rrb.Vertical(*spatial) if len(spatial) > 1 else spatial[0], rrb.Vertical(*views),
            column_shares=[2, 3], name=f"run {run.name}",
        ))
    side = [rrb.Tabs(rrb.TextDocumentView(origin="/identification/parameters", name="identified vs. analytic"),
                     rrb.TextDocumentView(origin="/experiment", name="experiment"),
                     active_tab=0 if scene.result is not None else 1)]
    if scene.result is not None:
        side.append(rrb.TextDocumentView(origin="/identification/modes", name="modes: frequency, damping"))
    if scene.comparison is not None:
        side.append(rrb.BarChartView(origin="/identification/rel_error",
                                     name="relative error per parameter (bar k = row k)",
                                     plot_legend=rrb.PlotLegend(visible=False)))
    shares = [3.0, 1.3, 1.6][:len(side)]
    if scene.overlay is not None:
        extra = scene.overlay.side_views()
        side, shares = side + extra, shares + [2.0] * len(extra)
    layout = rrb.Horizontal(rrb.Tabs(*tabs, active_tab=scene.active_run),
                            rrb.Vertical(*side, row_shares=shares), column_shares=[5, 2])
    return rrb.Blueprint(layout, rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"),
                         rrb.TimePanel(state="collapsed", timeline=TIMELINE, play_state="paused"), auto_views=False)


def rig_samples(run: RunData) -> np.ndarray:
    """Indices of the samples the 3D rig is drawn at (at most :data:`RIG_RATE` per second)."""
    rate = run.sample_rate
    step = max(1, int(math.floor(rate / RIG_RATE))) if math.isfinite(rate) else 1
    return np.arange(0, run.n_samples, step)


def log_rig(rec, scene: Scene, run: RunData, root: str | None = None, motion=None) -> None:
    """Draw the rig of ``run`` moving: table and floors, at ``root`` (default ``/runs/<run>/rig``),
    with ``motion = (z, q)`` (table displacement (n,), floors relative to it (n, d), m; default: the
    recording's, :meth:`Scene.drawn`)."""
    import rerun as rr

    d, X = scene.experiment.storeys, scene.exaggeration
    h = scene.heights
    level = np.concatenate([[0.0], np.cumsum(h)])
    w = float(h.max())
    root = root or f"{_run_path(run.name)}/rig"
    idx = rig_samples(run)
    n = idx.size
    time = rr.TimeColumn(TIMELINE, duration=run.time[idx])
    zero = np.zeros(n)
    z, q = scene.drawn(run) if motion is None else motion
    z = zero if z is None else z[idx]
    q = np.zeros((n, d)) if q is None else q[idx]
    rec.log(root, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log(f"{root}/base", rr.Boxes3D(centers=[[0, 0, -0.04 * w]], half_sizes=[[0.9 * w, 0.6 * w, 0.04 * w]],
                                       colors=[_TABLE_COLOR], labels=[f"shake table (x{X:g})"],
                                       fill_mode="solid"), static=True)
    rec.send_columns(f"{root}/base", indexes=[time],
                     columns=rr.Transform3D.columns(translation=np.column_stack([X * z, zero, zero])))
    posts = np.array([[sx * 0.45 * w, sy * 0.3 * w] for sx in (-1, 1) for sy in (-1, 1)])
    for i in range(d):
        color = _PALETTE[i % len(_PALETTE)]
        below = q[:, i - 1] if i else zero
        rec.log(f"{root}/base/floor{i + 1}",
                rr.Boxes3D(half_sizes=[[0.5 * w, 0.35 * w, 0.03 * w]], colors=[color], fill_mode="solid",
                           labels=[f"floor {i + 1}"]), static=True)
        rec.send_columns(f"{root}/base/floor{i + 1}", indexes=[time], columns=rr.Transform3D.columns(
            translation=np.column_stack([X * q[:, i], zero, np.full(n, level[i + 1])])))
        rec.log(f"{root}/base/storey{i + 1}",
                rr.Boxes3D(centers=np.column_stack([posts, np.full(4, h[i] / 2)]),
                           half_sizes=[[0.01 * w, 0.01 * w, h[i] / 2]] * 4, colors=[color], fill_mode="solid"),
                static=True)
        shear = np.tile(np.eye(3), (n, 1, 1))
        shear[:, 0, 2] = X * (q[:, i] - below) / h[i]
        rec.send_columns(f"{root}/base/storey{i + 1}", indexes=[time], columns=rr.Transform3D.columns(
            translation=np.column_stack([X * below, zero, np.full(n, level[i])]), mat3x3=shear))
    peak = float(np.max(np.abs(z[:, None] + q), initial=0.0))  # of the drawn samples
    true = _nice(peak) if peak > 0 else 0.01 / X
    rec.log(f"{root}/scale", rr.Arrows3D(origins=[[-0.5 * w, -0.7 * w, 0.0]], vectors=[[X * true, 0.0, 0.0]],
                                         colors=[_BASE_COLOR], labels=[f"{true * 1e3:g} mm x{X:g}"]),
            static=True)


def _log_series(rec, entity: str, time, values: np.ndarray, name: str, color) -> None:
    import rerun as rr

    rec.log(entity, rr.SeriesLines(names=name, colors=[color]), static=True)
    rec.send_columns(entity, indexes=[time], columns=rr.Scalars.columns(scalars=values))


def _channel_label(channel: str) -> tuple[str, tuple]:
    group = channel.rstrip("0123456789")
    if group != channel:
        i = int(channel[len(group):])
        return f"{channel}: floor {i} ({channel_unit(channel)})", _PALETTE[(i - 1) % len(_PALETTE)]
    return f"{channel}: table ({channel_unit(channel)})", _BASE_COLOR


def _fmt(x: float) -> str:
    return f"{x:.6g}" if math.isfinite(x) else "n/a"


def _is_modal(result) -> bool:
    """True for the modal fit of runs without added mass (it has no M, mu, kappa of eq. (3))."""
    from momentid.estimation.scaled import ModalIdentification

    return isinstance(result, ModalIdentification)


def _parameters_markdown(scene: Scene) -> str:
    r = scene.result
    if r is None:
        return "# Identification\n\n" + "\n\n".join(n for n in scene.notes if n.startswith("not identified"))
    if _is_modal(r):  # no added mass: modes, and K, C only when the lab states its masses
        return f"# Identification of {scene.experiment.name}\n\n```\n{r.table()}\n```"
    lines = [f"# Identification of {scene.experiment.name}", "",
             f"estimator **{r.estimator}**, runs {', '.join(r.runs)}: {r.n_equations} equations, "
             f"{r.n_unknowns} unknowns, rank {r.rank}, condition {r.condition:.3g}, residual RMS "
             f"{r.residual_rms:.3g} N, Rayleigh misfit of C {r.damping_misfit:.2e}", ""]
    c = scene.comparison
    if c is None:
        lines += ["| parameter | identified |", "|---|---:|"]
        lines += [f"| {k} | {_fmt(float(v))} |" for k, v in (("mu (1/s)", r.mu), ("kappa (s)", r.kappa))]
        lines += [f"| {m}[{i + 1},{j + 1}] | {_fmt(float(getattr(r, m)[i, j]))} |"
                  for m in "MCK" for i in range(r.storeys) for j in range(i, r.storeys)]
        return "\n".join(lines)
    worst = max(c.entries, key=lambda e: e.rel_error)
    lines += ["| # | parameter | unit | identified | analytic | rel. error |", "|---:|---|---|---:|---:|---:|"]
    lines += [f"| {k + 1} | {e.name} | {e.unit} | {_fmt(e.identified)} | {_fmt(e.analytic)} | {e.rel_error:.2e} |"
              for k, e in enumerate(c.entries)]
    lines += ["", f"largest relative error: **{worst.rel_error:.2e}** ({worst.name})"]
    return "\n".join(lines)


def _modes_markdown(scene: Scene) -> str:
    ident = scene.result.modes()
    an = scene.comparison.analytic_modes if scene.comparison is not None else None
    lines = ["| mode | f identified (Hz) | f analytic (Hz) | zeta identified | zeta analytic |",
             "|---:|---:|---:|---:|---:|"]
    for k in range(len(ident.frequency)):
        fa, za = (an.frequency[k], an.damping_ratio[k]) if an is not None else (math.nan, math.nan)
        lines.append(f"| {k + 1} | {ident.frequency[k]:.5f} | {fa:.5f} | {ident.damping_ratio[k]:.5f} | {za:.5f} |")
    return "\n".join(lines).replace("nan", "n/a")


def _experiment_markdown(scene: Scene) -> str:
    e = scene.experiment
    s = e.scenario
    lines = [f"# {e.name}", "", str(s.get("description", "")), "",
             f"recording `{e.source}`; {len(e.runs)} runs, {e.storeys} storeys",
             "", f"**3D views: every displacement is drawn x{scene.exaggeration:g}** (table and floors); "
             "the arrow in front of the table is the true displacement of its label, drawn at that scale.", "",
             "| run | added mass per floor (kg) | samples | duration (s) |", "|---|---|---:|---:|"]
    lines += [f"| {r.name} | {', '.join(f'{m:g}' for m in r.added_mass)} | {r.n_samples} | "
              f"{r.time[-1] - r.time[0]:g} |" for r in e.runs]
    notes = list(e.notes) + scene.notes
    if notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in notes]
    return "\n".join(lines)


def log_scene(rec, scene: Scene) -> None:
    """Send everything of ``scene`` to the recording stream ``rec`` (series via ``send_columns``)."""
    import rerun as rr

    md = rr.MediaType.MARKDOWN
    rec.send_recording_name(scene.experiment.name)
    rec.log("/experiment", rr.TextDocument(_experiment_markdown(scene), media_type=md), static=True)
    rec.log("/identification/parameters", rr.TextDocument(_parameters_markdown(scene), media_type=md), static=True)
    if scene.result is not None:
        rec.log("/identification/modes", rr.TextDocument(_modes_markdown(scene), media_type=md), static=True)
    if scene.overlay is not None:
        scene.overlay.log_static(rec)
    if scene.comparison is not None:
        errors = np.array([e.rel_error for e in scene.comparison.entries])
        rec.log("/identification/rel_error",
                rr.BarChart(errors, abscissa=np.arange(1, errors.size + 1, dtype=float), color=_PALETTE[3]),
                static=True)
    for run in scene.experiment.runs:
        root = _run_path(run.name)
        log_rig(rec, scene, run)
        if scene.overlay is not None:
            scene.overlay.log(rec, scene, run)
        time = rr.TimeColumn(TIMELINE, duration=run.time)
        for channel in run.channels:
            name, color = _channel_label(channel)
            _log_series(rec, f"{root}/sensors/{channel}", time, run[channel], name, color)
        if run.name in scene.reconstructed:
            z, q = scene.reconstructed[run.name]
            _log_series(rec, f"{root}/reconstructed/z", time, z, "z: table (m)", _BASE_COLOR)
            for i, column in enumerate(q.T):
                _log_series(rec, f"{root}/reconstructed/q{i + 1}", time, column, f"q{i + 1}: floor {i + 1} (m)",
                            _PALETTE[i % len(_PALETTE)])
        for i, column in enumerate(scene.residuals.get(run.name, np.empty((0, 0))).T):
            _log_series(rec, f"{root}/residual/r{i + 1}", time, column, f"floor {i + 1} (N)",
                        _PALETTE[i % len(_PALETTE)])


def write_rrd(experiment, path, **options) -> Path:
    """Write an experiment with its blueprint to a ``.rrd`` file (no viewer needed).

    Parameters
    ----------
    experiment : Experiment or Scene
        What to write; an experiment is first passed through :func:`prepare`.
    path : str or Path
        The ``.rrd`` file (parent folders are created).
    **options
        Keyword arguments of :func:`prepare` (result, exaggeration, run, identify_options).

    Returns
    -------
    Path

    Raises
    ------
    ViewerError
        The file cannot be written (or see :func:`prepare`).
    """
    import rerun as rr

    scene = experiment if isinstance(experiment, Scene) else prepare(experiment, **options)
    path = Path(path)
    # Logged to memory and written here, not by rerun's own file sink: that one writes from a
    # background thread and drops a write error (a full disk) silently, leaving a truncated file.
    rec = rr.RecordingStream(APPLICATION_ID)
    stream = rec.binary_stream()
    try:
        rec.send_blueprint(blueprint(scene), make_active=False, make_default=True)
        log_scene(rec, scene)
        data = stream.read(flush=True) or b""
    finally:
        rec.disconnect()
    _write_file(path, data)
    return path


def _write_file(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` whole or not at all (a temporary file renamed into place)."""
    try:
        write_whole(path, data)   # locked: a second writer of the same file is refused
    except OSError as exc:
        raise ViewerError(f"{path}: cannot write the rerun recording ({exc.strerror or exc}); "
                          f"expected a writable path with {len(data) / 1e6:.3g} MB free; nothing was written"
                          ) from None


def _listening(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.settimeout(0.5)
        return s.connect_ex(("127.0.0.1", port)) == 0


def show(scene: Scene, *, port: int = 9876) -> None:
    """Send ``scene`` to a rerun viewer: the one listening on ``port``, else a spawned one.

    Raises
    ------
    ViewerError
        No viewer runs and none can be spawned (no display, no ``rerun`` executable,
        or it did not start); the message suggests ``--save``.
    """
    import rerun as rr

    source = scene.experiment.source
    hint = (f"write a file instead: momentid view {source} --save out.rrd, and open it with "
            "`rerun out.rrd` where there is a display")
    rec = rr.RecordingStream(APPLICATION_ID)
    bp = blueprint(scene)
    if not _listening(port):
        if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise ViewerError(f"cannot show {source}: no display to open the rerun viewer on "
                              f"(DISPLAY and WAYLAND_DISPLAY are unset); {hint}")
        if shutil.which("rerun") is None:
            raise ViewerError(f"cannot show {source}: the `rerun` executable is not on PATH "
                              f"(pip install rerun-sdk); {hint}")
        try:
            rec.spawn(port=port, connect=False)
        except (OSError, RuntimeError) as exc:
            raise ViewerError(f"cannot show {source}: spawning the rerun viewer failed ({exc}); {hint}") from None
        if not _listening(port):
            raise ViewerError(f"cannot show {source}: the rerun viewer did not start on port {port}; {hint}")
    rec.connect_grpc(f"rerun+http://127.0.0.1:{port}/proxy", default_blueprint=bp)
    rec.send_blueprint(bp, make_active=True)
    try:
        log_scene(rec, scene)
        rec.flush()
    finally:
        rec.disconnect()


def view(recording, *, save=None, result=None, exaggeration: float | None = None, run: str | None = None,
         identify_options: dict | None = None, port: int = 9876, twin=None) -> Path | None:
    """Read ``recording``, then show it in the viewer or, with ``save``, write a ``.rrd``.

    Parameters
    ----------
    recording : str, Path or Experiment
        An MCAP recording (or an experiment already read).
    save : str or Path, optional
        Write this ``.rrd`` file instead of opening a viewer.
    result : str, Path or Identification, optional
        A JSON file of ``momentid identify --json`` or an identification; default:
        identify the recording with ``identify_options``.
    exaggeration, run, identify_options
        See :func:`prepare`.
    port : int
        Port of the viewer to connect to or spawn.
    twin : str or Path, optional
        A folder of ``momentid twin``: each run's twin floor accelerations beside the recorded ones
        and the twin moving (:mod:`momentid.twin.overlay`); the recording is then not identified again.

    Returns
    -------
    Path or None
        The ``.rrd`` written, or None when shown in a viewer.

    Raises
    ------
    RecordingError
        The recording is missing or unreadable.
    ViewerError
        See :func:`load_result`, :func:`prepare`, :func:`write_rrd`, :func:`show`.
    """
    from momentid.io.mcap_check import MCAP_MAGIC
    from momentid.io.recording import read_recording

    if save is not None and Path(save).is_file():
        with open(save, "rb") as f:
            if f.read(len(MCAP_MAGIC)) == MCAP_MAGIC:   # `view rec.mcap --save rec.mcap` destroyed the recording
                raise ViewerError(f"--save {save}: that file is an MCAP recording; expected a new path or an "
                                  f"existing .rrd (a rerun file written over it would destroy it)")
    experiment = recording if isinstance(recording, Experiment) else read_recording(recording)
    if isinstance(result, (str, Path)):
        result = load_result(result, experiment)
    scene = prepare(experiment, result=result, exaggeration=exaggeration, run=run,
                    identify_options=identify_options, identify=twin is None)
    if twin is not None:
        from momentid.twin.overlay import TwinOverlay

        scene.overlay = TwinOverlay.from_folder(twin, experiment)
    if save is not None:
        return write_rrd(scene, save)
    show(scene, port=port)
    return None
