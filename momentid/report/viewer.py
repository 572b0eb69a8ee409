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

This module draws and sends (:func:`blueprint`, :func:`log_scene`,
:func:`write_rrd`, :func:`show`, :func:`view`); what is shown is computed in
:mod:`momentid.report.scene` (re-exported here), the rig is drawn by :mod:`momentid.report.rig_drawing`
and the text panels are written by :mod:`momentid.report.panels`.
"""

from __future__ import annotations

import os
import shutil
import socket
import sys
from pathlib import Path
from typing import Any, TYPE_CHECKING

import numpy as np

from momentid.core.series import Experiment, RunData, channel_unit
from momentid.errors import ViewerError
from momentid.io.exclusive import write_whole
from momentid.report.panels import experiment_markdown, modes_markdown, parameters_markdown
from momentid.report.rig_drawing import (BASE_COLOR, PALETTE, RIG_RATE, TIMELINE, log_rig, rig_samples,
                                         run_path)
from momentid.report.scene import (DISPLACEMENT_HIGHPASS, Scene, auto_exaggeration, check_result,
                                   displacements_from_accelerations, load_result, prepare)

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb
    from momentid.estimation.identified import Identification
    from momentid.estimation.scaled import ModalIdentification

__all__ = ["Scene", "auto_exaggeration", "displacements_from_accelerations", "DISPLACEMENT_HIGHPASS", "load_result",
           "check_result", "prepare", "blueprint", "log_scene", "write_rrd", "show", "view", "rig_samples", "log_rig",
           "TIMELINE", "APPLICATION_ID", "RIG_RATE"]

#: The rerun application every recording is sent as.
APPLICATION_ID = "momentid"

#: Time-series views of a run tab: (title, base channel, floor prefix).
_SERIES_VIEWS = (
    ("base acceleration zdd", "zdd", None),
    ("floor absolute accelerations a", None, "a"),
    ("displacements: table z, floors q relative to it", "z", "q"),
    ("velocities: table zd, floors v relative to it", "zd", "v"),
    ("the table sensor's cross and vertical accelerations", ("table_ay", "table_az"), None),
    ("the table sensor's angular rates", ("table_wx", "table_wy", "table_wz"), None),
)


def _first(base: str | tuple | None) -> str | None:
    return base[0] if isinstance(base, tuple) else base


def _series_paths(scene: Scene, run: RunData, base: str | None, prefix: str | None) -> list[str]:
    root = run_path(run.name)
    chans = list(base) if isinstance(base, tuple) else [base] if base else []
    chans += [f"{prefix}{i + 1}" for i in range(scene.experiment.storeys)] if prefix else []
    return [f"{root}/sensors/{c}" for c in chans if run.has(c)]


def blueprint(scene: Scene) -> rrb.Blueprint:
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
        root = run_path(run.name)
        eye = rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=[0.9 * total, -1.9 * total, 0.8 * total],
                                look_target=[0.0, 0.0, 0.45 * total], eye_up=[0.0, 0.0, 1.0])
        views = [rrb.TimeSeriesView(name=f"{run.name}: {title} ({channel_unit(_first(base) or prefix + '1')})",
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


def _log_series(rec, entity: str, time, values: np.ndarray, name: str, color) -> None:
    import rerun as rr

    rec.log(entity, rr.SeriesLines(names=name, colors=[color]), static=True)
    rec.send_columns(entity, indexes=[time], columns=rr.Scalars.columns(scalars=values))


def _channel_label(channel: str) -> tuple[str, tuple]:
    group = channel.rstrip("0123456789")
    if group != channel:
        i = int(channel[len(group):])
        return f"{channel}: floor {i} ({channel_unit(channel)})", PALETTE[(i - 1) % len(PALETTE)]
    return f"{channel}: table ({channel_unit(channel)})", BASE_COLOR


def log_scene(rec: rr.RecordingStream, scene: Scene) -> None:
    """Send everything of ``scene`` to the recording stream ``rec`` (series via ``send_columns``)."""
    import rerun as rr

    md = rr.MediaType.MARKDOWN
    rec.send_recording_name(scene.experiment.name)
    rec.log("/experiment", rr.TextDocument(experiment_markdown(scene), media_type=md), static=True)
    rec.log("/identification/parameters", rr.TextDocument(parameters_markdown(scene), media_type=md), static=True)
    if scene.result is not None:
        rec.log("/identification/modes", rr.TextDocument(modes_markdown(scene), media_type=md), static=True)
    if scene.overlay is not None:
        scene.overlay.log_static(rec)
    if scene.comparison is not None:
        errors = np.array([e.rel_error for e in scene.comparison.entries])
        rec.log("/identification/rel_error",
                rr.BarChart(errors, abscissa=np.arange(1, errors.size + 1, dtype=float), color=PALETTE[3]),
                static=True)
    for run in scene.experiment.runs:
        root = run_path(run.name)
        log_rig(rec, scene, run)
        if scene.overlay is not None:
            scene.overlay.log(rec, scene, run)
        time = rr.TimeColumn(TIMELINE, duration=run.time)
        for channel in run.channels:
            name, color = _channel_label(channel)
            _log_series(rec, f"{root}/sensors/{channel}", time, run[channel], name, color)
        if run.name in scene.reconstructed:
            z, q = scene.reconstructed[run.name]
            _log_series(rec, f"{root}/reconstructed/z", time, z, "z: table (m)", BASE_COLOR)
            for i, column in enumerate(q.T):
                _log_series(rec, f"{root}/reconstructed/q{i + 1}", time, column, f"q{i + 1}: floor {i + 1} (m)",
                            PALETTE[i % len(PALETTE)])
        residual = scene.residuals.get(run.name, np.empty((0, 0)))
        # the weak form of accelerometer-only runs loses half its kernel at each end: centred in the run
        head = (run.n_samples - residual.shape[0]) // 2
        residual_time = rr.TimeColumn(TIMELINE, duration=run.time[head:head + residual.shape[0]])
        for i, column in enumerate(residual.T):
            _log_series(rec, f"{root}/residual/r{i + 1}", residual_time, column, f"floor {i + 1} (N)",
                        PALETTE[i % len(PALETTE)])


def write_rrd(experiment: Experiment | Scene, path: str | os.PathLike, **options: Any) -> Path:
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


def view(recording: str | os.PathLike | Experiment, *, save: str | os.PathLike | None = None,
         result: str | os.PathLike | Identification | ModalIdentification | None = None,
         exaggeration: float | None = None, run: str | None = None, identify_options: dict | None = None,
         port: int = 9876,
         twin: str | os.PathLike | None = None) -> Path | None:
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
        and the twin moving (:mod:`momentid.report.twin_overlay`); the recording is then not identified again.

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
        from momentid.report.twin_overlay import TwinOverlay

        scene.overlay = TwinOverlay.from_folder(twin, experiment)
    if save is not None:
        return write_rrd(scene, save)
    show(scene, port=port)
    return None
