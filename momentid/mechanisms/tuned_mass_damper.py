"""A tuned-mass damper: a body hung on a floor by a spring and a dashpot, in every run.

The body (``mass``) rides on its floor on a slide joint of its own, its spring tuned to ``frequency``
and its dashpot at ``damping_ratio`` of critical: its relative motion ``u`` obeys
``u'' + 2 zeta w u' + w^2 u = -a_j`` (``a_j`` the floor's absolute acceleration, ``w = 2 pi frequency``)
and it pushes its floor with ``-mass (a_j + u'')``, its own absolute acceleration times its mass.  This
module is all the project knows of it: its MJCF elements at its floor (:meth:`TunedMassDamper.elements`),
its signature in the floor-force residual (:meth:`TunedMassDamper.screen_equation`) and its sizing by
re-simulation of all three parameters (:meth:`TunedMassDamper.size`).  ``docs/mechanisms.md`` walks
through it.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from momentid.core.structure import Mechanism
from momentid.mechanisms.base import EquationSignals, Fitter, MechanismKind, Param, Refit, Screened, Target
from momentid.mechanisms.place import Place
from momentid.mechanisms.registry import register
from momentid.mechanisms.sizing import Sized, Sizer

__all__ = ["TunedMassDamper", "GRID_LOW_OVER_TOP_MODE", "GRID_HIGH_OVER_TOP_MODE", "GRID_POINTS",
           "GRID_DAMPING_RATIOS"]

#: Screening grid of the damper's frequency: log-spaced from this fraction of the model's top mode (a
#: damper is tuned to a mode, the lowest included) ...
GRID_LOW_OVER_TOP_MODE = 1 / 30
#: ... to a little above the top mode, ...
GRID_HIGH_OVER_TOP_MODE = 1.2
#: ... in this many points (16 % apart: a start, which the re-simulation refines), at the middle one of
#: these damping ratios; the best few frequencies are then tried at the others (a tuned-mass damper's
#: dashpot is at 2-30 % of critical).
GRID_POINTS = 24
GRID_DAMPING_RATIOS = (0.03, 0.1, 0.3)
#: Frequencies of the first pass tried at every damping ratio.
GRID_REFINED = 3


@register
class TunedMassDamper(MechanismKind):
    name = "tuned_mass_damper"
    target = Target.FLOOR
    params = (Param("mass", "kg", "mass of the damper's body", low=0.0, low_open=True, example=1.0),
              Param("frequency", "Hz", "natural frequency of the body on its spring", low=0.0, low_open=True,
                    example=0.8),
              Param("damping_ratio", "1", "damping ratio of its dashpot", low=0.0, low_open=True, example=0.1))
    fitted = params[0]
    mjcf_elements = True
    refit = Refit.SEARCH
    summary = "a body hung on a floor by a spring and a dashpot (mass, tuning frequency, damping ratio)"

    def elements(self, spec: mujoco.MjSpec, mech: Mechanism, place: Place, bodies: Sequence[mujoco.MjsBody],
                 timestep: float) -> dict[int, float]:
        """A body of ``mass`` hung on floor ``place`` by a slide joint of its ``frequency`` and
        ``damping_ratio``; the floor keeps its mass.
        """
        p = dict(mech.parameters)
        m, w = p["mass"], 2 * np.pi * p["frequency"]
        body = bodies[place.index].add_body(name=f"tmd{place.index}", pos=[0.0, 0.0, 0.05])
        body.mass = m
        body.inertia = [m * 1e-3] * 3                  # a slide joint only: any valid inertia
        joint = body.add_joint(name=f"tmd{place.index}_x", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
        joint.stiffness = [m * w * w, 0.0, 0.0]
        joint.damping = [2 * p["damping_ratio"] * m * w, 0.0, 0.0]
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.04, 0.04, 0.04], rgba=[0.8, 0.2, 0.2, 1],
                      contype=0, conaffinity=0)
        return {}                                      # a body of its own: the floor keeps its mass

    def screen_equation(self, signals: EquationSignals, fit: Fitter, place: Place) -> list[Screened]:
        """The damper's force on floor ``place`` for the grid point (frequency, damping ratio) that
        explains most: its body's absolute acceleration, driven by the measured floor acceleration, per
        kilogram; the floor's own acceleration is the confound (an identified mass may hold part of it)."""
        a = signals.a[:, place.index - 1]

        def tried(f, zeta):
            body = signals.attachment_response(a, f, zeta)
            return fit([signals.columns(-body, place)], [signals.columns(a, place)], place,
                       lambda c, e: ({"mass": float(c[0]), "frequency": float(f), "damping_ratio": zeta},
                                     {"mass": float(e[0])}))

        middle = GRID_DAMPING_RATIOS[len(GRID_DAMPING_RATIOS) // 2]
        grid = np.geomspace(GRID_LOW_OVER_TOP_MODE * signals.f_top, GRID_HIGH_OVER_TOP_MODE * signals.f_top,
                            GRID_POINTS)
        first = []
        for f in grid:
            first += [(f, s) for s in tried(f, middle)]
        first.sort(key=lambda pair: -pair[1].explained)
        found = [s for _, s in first[:1]]
        for f, _ in first[:GRID_REFINED]:
            for zeta in GRID_DAMPING_RATIOS:
                if zeta != middle:
                    found += tried(f, zeta)
        return [max(found, key=lambda s: s.explained)] if found else []

    def size(self, sizer: Sizer, place: Place, params: dict, std: dict) -> Sized:
        """Every parameter searched by re-simulation from the screening's grid point, on the lab's nominal
        model when it states one (the identified model has absorbed part of the damper), else on the
        identified one."""
        structure = sizer.nominal if sizer.nominal is not None else sizer.linear_structure
        params, std = sizer.search(structure, sizer.entry(self, place, params), tuple(p.name for p in self.params))
        # a body hung on a floor is at most as heavy as the floor itself (dampers weigh a few % of it):
        # a search that runs past that has found another rig's dynamics, and replays held there
        params = dict(params, mass=min(float(params["mass"]), float(structure.masses[place.index - 1])))
        return Sized(structure, params, std)
