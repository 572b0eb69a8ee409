"""The answer of a twin in HTML: a notebook's ``Twin._repr_html_`` and the report page's first section
(:mod:`momentid.report`), the same words in both: what rig it is, its modes, how well it replays each
trial, its warnings."""

from __future__ import annotations

from typing import Any

from momentid.core import html

__all__ = ["twin_html", "twin_headline"]


def twin_headline(twin: Any) -> str:
    """One sentence of a :class:`~momentid.twin.build.Twin` (which this module's caller imports: typed
    ``Any``): the rig, its masses, the trials it is calibrated on, the replays' NRMSE."""
    p = twin.parameters
    masses = ("mass-normalised (no floor masses stated)" if p.mass_normalised
              else f"floor masses {', '.join(f'{m:g}' for m in p.masses)} kg")
    worst = max(twin.replays, key=lambda r: r.nrmse / max(r.noise_nrmse, 1e-12))
    return (f"MuJoCo twin of {twin.source}: {html.count(p.storeys, 'storey')}, {masses}; calibrated "
            f"on {', '.join(p.runs)}; replay NRMSE {min(r.nrmse for r in twin.replays) * 100:.1f}-"
            f"{max(r.nrmse for r in twin.replays) * 100:.1f} % (the furthest from its noise: {worst.run}, "
            f"{worst.nrmse / max(worst.noise_nrmse, 1e-12):.1f} x the noise alone).")


def twin_html(twin: Any) -> str:
    """The answer of a :class:`~momentid.twin.build.Twin` (module docstring)."""
    ident = twin.identification.modes()
    body = html.table(["mode", "frequency (Hz)", "damping ratio (%)", "identified frequency (Hz)",
                       "identified damping ratio (%)"],
                      [[f"{i + 1}", f"{f:.4f}", f"{100 * z:.3f}", f"{fi:.4f}", f"{100 * zi:.3f}"]
                       for i, (f, z, fi, zi) in enumerate(zip(twin.modes.frequency, twin.modes.damping_ratio,
                                                              ident.frequency, ident.damping_ratio))],
                      caption="Modes of the MJCF written (read back from MuJoCo) and of the identification")
    d = twin.parameters.storeys
    body += html.table(["trial", "sensors", "NRMSE (%)", "noise alone (%)",
                        *(f"floor {j + 1} sensor (%)" for j in range(d))],
                       [[r.run, "calibrated" if r.calibrated else "nominal", f"{100 * r.nrmse:.2f}",
                         f"{100 * r.noise_nrmse:.2f}", *(f"{100 * x:.2f}" for x in r.nrmse_floors)]
                        for r in twin.replays],
                       caption="Each trial replayed through the twin under its recorded table acceleration "
                               "(floor-acceleration NRMSE after the quiet lead-in)", names=2)
    return html.summary(twin_headline(twin), body + html.warnings_list(twin.warnings))
