"""An added mass attached flexibly: on its own slide joint with a spring and damper, not welded."""

from __future__ import annotations

import mujoco
import numpy as np

from momentid.core.structure import Mechanism
from momentid.mechanisms.base import EquationSignals, Fitter, MechanismKind, Param, Refit, Screened, Target
from momentid.mechanisms.place import Place
from momentid.mechanisms.registry import register
from momentid.mechanisms.sizing import Attachment

__all__ = ["FlexibleAddedMass", "GRID_DAMPING_RATIO", "GRID_LOW_OVER_TOP_MODE", "GRID_HIGH_OVER_SAMPLE_RATE",
           "GRID_POINTS"]

#: Damping ratio of the attachment oscillators on the screening grid (a lightly damped bolt-on).
GRID_DAMPING_RATIO = 0.05
#: Screening grid of attachment frequencies: from just above the structure's top mode (an attachment
#: below it would show as a changed mode, which the identification absorbs) ...
GRID_LOW_OVER_TOP_MODE = 1.2
#: ... to 0.3 x the sample rate (the band-limited accelerations carry little above), ...
GRID_HIGH_OVER_SAMPLE_RATE = 0.3
#: ... in this many log-spaced points (about 10 % apart on the paper's rig).
GRID_POINTS = 24


@register
class FlexibleAddedMass(Attachment, MechanismKind):
    name = "flexible_added_mass"
    target = Target.FLOOR
    params = (Param("frequency", "Hz", "natural frequency of the added mass on its attachment",
                    low=0.0, low_open=True, example=6.0),
              Param("damping_ratio", "1", "damping ratio of the attachment", low=0.0, example=0.05))
    fitted = Param("amplitude", "1", "share of the attachment's relative acceleration in the floor force")
    refit = Refit.ATTACHMENT
    summary = "the added mass on a floor on a spring and damper of its own"

    def added_mass_body(self, mech: Mechanism, body: mujoco.MjsBody, mass: float) -> None:
        """The added mass on a slide joint of its own: a spring and a dashpot of its ``frequency`` and
        ``damping_ratio``."""
        w = 2 * np.pi * mech.get("frequency")
        joint = body.add_joint(name=f"added{mech.location}_x", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
        joint.stiffness = [mass * w * w, 0.0, 0.0]
        joint.damping = [2 * mech.get("damping_ratio") * mass * w, 0.0, 0.0]

    def screen_equation(self, signals: EquationSignals, fit: Fitter, place: Place) -> list[Screened]:
        """The attachment's force on floor ``place`` for the grid frequency that explains most.

        The attachment oscillator is driven by the measured (band-limited) floor acceleration; its
        resonance amplifies that channel's noise too, which biases the fitted amplitude low.
        """
        j = place.index - 1
        dm, a = signals.added_mass[:, j], signals.a[:, j]
        if not np.any(dm > 0):
            return []
        best = None
        fs = signals.sample_rate
        for f_a in np.geomspace(GRID_LOW_OVER_TOP_MODE * signals.f_top, GRID_HIGH_OVER_SAMPLE_RATE * fs,
                                GRID_POINTS):
            rel = signals.attachment_response(a, f_a, GRID_DAMPING_RATIO) - a
            phi = np.where(dm > 0, -dm * rel, 0.0)
            found = fit([signals.columns(phi, place)], [signals.columns(a, place)], place,
                        lambda c, e, f_a=f_a: ({"frequency": float(f_a), "damping_ratio": GRID_DAMPING_RATIO,
                                                "amplitude": float(c[0])}, {"amplitude": float(e[0])}))
            # A later grid point replaces the best so far when its share explained exceeds the best's
            # amplitude standard error: the rule the diagnosis was validated with (benchmarks/), kept
            # as it is.  (Comparing with the best's share explained instead picks other points; that
            # change needs the validation matrix re-run.)
            if found and (best is None or found[0].explained > best.std["amplitude"]):
                best = found[0]
        return [best] if best else []

    def attachment_matrices(self, M: np.ndarray, C: np.ndarray, K: np.ndarray, floor: int, mass: float,
                            frequency: float, damping_ratio: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """M, C, K (d+1, d+1) of a model with ``mass`` (kg) on floor ``floor`` (0-based) on its attachment."""
        d = M.shape[0]
        w = 2 * np.pi * frequency
        out = [np.zeros((d + 1, d + 1)) for _ in range(3)]
        for X, Y in zip(out, (M, C, K)):
            X[:d, :d] = Y
        out[0][d, d] = mass
        k_a, c_a = mass * w * w, 2 * damping_ratio * mass * w
        for X, v in ((out[2], k_a), (out[1], c_a)):
            X[floor, floor] += v
            X[d, d] += v
            X[floor, d] -= v
            X[d, floor] -= v
        return tuple(out)
