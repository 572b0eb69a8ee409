"""The report page of ``momentid twin -o DIR`` (:class:`~momentid.report.page.Page`): the twin's modes and
each trial's replay misfit first; then its K and C, extra modes, each trial's sensor model, the
simulation, notes; then the transfer functions, recorded and the twin's, and every trial recorded
against the twin's replay with a zoom on its largest response."""

from __future__ import annotations

from typing import TYPE_CHECKING

from momentid.core import html
from momentid.report.page import Page, Provenance

if TYPE_CHECKING:
    from momentid.core.series import Experiment
    from momentid.twin.build import Twin

__all__ = ["twin_page", "OVERLAY_BINS"]

#: Stretches a whole trial is drawn as on the page (minimum and maximum of each): about its panel's
#: width on screen in pixels (a pixel column shows a stretch's range), at a fraction of every sample's size.
OVERLAY_BINS = 400


def _sensor_rows(twin) -> list:
    p = twin.parameters
    rows = []
    for name, s in [*p.sensors.items(), ("nominal (trials not calibrated on)", p.nominal)]:
        rows.append([name, *(f"{g:.4f}" for g in s.gain), *(f"{1e3 * t:+.2f}" for t in s.clock_offset),
                     *(f"{b:+.4f}" for b in s.bias)])
    return rows


def twin_page(twin: Twin, experiment: Experiment, made: Provenance) -> Page:
    """The page of ``twin`` (a :class:`~momentid.twin.build.Twin` of ``experiment``; module docstring)."""
    from momentid.twin.plots import replay_figure, transfer_figure

    p = twin.parameters
    d = p.storeys
    page = Page(f"Twin of {experiment.name}", f"{twin.source}: the calibrated MuJoCo twin (twin.xml), "
                                              f"{html.count(d, 'storey')}, {len(twin.replays)} trials replayed.", made)
    page.answer(twin._repr_html_())
    unit = "normalised by the mean floor mass" if p.mass_normalised else "SI"
    page.table("Stiffness and damping", html.matrix_table(p.K, caption="K (N/m)")
               + html.matrix_table(p.C, caption="C (N s/m)")
               + html.table(["", *(f"floor {j + 1}" for j in range(d))],
                            [["mass (kg)", *(f"{m:.4g}" for m in p.masses)],
                             ["storey height (m)", *(f"{h:.4g}" for h in p.storey_heights)]]),
               note=f"Units: {unit}; the twin carries them as tendons between the floors (twin.xml).")
    if p.extra_modes:
        page.table("Resonances beyond the storey modes", html.table(
            ["", "frequency (Hz)", "damping ratio (%)", *(f"residue at floor {j + 1} sensor" for j in range(d))],
            [[f"extra mode {k + 1}", f"{e.frequency:.4f}", f"{100 * e.damping_ratio:.3f}",
              *(f"{x:+.3g}" for x in e.residues)] for k, e in enumerate(p.extra_modes)]))
    page.table("Sensor models", html.table(
        ["trial", *(f"floor {j + 1} gain (1)" for j in range(d)),
         *(f"floor {j + 1} clock offset (ms)" for j in range(d)),
         *(f"floor {j + 1} bias (m/s²)" for j in range(d))], _sensor_rows(twin)),
        note="Each floor sensor against the table's: the twin reads its floors through these.")
    t = twin.timing
    page.table("Simulation", html.table(["quantity", "value"], [
        ["integrator", "RK4"], ["time step", f"{t.timestep:.6g} s"], ["steps per sample", f"{t.substeps}"],
        ["sample rate", f"{t.sample_rate:.6g} Hz"]]))
    page.lines("Notes", [f"note: {n}" for n in twin.notes])
    top = max([*twin.modes.frequency, *(e.frequency for e in p.extra_modes)])
    page.figure("Table-to-floor transfer functions of the calibration trials (H1 where the coherence reaches 0.8) "
                "and of the twin.",
                lambda: transfer_figure(p, experiment, [r.run for r in twin.replays if r.calibrated], top))
    for replay in twin.replays:
        page.figure(f"Trial {replay.run}: recorded floor accelerations and the twin's replay (left: the whole trial "
                    f"after its quiet lead-in; right: the seconds around its largest response).",
                    lambda replay=replay: replay_figure(replay, bins=OVERLAY_BINS))
    return page
