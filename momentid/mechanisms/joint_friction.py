"""Micro-slip friction in a storey's bolted or clamped joints: an Iwan model built of MuJoCo sliders.

A clamped joint does not slip all at once.  As the drift grows, the contact's rim slips first and its
centre last: the joint softens and dissipates more per cycle the harder it shakes (micro-slip), until
the whole contact slides (macro-slip).  Iwan's model is that joint: many Jenkins elements in parallel,
each a spring ``k_j`` in series with a Coulomb slider of strength ``f_j = k_j delta_j``; element ``j``
sticks while the storey's drift stays within ``delta_j`` of where it last slipped.  Its loops follow
Masing's rules.  Segalman's power-law density of the slip drifts, ``rho(delta) ~ delta^chi`` on
``(0, delta_max]``, gives the measured signature of bolted joints: for a drift amplitude ``A`` below
``delta_max`` the stiffness lost and the damping ratio added both grow as ``A^(chi + 1)``.

In MuJoCo each element is a **slider**: a small body on a slide joint (``slip<s>_<j>``) riding on the
floor below the storey, with the slider's ``frictionloss`` ``f_j`` (MuJoCo's dry-friction constraint),
and a fixed tendon ``jenkins<s>_<j> = q_s - q_(s-1) - p`` (the storey's drift less the slip) with
stiffness ``k_j``.  No Python runs in the loop: the elements live in the MJCF and a stock
``mujoco.MjModel`` carries them (a real rig's twin with them replays MuJoCo's step in compiled code,
:mod:`momentid.lab.step_replay`).  The ``SLIDERS`` elements sit at geometric slip drifts from
``delta_max / SPAN`` to ``delta_max``, each weighted by the density's share of its bin.  The storey
tendon keeps ``k - stiffness`` so that the stuck joint (small drifts) has the storey's stiffness ``k``.

Each slider's mass and damping make its own spring-mass oscillation fast and damped at the model's
step (:data:`SLIDER_STEP_PHASE`, :data:`SLIDER_DAMPING_RATIO`).  MuJoCo integrates the sliders'
springs explicitly, so a slipping element lags the ideal Jenkins element by about one step: at 2 ms
steps and drifts of 3-4 slip drifts the joint's force is off the ideal law by 13 % of its RMS (7 % at
1 ms, about 25 % at 4 ms; tests/test_joint_friction.py).  A twin fitted through MuJoCo is sized with this element, at
its own step.  Use a step of at most :data:`MAX_TIMESTEP`.
"""

from __future__ import annotations

from collections.abc import Sequence
import math

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from momentid.core.structure import Mechanism
from momentid.mechanisms.base import MechanismKind, Param, Target
from momentid.mechanisms.place import Place
from momentid.mechanisms.registry import register

__all__ = ["JointFriction", "SLIDERS", "SPAN", "slider_elements", "add_sliders", "backbone", "lost_fraction",
           "MAX_TIMESTEP"]

#: Jenkins elements per joint: enough for a smooth backbone over the two decades of drift a rig shows.
SLIDERS = 6
#: Ratio of the largest to the smallest slip drift of the elements.
SPAN = 64.0
#: Each slider's spring-mass oscillation advances this many radians per step (mass ``k_j h^2 / phase^2``):
#: below MuJoCo's explicit-spring stability limit (2), fast against the storey's modes.
SLIDER_STEP_PHASE = 1.5
#: Damping ratio of each slider's spring-mass oscillation (joint damping; implicit in ``implicitfast``).
SLIDER_DAMPING_RATIO = 0.3
#: Largest integrator step (s) the elements are tested at.
MAX_TIMESTEP = 1.0 / 240.0
#: Impedance of the sliders' friction constraints (MuJoCo's ``solimp``): as stiff as MuJoCo allows, so
#: that a stuck slider does not creep.
_SOLIMP = (0.9999, 0.9999, 0.001, 0.5, 2.0)
#: A slider's inertia is its joint's armature, not its body's mass: the body carries this token mass
#: only, so that the floor's acceleration does not load the slider (a mass riding the floor would pull
#: on its own friction, as much as the weakest sliders' strength on a 20 m/s^2 floor).
_BODY_MASS = 1e-9


def slider_elements(stiffness: float, slip_drift: float, exponent: float, sliders: int = SLIDERS,
                    span: float = SPAN) -> tuple[np.ndarray, np.ndarray]:
    """The Jenkins elements of one joint.

    Parameters
    ----------
    stiffness : float
        Total stiffness of the joint's elements (N/m): the stiffness the storey loses at macro-slip.
    slip_drift : float
        ``delta_max`` (m): the drift at which the last element slips.
    exponent : float
        ``chi`` (> -1) of the density ``delta^chi``.

    Returns
    -------
    k : ndarray, shape (sliders,)
        Element stiffnesses (N/m), summing to ``stiffness``.
    delta : ndarray, shape (sliders,)
        Element slip drifts (m), ascending; the slider strengths are ``k * delta`` (N).
    """
    ratio = span ** (1.0 / (sliders - 1))
    nodes = slip_drift * ratio ** (np.arange(sliders) - (sliders - 1.0))
    edges = np.concatenate([[0.0], nodes[:-1] * math.sqrt(ratio), [slip_drift]]) / slip_drift
    weights = edges[1:] ** (exponent + 1.0) - edges[:-1] ** (exponent + 1.0)
    return stiffness * weights, nodes


def backbone(params: dict, drift: ArrayLike) -> np.ndarray:
    """The joint's force (N) on first loading to ``drift`` (m, >= 0): ``sum_j k_j min(x, delta_j)``."""
    k, delta = slider_elements(params["stiffness"], params["slip_drift"], params["exponent"])
    x = np.asarray(drift, float)[..., None]
    return np.sum(k * np.minimum(x, delta), axis=-1)


