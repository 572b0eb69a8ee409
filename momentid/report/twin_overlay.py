"""The twin in the rerun viewer: ``momentid view REC --twin DIR``.

:class:`TwinOverlay` replays every run of the recording through the twin of ``DIR`` (its
``twin.json``) and adds to each run's tab of :mod:`momentid.report.viewer`:

* a second 3D view, **the twin moving**: the table's drift-free displacement (the same one the
  recording's view draws, band-limited double integration of the recorded table acceleration) and the
  twin's floors relative to it (its joints, from MuJoCo; they cannot drift: storey springs hold them);
* per floor, **the recorded and the twin's floor-sensor readings** in one plot;

and to the side column the twin's summary (modes, every trial's NRMSE).

Entity paths::

    /runs/<run>/twin/rig/...           the twin's rig (as /runs/<run>/rig)
    /runs/<run>/twin/a<j>              Scalars, the twin's floor sensor j (m/s^2)
    /twin/summary                      markdown: the twin's modes and per-trial NRMSE
"""

from __future__ import annotations

from dataclasses import dataclass
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from momentid.core.series import Experiment, RunData
from momentid.twin.files import check_against, read_twin
from momentid.twin.replay import Replay, replay_run

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb
    from momentid.report.scene import Scene

__all__ = ["TwinOverlay", "TWIN_COLOR"]

#: The twin's series colour (the recorded ones keep the viewer's per-floor palette).
TWIN_COLOR = (255, 127, 14)


@dataclass(frozen=True)
class TwinOverlay:
    """A twin's replays of a recording's runs, for :class:`momentid.report.viewer.Scene`'s ``overlay``.

    Attributes
    ----------
    folder : str
        The twin's folder.
    parameters : TwinParameters
    replays : dict of str to Replay
    """

    folder: str
    parameters: object
    replays: dict

    @classmethod
    def from_folder(cls, folder: str | os.PathLike, experiment: Experiment) -> TwinOverlay:
        """Read the twin of ``folder`` and replay every run of ``experiment`` through it.

        Raises
        ------
        TwinFolderError, RecordingError
            No twin there, or the twin of a rig with another number of storeys.
        """
        params = read_twin(folder)
        check_against(params, experiment)
        stated = dict(experiment.statement.noise) if experiment.statement is not None else None
        replays = {run.name: replay_run(params, run, stated_noise=stated) for run in experiment.runs}
        return cls(str(folder), params, replays)

    def _root(self, run) -> str:
        import rerun as rr

        return f"/runs/{rr.escape_entity_path_part(run.name)}/twin"

    def spatial_views(self, scene: Scene, run: RunData, eye: rrb.EyeControls3D) -> list[rrb.View]:
        """The twin's rig moving, beside the recording's (a 3D view with the same ``eye``)."""
        import rerun.blueprint as rrb

        return [rrb.Spatial3DView(origin=f"{self._root(run)}/rig", eye_controls=eye,
                                  name=f"{run.name}: the twin, displacements drawn x{scene.exaggeration:g}")]

    def series_views(self, scene: Scene, run: RunData) -> list[rrb.View]:
        """Per floor sensor, the recorded and the twin's acceleration in one time-series view."""
        import rerun as rr
        import rerun.blueprint as rrb

        recorded = f"/runs/{rr.escape_entity_path_part(run.name)}/sensors"
        replay = self.replays[run.name]
        return [rrb.TimeSeriesView(
            name=f"{run.name}: floor {j + 1} sensor, recorded and twin (m/s^2; NRMSE "
                 f"{100 * replay.nrmse_floors[j]:.1f} %)",
            contents=[f"{recorded}/a{j + 1}", f"{self._root(run)}/a{j + 1}"],
            plot_legend=rrb.PlotLegend(rrb.Corner2D.RightTop, visible=True))
            for j in range(self.parameters.storeys)]

    def side_views(self) -> list[rrb.View]:
        """The twin's summary (modes and NRMSE per trial) as a text view."""
        import rerun.blueprint as rrb

        return [rrb.TextDocumentView(origin="/twin/summary", name="twin: modes and NRMSE per trial")]

    def log(self, rec: rr.RecordingStream, scene: Scene, run: RunData) -> None:
        """The twin's rig moving and its floor sensors, for ``run``."""
        import rerun as rr

        from momentid.report.rig_drawing import TIMELINE, log_rig

        replay: Replay = self.replays[run.name]
        z, _ = scene.drawn(run)
        log_rig(rec, scene, run, root=f"{self._root(run)}/rig",
                motion=(np.zeros(run.n_samples) if z is None else z, replay.q))
        time = rr.TimeColumn(TIMELINE, duration=run.time)
        for j in range(self.parameters.storeys):
            entity = f"{self._root(run)}/a{j + 1}"
            rec.log(entity, rr.SeriesLines(names=f"a{j + 1}: twin, floor {j + 1} (m/s^2)", colors=[TWIN_COLOR]),
                    static=True)
            rec.send_columns(entity, indexes=[time], columns=rr.Scalars.columns(scalars=replay.twin[:, j]))

    def log_static(self, rec: rr.RecordingStream) -> None:
        """The twin's summary, once for every run."""
        import rerun as rr

        rec.log("/twin/summary", rr.TextDocument(self.markdown(), media_type=rr.MediaType.MARKDOWN), static=True)

    def markdown(self) -> str:
        """The twin's modes and every trial's NRMSE, as markdown."""
        from momentid.core.analytic import modal_properties

        p = self.parameters
        modes = modal_properties(np.diag(p.masses), p.C, p.K)
        lines = [f"# Twin `{Path(self.folder).name}`", "",
                 f"calibrated on {', '.join(p.runs)}" + (" (mass-normalised)" if p.mass_normalised else ""), "",
                 "| mode | frequency (Hz) | damping ratio (%) |", "|---:|---:|---:|"]
        lines += [f"| {i + 1} | {f:.4f} | {100 * z:.3f} |" for i, (f, z) in enumerate(zip(modes.frequency,
                                                                                          modes.damping_ratio))]
        lines += ["", "| trial | sensors | NRMSE (%) | noise alone (%) |", "|---|---|---:|---:|"]
        lines += [f"| {r.run} | {'calibrated' if r.calibrated else 'nominal'} | {100 * r.nrmse:.2f} | "
                  f"{100 * r.noise_nrmse:.2f} |" for r in self.replays.values()]
        return "\n".join(lines)
