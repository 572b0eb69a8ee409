"""The contract of a mechanism: one piece of physics beyond the linear shear model.

A mechanism kind is a subclass of :class:`MechanismKind` in its own module of
:mod:`momentid.mechanisms`, registered with :func:`momentid.mechanisms.registry.register`.
It declares, in one place, everything the rest of the project needs to know about it:

- its **name**, **target** (where it acts: a storey, a floor, a floor against the table, two floors
  or a sensor channel; :mod:`momentid.mechanisms.place`), **parameters** with their SI units and
  physical bounds (a scenario's ``[truth]`` record is validated against them);
- how it changes the **MuJoCo model** (:meth:`MechanismKind.storey_tendon`,
  :meth:`MechanismKind.added_mass_body`, :meth:`MechanismKind.elements`), or the **storey force** or **link
  force** (a floor against the table, or two floors) the simulator applies in its control callback
  (:meth:`MechanismKind.storey_force`, :meth:`MechanismKind.floor_force`), with an internal
  state the simulator integrates when the force has memory (:meth:`MechanismKind.has_state`,
  :meth:`MechanismKind.state_rate`), or the **sensor model**
  (:meth:`MechanismKind.distort` / :meth:`MechanismKind.correct`);
- its **screening signature**: the columns of the equation residual it would explain at a place
  (:meth:`MechanismKind.screen_equation`), for the table channel the replay residual
  (:meth:`MechanismKind.replay_column`), for a sensor fault the kinematic check's fit
  (:meth:`MechanismKind.from_kinematic`);
- its signature to the **damping pattern** of an identified C (:meth:`MechanismKind.damping_pattern`);
- how the diagnosis **refits** it (:attr:`MechanismKind.refit`, :meth:`MechanismKind.force_signal`)
  and turns the fitted coefficients back into a model record (:meth:`MechanismKind.as_records`);
- its **report wording** (:meth:`MechanismKind.describe`).

``truth_only`` kinds can be built into a rig (hidden scenarios) but are not in the diagnosis
library: the diagnosis must call them "unexplained".

Every hook that concerns one mechanism receives its :class:`~momentid.mechanisms.place.Place`; the
diagnosis never reads a location's keys or a kind's name.

This package sits below :mod:`momentid.lab` and :mod:`momentid.diagnosis`: it imports only
:mod:`momentid.core`, :mod:`momentid.errors`, numpy and mujoco.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, replace
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from momentid.core.series import RunData
from momentid.core.structure import Mechanism, Structure
from momentid.errors import ModelError
from momentid.mechanisms.native import NativeLaw
from momentid.mechanisms.place import Place, Target
from momentid.mechanisms.sizing import Sized, Sizer, size_correction

if TYPE_CHECKING:
    import mujoco

__all__ = ["GRAVITY", "Target", "Place", "Refit", "Param", "MechanismKind", "SensorFault", "Screened",
           "EquationSignals", "one_coefficient", "storey_to_floor", "drifts", "registered_instance", "SensorStage",
           "Signal", "ToParams"]

GRAVITY = 9.81   # m/s^2, as in MuJoCo's default option

#: What a force law takes and returns: a float (the simulator's callback, at one instant) or an array
#: (n,) (the diagnosis's screening and refits, over a record).
Signal = float | np.ndarray
#: ``to_params(coef, std) -> (parameters, std)``: a signature's fitted coefficients and their standard
#: errors (arrays, one per column) named as the kind's parameters.
ToParams = Callable[[np.ndarray, np.ndarray], tuple[dict, dict]]


class Refit(enum.Enum):
    """How the diagnosis sizes a screened candidate before it is re-simulated.

    ``RESIMULATE``: a nonlinear force at a link, refitted by errors-in-variables together with the
    linear model, then its size searched by re-simulation.  ``ATTACHMENT``: a change of the rig the
    identified model partly absorbed, kept on the lab's nominal model.  ``DAMPING_PATTERN``: a linear
    term the identified C holds, read from its pattern.  ``CORRECT_DATA``: a sensor fault, undone on
    the recordings, which are then re-identified.  ``SEARCH``: several parameters searched together by
    re-simulation (a tuned-mass damper's mass, frequency and damping).

    Each kind sizes itself (:meth:`MechanismKind.size`, :mod:`momentid.mechanisms.sizing`); the value
    groups kinds for the stages that screen and combine them.  A kind states the rest of what its
    sizing needs: :meth:`MechanismKind.force_signal` (``RESIMULATE``), :meth:`MechanismKind.attachment_matrices`
    (``ATTACHMENT``), :meth:`MechanismKind.damping_pattern` (``DAMPING_PATTERN``),
    :meth:`MechanismKind.correct` (``CORRECT_DATA``).
    """

    RESIMULATE = "resimulate"
    ATTACHMENT = "attachment"
    DAMPING_PATTERN = "damping pattern"
    CORRECT_DATA = "correct data"
    SEARCH = "search"


@dataclass(frozen=True)
class Param:
    """One parameter of a mechanism: name, SI unit, meaning and physical bounds.

    ``low`` / ``high`` bound the value; ``low_open`` excludes ``low`` itself (``> low``);
    ``example`` is a typical value on the paper's rig (docs, tests).
    """

    name: str
    unit: str
    meaning: str
    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False
    example: float = 1.0

    @property
    def bounded(self) -> bool:
        """Whether the parameter has a finite lower or upper bound."""
        return self.low > -math.inf or self.high < math.inf

    def within(self, value: float) -> bool:
        """True when ``value`` is within the bounds."""
        above = value > self.low if self.low_open else value >= self.low
        return above and value <= self.high

    def admits(self, value: float) -> bool:
        """True when ``value`` is finite and within the bounds."""
        return math.isfinite(value) and self.within(value)

    def expected(self) -> str:
        """The bounds in words, for error messages (``"a number > 0 (N)"``)."""
        lo = f"{'>' if self.low_open else '>='} {self.low:g}" if self.low > -math.inf else ""
        hi = f"<= {self.high:g}" if self.high < math.inf else ""
        bounds = " and ".join(b for b in (lo, hi) if b)
        return f"a number{' ' + bounds if bounds else ''} ({self.unit}): {self.meaning}"


@dataclass(frozen=True)
class Screened:
    """A mechanism's fitted signature at one place, before the diagnosis names it a candidate."""

    place: Place
    parameters: dict
    std: dict
    explained: float


@dataclass(frozen=True)
class EquationSignals:
    """Band-limited signals of the training runs, stacked in time, for equation screening.

    Attributes
    ----------
    a, v, q : ndarray, shape (n, d)
        Floor absolute accelerations (m/s^2), relative velocities (m/s), displacements (m).
    added_mass : ndarray, shape (n, d)
        Each sample's run's added masses (kg).
    drift, drift_velocity : ndarray, shape (n, d)
        Storey drifts (m) and their rates (m/s).
    jerk : ndarray, shape (n, d)
        Time derivative of ``a`` (m/s^3).
    masses : ndarray, shape (d,)
        Floor masses of the model screened against (kg).
    C, K : ndarray, shape (d, d)
        Damping (N s/m) and stiffness (N/m) matrices of that model.
    sample_rate, f_top : float
        Sample rate and the model's highest natural frequency (Hz).
    attachment_response : callable
        ``(a_j, frequency, damping_ratio) -> x``: absolute acceleration (n,) of a unit oscillator
        driven at its base by ``a_j`` (the diagnosis's linear simulator).
    """

    a: np.ndarray
    v: np.ndarray
    q: np.ndarray
    added_mass: np.ndarray
    drift: np.ndarray
    drift_velocity: np.ndarray
    jerk: np.ndarray
    masses: np.ndarray
    C: np.ndarray
    K: np.ndarray
    sample_rate: float
    f_top: float
    attachment_response: Callable[[np.ndarray, float, float], np.ndarray]

    @property
    def storeys(self) -> int:
        """Number of storeys ``d``."""
        return self.a.shape[1]

    def stretch(self, place: Place) -> np.ndarray:
        """The place's stretch (n,) (m): a storey's drift, a floor's displacement against the table, ..."""
        return place.stretch(self.q)

    def stretch_rate(self, place: Place) -> np.ndarray:
        """The rate (n,) (m/s) of :meth:`stretch`."""
        return place.stretch(self.v)

    def columns(self, phi: np.ndarray, place: Place) -> np.ndarray:
        """Floor forces (n, d) of a force ``phi`` (n,) at ``place`` (resisting a link's stretch)."""
        return place.columns(phi, self.storeys)

    def linear_confounds(self, place: Place) -> list[np.ndarray]:
        """A spring and a dashpot at ``place``, which the identified model may have absorbed there: the
        confounds of a force screened at a link."""
        return [self.columns(self.stretch(place), place), self.columns(self.stretch_rate(place), place)]

    def storey_columns(self, phi: np.ndarray, s: int) -> np.ndarray:
        """Floor forces (n, d) of a force ``phi`` (n,) resisting storey ``s``'s drift (0-based)."""
        return self.columns(phi, Place(Target.STOREY, s + 1))

    def floor_columns(self, phi: np.ndarray, j: int) -> np.ndarray:
        """Floor forces (n, d) of a force ``phi`` (n,) on floor ``j`` alone (0-based)."""
        return self.columns(phi, Place(Target.FLOOR, j + 1))


#: ``fit(columns, confounds, place, to_params) -> list[Screened]``: the screening's held-out least
#: squares of the residual on signature ``columns`` and ``confounds`` (each (n, d) floor forces);
#: ``to_params(coef, std) -> (parameters, std)`` names the fitted coefficients.  Empty when the
#: columns cannot be fitted (one of them is zero).
Fitter = Callable[[list, list, Place, Callable], "list[Screened]"]


def storey_to_floor(f: np.ndarray) -> np.ndarray:
    """Generalised floor forces from storey forces resisting the drifts: shape (..., d)."""
    out = -f.copy()
    out[..., :-1] += f[..., 1:]
    return out


def drifts(q: np.ndarray) -> np.ndarray:
    """Storey drifts ``q_i - q_(i-1)`` from floor displacements (..., d)."""
    out = q.copy()
    out[..., 1:] -= q[..., :-1]
    return out


def one_coefficient(name: str) -> ToParams:
    """Parameters and standard errors of a signature whose coefficient is the parameter itself."""
    return lambda c, e: ({name: float(c[0])}, {name: float(e[0])})


def registered_instance(cls: type) -> MechanismKind:
    """The registry's instance of the kind ``cls`` (what an unpickled kind becomes)."""
    instance = cls.__dict__.get("registered")
    if instance is None:
        raise ModelError(f"{cls.__qualname__} is not a registered mechanism kind")
    return instance


class MechanismKind:
    """Base class of a mechanism kind; see the module docstring for the contract.

    Subclasses set the class attributes and override the hooks their physics needs; the
    defaults are "no effect".  One instance per kind lives in the registry.
    """

    #: Identifier used in scenarios' ``[truth]``, reports and the CLI.
    name: ClassVar[str]
    #: Where it acts (:class:`~momentid.mechanisms.place.Target`).
    target: ClassVar[Target]
    #: Parameters of the model record (a scenario's ``[truth]`` entry), with bounds.
    params: ClassVar[tuple[Param, ...]] = ()
    #: The coefficient the screening fits and the refit refines (None: not diagnosable alone).
    fitted: ClassVar[Param | None] = None
    #: Built into rigs but outside the diagnosis library (its answer is "unexplained").
    truth_only: ClassVar[bool] = False
    #: The open search's law at its target (:mod:`momentid.diagnosis.added_mass.open_search` builds its records).
    open_search: ClassVar[bool] = False
    #: Fitted by re-simulation on a real rig's MuJoCo twin (the accelerometer-only diagnosis,
    #: :mod:`momentid.diagnosis.twin.path`), whatever ``truth_only`` says of the added-mass one.
    real_rig: ClassVar[bool] = False
    #: A force the MJCF cannot express (a storey force, or a link force between a floor and the table
    #: or two floors), applied by the simulator's control callback.
    callback: ClassVar[bool] = False
    #: Its storey force takes a fraction of the storey's own stiffness (the callback needs it).
    needs_stiffness: ClassVar[bool] = False
    #: A sensor fault the kinematic check (``a_j = zdd + q_j''``) tests (:meth:`from_kinematic`):
    #: channels found consistent rule it out.
    kinematic: ClassVar[bool] = False
    #: How the diagnosis sizes it (None for truth-only kinds).
    refit: ClassVar[Refit | None] = None
    #: A force that opposes its place's stretch rate: a linear identification takes it into C as an
    #: equivalent viscous damping, so where C's pattern shows a damper, this kind there is its rival.
    dissipative: ClassVar[bool] = False
    #: A linear storey spring (a loss of stiffness) the identified K takes in, in every run alike: an
    #: identified model shows it only through what the added masses change; the lab's nominal model
    #: shows it whole (see :func:`~momentid.diagnosis.added_mass.screening.linear_springs_left`).
    linear_spring: ClassVar[bool] = False
    #: A kind that adds bodies, joints and tendons of its own to the MJCF at its place (:meth:`elements`),
    #: e.g. ``joint_friction``'s sliders across a storey, ``tuned_mass_damper``'s body hung on a floor.
    mjcf_elements: ClassVar[bool] = False
    #: One line for the docs and ``describe``.
    summary: ClassVar[str] = ""

    #: The registry's one instance of this kind (set by :func:`~momentid.mechanisms.registry.register`).
    registered: ClassVar[MechanismKind | None] = None

    def __reduce__(self):
        # One instance per kind: a kind sent to or from another process (a diagnosis's worker) is the
        # registry's instance there, so that kinds compare by identity everywhere.
        return registered_instance, (type(self),)

    # ---------------------------------------------------------------- where

    def place(self, index: int | tuple[int, int] | list[int] | str) -> Place:
        """The place of this kind at ``index`` (a record's location; a list of two floors as a pair)."""
        return Place(self.target, tuple(index) if isinstance(index, list) else index)

    def places(self, storeys: int) -> tuple[Place, ...]:
        """Every place this kind can sit at in a rig of ``storeys`` storeys."""
        return self.target.places(storeys)

    # ---------------------------------------------------------------- the record

    def validate(self, mech: Mechanism, storeys: int) -> None:
        """Raise :class:`ModelError` unless ``mech`` is a valid record of this kind in a rig of
        ``storeys`` storeys (place in range, every parameter present and within bounds)."""
        if self.target is Target.CHANNEL:
            raise ModelError(f"mechanism {self.name!r} is a sensor fault: it has no place in the rig's model")
        problem = self.place(mech.location).problem(storeys)
        if problem is not None:
            raise ModelError(f"mechanism {self.name!r}: {self.target.key} {mech.location}, expected {problem}")
        values = dict(mech.parameters)
        for p in self.params:
            if p.name not in values or not p.admits(values[p.name]):
                raise ModelError(f"mechanism {self.name!r}: {p.name} = {values.get(p.name)!r}, "
                                 f"expected {p.expected()}")
        extra = set(values) - {p.name for p in self.params}
        if extra:
            raise ModelError(f"mechanism {self.name!r}: unknown parameters {sorted(extra)}, "
                             f"expected {[p.name for p in self.params]}")

    # ---------------------------------------------------------------- the lab: MuJoCo model and sensors

    def storey_tendon(self, mech: Mechanism, stiffness: float, damping: float, weight_above: float,
                      height: float) -> tuple[float, float]:
        """(stiffness N/m, damping N s/m) of the storey tendon ``mech`` sits on, changed by it.

        ``weight_above`` is the mass (kg) of the floors and added masses above the storey,
        ``height`` the storey's height (m).
        """
        return stiffness, damping

    def elements(self, spec: mujoco.MjSpec, mech: Mechanism, place: Place, bodies: Sequence[mujoco.MjsBody],
                 timestep: float) -> dict[int, float]:
        """For ``mjcf_elements`` kinds: add the bodies, joints and tendons of ``mech`` at ``place`` to
        ``spec`` (``mujoco.MjSpec``): across a storey (riding on the body below it), hung on a floor, ...

        ``bodies`` are the table's (``bodies[0]``) and the floors' ``mujoco.MjsBody`` (``bodies[j]``: floor
        ``j``, on the slide joint ``q<j>``); ``timestep`` is the integrator's step (s).  Returns the mass
        (kg) the elements take off each level (``{level: kg}``): a body riding on a floor and counted in
        its stated mass."""
        return {}

    def added_mass_body(self, mech: Mechanism, body: mujoco.MjsBody, mass: float) -> None:
        """Change the MJCF body (``mujoco.MjsBody``) of the added mass ``mass`` (kg) on ``mech``'s floor."""

    def storey_force(self, params: dict, drift: Signal, drift_velocity: Signal, time: float,
                     stiffness: float | None) -> Signal:
        """Force (N) the storey exerts against its drift (positive resists); floats or arrays.

        Only for ``callback`` kinds on ``Target.STOREY``.  ``params`` maps parameter names to values;
        ``time`` is the time since the run started (s); ``stiffness`` the storey's linear stiffness
        (N/m) when ``needs_stiffness``.
        """
        raise NotImplementedError(f"{self.name} is not a callback storey force")

    def floor_force(self, params: dict, displacement: Signal, velocity: Signal, time: float,
                    stiffness: float | None) -> Signal:
        """Force (N) a ``callback`` kind on ``Target.FLOOR_TABLE`` or ``Target.FLOORS`` exerts across
        its link (positive resists the link's stretch: its floor's displacement relative to the table,
        or its upper floor's relative to its lower one); floats or arrays.

        The arguments are those of :meth:`storey_force`, with the link's stretch (m) and its rate
        (m/s) in place of a storey's drift; ``stiffness`` is None.
        """
        raise NotImplementedError(f"{self.name} is not a callback link force")

    def link_law(self, params: dict, place: Place, stiffness: float | None) -> Callable[..., float]:
        """The force across ``place``'s link as the simulator's callback calls it, about four times a
        step: a function of floats ``(stretch, rate, time)`` (and the keyword ``state`` when the force
        has memory) returning a float.

        The default binds ``params`` and ``stiffness`` to :meth:`storey_force` (a storey) or
        :meth:`floor_force` (another link).  A kind may return a leaner function with the same
        arithmetic on floats, bit for bit (the callback's Python is most of a replay's time; tested
        against the law in ``tests/test_model.py``).
        """
        law = self.storey_force if place.target is Target.STOREY else self.floor_force
        return lambda x, v, t, **state: law(params, x, v, t, stiffness, **state)

    def native_law(self) -> NativeLaw | None:
        """For ``callback`` kinds: the force law (and its state's rate) as native code, which the simulator
        calls from MuJoCo's step with no Python (:mod:`momentid.mechanisms.native`), taking
        :meth:`native_parameters`; the same law as :meth:`storey_force` / :meth:`floor_force` to round-off.
        None: the simulator calls the Python law (:meth:`link_law`)."""
        return None

    def native_parameters(self, params: dict, stiffness: float | None) -> list[float]:
        """The parameter vector :meth:`native_law` takes: the values of :attr:`params` in order, then the
        storey's ``stiffness`` (N/m) when the kind ``needs_stiffness``."""
        values = [float(params[p.name]) for p in self.params]
        return values + [float(stiffness)] if self.needs_stiffness else values

    def has_state(self, params: dict) -> bool:
        """True when the force has memory: one internal state the simulator integrates with the
        motion (a MuJoCo actuator's activation, see :mod:`momentid.lab.rig`), passed to
        :meth:`storey_force` / :meth:`floor_force` as the keyword ``state``."""
        return False

    def state_rate(self, params: dict, state: float, displacement: float, velocity: float) -> float:
        """Time derivative of the internal state (:meth:`has_state`) at the link's stretch
        ``displacement`` (m) changing at ``velocity`` (m/s)."""
        raise NotImplementedError(f"{self.name} has no internal state")

    def distort(self, time: np.ndarray, x: np.ndarray, params: dict) -> np.ndarray:
        """A sensor fault: the reading (n,) of a channel whose true signal is ``x`` (n,)."""
        raise NotImplementedError(f"{self.name} is not a sensor fault")

    def correct(self, time: np.ndarray, x: np.ndarray, params: dict) -> np.ndarray:
        """A sensor fault undone: the true signal (n,) from the faulty reading ``x`` (n,)."""
        raise NotImplementedError(f"{self.name} is not a sensor fault")

    def correct_run(self, run: RunData, place: Place, params: dict) -> RunData:
        """``run`` with this sensor fault undone on the channel ``place`` (unchanged if not recorded)."""
        channel = place.index
        if not run.has(channel):
            return run
        j = run.channels.index(channel)
        values = run.values.copy()
        values[:, j] = self.correct(run.time, run.values[:, j], params)
        return replace(run, values=values)

    # ---------------------------------------------------------------- the diagnosis

    def screen_equation(self, signals: EquationSignals, fit: Fitter, place: Place) -> list[Screened]:
        """Fits of this kind's signature in the floor-force residual at ``place`` (one of :meth:`places`).

        ``fit`` (:data:`Fitter`) is the screening's held-out least squares: each column an (n, d)
        array of floor forces; confounds are linear terms the identified model may have absorbed.
        Returns the fits, none when the signature does not apply here.
        """
        return []

    def replay_column(self, sim: np.ndarray, sim_rate: np.ndarray, step: np.ndarray
                      ) -> tuple[np.ndarray, ToParams] | None:
        """Signature of a fault on the table channel in the replay residual, or None.

        ``sim``: band-limited replayed floor accelerations (n, d); ``sim_rate``: their time
        derivative; ``step``: the replay of a unit table acceleration.  Returns
        ``(column (n, d), to_params)`` with ``to_params(c, e) -> (params, std)``.
        """
        return None

    def from_kinematic(self, fit: Any) -> tuple[dict, dict, float] | None:
        """For ``kinematic`` kinds: (parameters, standard errors, share explained) of this fault from the
        kinematic check's fit on one channel (:class:`~momentid.diagnosis.added_mass.kinematic_check.SensorFit`)."""
        return None

    def force_signal(self, params: dict, stretch: np.ndarray, rate: np.ndarray, weight_above: float) -> np.ndarray:
        """For ``RESIMULATE`` kinds: the force (n,) at the place per unit of the fitted coefficient, from
        the place's stretch (m) and its rate (m/s), each (n,), and the added mass (kg) it carries
        (:meth:`~momentid.mechanisms.place.Place.above`)."""
        raise NotImplementedError(f"{self.name} has no force signal")

    def size(self, sizer: Sizer, place: Place, params: dict, std: dict) -> Sized:
        """How the diagnosis sizes a screened candidate of this kind at ``place``, from its screened
        ``params`` and their standard errors ``std``: the model it sits on and its parameters
        (:mod:`momentid.mechanisms.sizing`: a kind names its way among its bases, or brings its own)."""
        raise ModelError(f"{self.name} is not sized by the diagnosis: it is not in its library")

    def damping_pattern(self, place: Place, storeys: int) -> np.ndarray:
        """For ``DAMPING_PATTERN`` kinds: its term (d, d) in the damping matrix C per unit of the fitted
        coefficient at ``place`` (a dashpot across a link: ``w w^T``, ``w`` its direction)."""
        w = place.direction(storeys)
        return np.outer(w, w)

    def attachment_matrices(self, M: np.ndarray, C: np.ndarray, K: np.ndarray, floor: int, mass: float,
                            frequency: float, damping_ratio: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For ``ATTACHMENT`` kinds: M, C, K (d+1, d+1) of the model (d, d) with ``mass`` (kg) on floor
        ``floor`` (0-based) on its attachment of natural ``frequency`` (Hz) and ``damping_ratio`` (the
        replay screening's extra degree of freedom)."""
        raise NotImplementedError(f"{self.name} is not an attachment")

    def physical(self, params: dict) -> bool:
        """A passive rig: the fitted coefficient within its physical bounds (absent: 0)."""
        return self.fitted is None or not self.fitted.bounded or self.fitted.within(params.get(self.fitted.name, 0.0))

    def as_records(self, place: Place, params: dict) -> tuple[Mechanism, ...]:
        """The model records (for :func:`momentid.lab.rig.build_spec`) of a diagnosed candidate."""
        if self.target is Target.CHANNEL:
            return ()
        return (Mechanism(self.name, place.index, tuple((p.name, params[p.name]) for p in self.params)),)

    def replay_structure(self, structure: Structure, place: Place, params: dict, static: bool) -> Structure:
        """The structure to build the augmented model on (a mechanism expressed through it)."""
        return structure

    def in_lab_terms(self, params: dict, std: dict, place: Place,
                     nominal: Structure | None) -> tuple[dict, dict]:
        """Fitted parameters and standard errors as the report states them."""
        return params, std

    def twin_parameters(self, stiffness: float, damping: float, drift: float, velocity: float) -> dict:
        """For ``real_rig`` kinds fitted by :func:`momentid.twin.fit.fit_twin`: per parameter ``(scale, start,
        low, high)`` (the parameter's units) at a storey of linear stiffness ``stiffness`` (N/m) and viscous
        damping ``damping`` (N s/m) whose training trials reach ``drift`` (m) and ``velocity`` (m/s) at their
        peaks: the fit searches ``value / scale`` within ``[low, high]`` from ``start``."""
        raise NotImplementedError(f"{self.name} declares no fit on a real rig's twin")

    def describe(self, place: Place, params: dict, std: dict) -> str:
        """The report's sentence naming this mechanism with its fitted parameters."""
        p = ", ".join(f"{k} = {v:.4g}" + (f" +/- {std[k]:.2g}" if k in std else "") for k, v in params.items())
        return f"Best explanation: {self.name.replace('_', ' ')} at {place.words}: {p}."


class SensorStage(enum.Enum):
    """Where in a channel's front end a sensor fault acts (:func:`momentid.lab.sensors.measure` applies
    every fault of ``[sensors.channel.X]`` at its stage, in this order)."""

    SIGNAL = "signal"    # on the true signal, before the anti-alias filter and the sampling (a clock offset)
    GAIN = "gain"        # on the sampled signal, before the instrument's own bias (a sensitivity)
    OFFSET = "offset"    # after the instrument's own bias (an offset)
    RANGE = "range"      # on the reading, noise and quantisation included (a saturation)


class SensorFault(MechanismKind):
    """A fault of one sensor channel: one model, the lab's and the diagnosis's.

    The lab applies it from a scenario's ``[sensors.channel.X]`` (the key :attr:`setting`, at its
    :attr:`stage`) through :meth:`distort`; the diagnosis undoes it on the recordings
    (:meth:`correct`, ``Refit.CORRECT_DATA``) when it can be undone (:attr:`reversible`).  A subclass
    states its fault's term in the floor equations on a floor's accelerometer or displacement channel
    (:meth:`channel_signature`), which screening fits on every channel, or what a look at the recorded
    channel alone finds (:meth:`inspect`).
    """

    target = Target.CHANNEL
    refit = Refit.CORRECT_DATA
    #: The key of ``[sensors.channel.X]`` that states this fault in a scenario, with its unit and bounds
    #: (its value is the fault's :attr:`fitted` parameter).
    setting: ClassVar[Param]
    #: Where in the channel's front end the lab applies it.
    stage: ClassVar[SensorStage] = SensorStage.OFFSET
    #: The fault can be undone on a recording (:meth:`correct`); one that cannot is applied to the
    #: model's readings instead when the diagnosis replays it.
    reversible: ClassVar[bool] = True

    def record(self, channel: str, value: float) -> Mechanism:
        """This fault on ``channel`` at ``value`` (its :attr:`setting`) as the lab applies it."""
        return Mechanism(self.name, channel, ((self.fitted.name, float(value)),))

    def inspect(self, run: RunData, channel: str) -> tuple[dict, float] | None:
        """What the recorded ``channel`` of ``run`` shows of this fault by itself, with no model: its
        parameters and the share of the channel's samples it holds, or None (the default: a fault only
        the model-based checks see)."""
        return None

    def size(self, sizer: Sizer, place: Place, params: dict, std: dict) -> Sized:
        """Sized by undoing the fault on the training runs and identifying them again
        (:func:`~momentid.mechanisms.sizing.size_correction`)."""
        return size_correction(self, sizer, place, params, std)

    def channel_signature(self, signals: EquationSignals, group: str, floor: int
                          ) -> tuple[np.ndarray, list[np.ndarray], ToParams] | None:
        """The fault's term on channel ``group`` (``"a"`` or ``"q"``) of ``floor`` (0-based) in the
        floor-force residual: ``(column (n, d), confounds, to_params)``, or None where it has none."""
        return None

    def screen_equation(self, signals: EquationSignals, fit: Fitter, place: Place) -> list[Screened]:
        """The fit of :meth:`channel_signature` on the channel ``place`` (``"a<j>"`` or ``"q<j>"``; none on
        another channel, or where the fault has no term)."""
        channel = str(place.index)
        if channel[0] not in "aq" or not channel[1:].isdigit():
            return []
        got = self.channel_signature(signals, channel[0], place.level - 1)
        if got is None:
            return []
        column, confounds, to_params = got
        return fit([column], confounds, place, to_params)