def lost_fraction(drift: float, slip_drift: float, exponent: float) -> float:
    """Share of the joint's stiffness its secant has lost at ``drift`` (m) on first loading (0: stuck, 1: all
    slipping), for a joint of slip drift ``slip_drift`` (m) and exponent ``exponent``."""
    return 1.0 - float(backbone({"stiffness": 1.0, "slip_drift": slip_drift, "exponent": exponent}, drift)) / drift


def add_sliders(spec: mujoco.MjSpec, params: dict, storey: int, lower_body: mujoco.MjsBody, upper_joint: str,
                lower_joint: str | None, timestep: float) -> float:
    """Add one joint's sliders and their tendons to ``spec`` (a ``mujoco.MjSpec``).

    Parameters
    ----------
    params : dict
        ``stiffness`` (N/m), ``slip_drift`` (m), ``exponent`` (1).
    storey : int
        The storey (1-based), for names.
    lower_body : mujoco.MjsBody
        The body below the storey (the table's base for storey 1): the sliders ride on it.
    upper_joint, lower_joint : str
        Slide joints of the floors above and below the storey (``lower_joint`` None for storey 1,
        whose lower body is the reference of the floor joints).
    timestep : float
        The model's integrator step (s).

    Returns
    -------
    float
        Total mass of the sliders (kg), which ride on ``lower_body``.
    """
    import mujoco

    k, delta = slider_elements(params["stiffness"], params["slip_drift"], params["exponent"])
    total = 0.0
    for j, (k_j, d_j) in enumerate(zip(k, delta)):
        name = f"{storey}_{j + 1}"
        mass = max(k_j * timestep ** 2 / SLIDER_STEP_PHASE ** 2, 1e-9)
        body = lower_body.add_body(name=f"slider{name}")
        body.mass = _BODY_MASS
        body.inertia = [_BODY_MASS * 1e-4] * 3
        joint = body.add_joint(name=f"slip{name}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
        joint.armature = mass
        joint.frictionloss = k_j * d_j
        joint.damping = [2.0 * SLIDER_DAMPING_RATIO * math.sqrt(k_j * mass), 0.0, 0.0]
        joint.solref_friction = [2.0 * timestep, 1.0]
        joint.solimp_friction = list(_SOLIMP)
        tendon = spec.add_tendon(name=f"jenkins{name}")
        tendon.wrap_joint(upper_joint, 1.0)
        if lower_joint is not None:
            tendon.wrap_joint(lower_joint, -1.0)
        tendon.wrap_joint(f"slip{name}", -1.0)
        tendon.stiffness = [k_j, 0.0, 0.0]
        tendon.springlength = [0.0, 0.0]
        total += _BODY_MASS
    return total


@register
class JointFriction(MechanismKind):
    name = "joint_friction"
    target = Target.STOREY
    params = (Param("stiffness", "N/m", "stiffness of the joint's stuck contact, lost at macro-slip", low=0.0,
                    low_open=True, example=200.0),
              Param("slip_drift", "m", "drift at which the whole contact slips (delta_max)", low=0.0, low_open=True,
                    high=0.1, example=0.005),
              Param("exponent", "1", "chi of the slip-drift density delta^chi (micro-slip: stiffness loss and "
                    "damping grow as A^(chi+1))", low=-0.95, high=2.0, example=-0.4))
    #: The added-mass diagnosis has no screening signature for it yet (it would call it "unexplained"); the
    #: real rig's twin fits it by re-simulation (:mod:`momentid.twin.fit`, used by
    #: :mod:`momentid.diagnosis.twin.path`: ``momentid diagnose`` of accelerometer-only recordings).
    truth_only = True
    real_rig = True
    mjcf_elements = True
    summary = ("Iwan joint across a storey: Jenkins sliders (spring + MuJoCo frictionloss) with slip drifts of "
               "density delta^chi up to delta_max (micro-slip)")

    def storey_tendon(self, mech: Mechanism, stiffness: float, damping: float, weight_above: float,
                      height: float) -> tuple[float, float]:
        """The storey tendon less the stuck joint's stiffness, which its sliders carry; damping unchanged."""
        return stiffness - dict(mech.parameters)["stiffness"], damping

    def elements(self, spec: mujoco.MjSpec, mech: Mechanism, place: Place, bodies: Sequence[mujoco.MjsBody],
                 timestep: float) -> dict[int, float]:
        """The joint's sliders and tendons, riding on the body below the storey (and the PGS solver);
        their mass is taken off that level.
        """
        # PGS: the table's huge armature swamps the Newton solver's convergence test, which then stops
        # before the sliders' friction constraints hold; PGS solves them one by one.
        spec.option.solver = mujoco.mjtSolver.mjSOL_PGS
        below, above = place.nodes
        taken = add_sliders(spec, dict(mech.parameters), mech.location, bodies[below], f"q{above}",
                            f"q{below}" if below > 0 else None, timestep)
        return {below: taken}

    def describe(self, place: Place, params: dict, std: dict) -> str:
        """The joint's stuck stiffness, slip drift, the force there and the slip-drift exponent."""
        slip = float(backbone(params, params["slip_drift"]))
        return (f"Joint friction (micro-slip) at {place.words}: the stuck joint's stiffness "
                f"{params['stiffness']:.4g} N/m, fully slipping at {1e3 * params['slip_drift']:.3g} mm of drift "
                f"under {slip:.3g} N, slip-drift exponent {params['exponent']:+.2f}.")
