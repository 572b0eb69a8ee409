"""The real rig as the twin's fit sizes it (:class:`FittedRig`), the recorded trials it is fitted to
(:class:`Trial`), and the fit's starting points with physics beyond the linear twin.

:mod:`momentid.twin.fit` fits a :class:`FittedRig` to trials by re-simulation (and re-exports these names).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from momentid.core.series import TABLE_MOTION, RunData
from momentid.core.structure import Mechanism
from momentid.errors import IdentificationError, MomentidError
from momentid.estimation.noise import quiet_lead_in
from momentid.lab import resim
from momentid.lab.rig_model import RigModel
from momentid.lab.tendons import pair_coefficient
from momentid.mechanisms import joint_friction as jf
from momentid.mechanisms import registry

__all__ = ["FittedRig", "friction_records", "Trial", "trial", "FIT_ENERGY", "REFERENCE_DRIFT", "START_DAMPING_SHARE",
           "storey_levels", "joint_tendon_stiffness", "twin_modes", "mechanism_start", "friction_start"]

#: Fraction of a training trial's floor-signal energy the fit re-simulates (the rest is a quiet tail).
FIT_ENERGY = 0.99
#: Drift (m) at which the fit states a joint's stiffness loss (storey drifts of a bench rig: 0.1-10 mm).
REFERENCE_DRIFT = 1e-3
#: Share of the linear twin's viscous damping an augmented fit starts from.
START_DAMPING_SHARE = 0.3


@dataclass(frozen=True)
class FittedRig:
    """A real rig as the twin's fit sizes it: the parameters it searches, and the rig they make
    (:meth:`rig`, built and re-simulated by the lab: :mod:`momentid.lab.resim`).

    Attributes
    ----------
    masses : ndarray, shape (d,)
        Floor masses (kg).
    stiffness : ndarray, shape (d, d)
        K (N/m) of the stuck joints (small drifts), symmetric positive definite.
    damping_ratio : ndarray, shape (d,)
        Modal viscous damping ratios (1) on the modes of (M, K), ascending frequency.
    friction : tuple of Mechanism
        Records of real-rig kinds (``joint_friction``, ``cubic_spring``, ``quadratic_damping``, ``bouc_wen``; at
        most one of a kind per storey; the field keeps its first kind's name); empty: the linear twin.
    gain, offset : ndarray, shape (d,)
        Floor sensors' gains (1) and clock offsets (s, positive: the sensor lags the table's).
    table_motion : tuple of str
        The table sensor's other motions (:data:`~momentid.core.series.TABLE_MOTION` names) the twin is also
        driven by (:meth:`drive`); empty: the table's shaking axis alone.
    table_gains : ndarray, shape (len(table_motion),)
        Each motion's gain into the table acceleration the twin feels (1 for an acceleration, m/s for a rate).
    """

    masses: np.ndarray
    stiffness: np.ndarray
    damping_ratio: np.ndarray
    friction: tuple = ()
    gain: np.ndarray = field(default=None)
    offset: np.ndarray = field(default=None)
    table_motion: tuple = ()
    table_gains: np.ndarray = field(default=None)

    def __post_init__(self):
        d = len(self.masses)
        if self.gain is None:
            object.__setattr__(self, "gain", np.ones(d))
        if self.offset is None:
            object.__setattr__(self, "offset", np.zeros(d))
        if self.table_gains is None:
            object.__setattr__(self, "table_gains", np.zeros(len(self.table_motion)))
        if len(self.table_gains) != len(self.table_motion):
            raise ValueError(f"table gains {list(self.table_gains)} for motions {list(self.table_motion)}: "
                             f"expected one gain per motion")

    def driven_by(self, motion: Sequence[str]) -> FittedRig:
        """The same rig driven by the table motions ``motion`` (names) too, each at gain zero."""
        return replace(self, table_motion=tuple(motion), table_gains=np.zeros(len(motion)))

    def drive(self, tr: Trial) -> np.ndarray:
        """The table acceleration (m/s^2, shape (n,)) the twin feels on ``tr``: the recorded shaking axis plus
        :attr:`table_gains` times the trial's :attr:`table_motion`.

        Raises
        ------
        IdentificationError
            ``tr`` lacks a motion the twin is driven by.
        """
        if not self.table_motion:
            return tr.zdd
        missing = [c for c in self.table_motion if c not in tr.motion_channels]
        if missing:
            raise IdentificationError(f"trial {tr.name!r}: no {', '.join(missing)} (the table sensor's other "
                                      f"motions); expected them, as the twin is driven by them")
        index = [tr.motion_channels.index(c) for c in self.table_motion]
        return tr.zdd + tr.motion[:, index] @ np.asarray(self.table_gains, float)

    @property
    def storeys(self) -> int:
        """Number of storeys ``d``."""
        return len(self.masses)

    @property
    def damping(self) -> np.ndarray:
        """C (N s/m), shape (d, d)."""
        return resim.modal_damping(self.masses, self.stiffness, self.damping_ratio)

    def linear(self) -> FittedRig:
        """The same rig without its friction."""
        return replace(self, friction=())

    def rig(self) -> RigModel:
        """The rig MuJoCo simulates (sensors apart): K and C as tendons, the friction on its storeys."""
        return RigModel.from_matrices(self.masses, self.stiffness, self.damping,
                                      np.full(self.storeys, resim.STOREY_HEIGHT), base_mass=resim.BASE_MASS,
                                      mechanisms=self.friction)

    def to_dict(self) -> dict:
        """The rig as a JSON-ready dict: masses (kg), K (N/m), damping ratios, each mechanism record with its place,
        the sensors' gains and clock offsets (s), the table motions' gains.
        """
        return {"masses_kg": np.asarray(self.masses).tolist(), "stiffness_n_per_m": np.asarray(self.stiffness).tolist(),
                "damping_ratio": np.asarray(self.damping_ratio).tolist(),
                "friction": [{"type": m.type, **registry.get(m.type).place(m.location).location,
                              **dict(m.parameters)} for m in self.friction],
                "sensor_gain": np.asarray(self.gain).tolist(), "sensor_offset_s": np.asarray(self.offset).tolist(),
                "table_motion_gains": dict(zip(self.table_motion, np.asarray(self.table_gains, float).tolist()))}


def friction_records(storeys: Iterable[int], params: Iterable[dict]) -> tuple[Mechanism, ...]:
    """``joint_friction`` records from per-storey ``params`` dicts."""
    return tuple(Mechanism("joint_friction", int(s), tuple(p.items())) for s, p in zip(storeys, params))


@dataclass(frozen=True)
class Trial:
    """One recorded trial: table acceleration, floor accelerations, where its shaking starts.

    Attributes
    ----------
    name : str
    zdd : ndarray, shape (n,)
    a : ndarray, shape (n, d)
    dt : float
    start : int
        First sample after the quiet lead-in.
    fit_stop : int
        Samples re-simulated while fitting (:data:`FIT_ENERGY`).
    norm : float
        ``sqrt(sum |a - mean|^2)`` after ``start`` (the NRMSE's denominator).
    motion : ndarray, shape (n, k)
        The table sensor's other motions (m/s^2, rad/s), each less its mean over the quiet lead-in.
    motion_channels : tuple of str, length k
        Their names (:data:`~momentid.core.series.TABLE_MOTION`).
    """

    name: str
    zdd: np.ndarray
    a: np.ndarray
    dt: float
    start: int
    fit_stop: int
    norm: float
    motion: np.ndarray = field(default=None)
    motion_channels: tuple = ()

    def __post_init__(self):
        if self.motion is None:
            object.__setattr__(self, "motion", np.zeros((len(self.zdd), 0)))


def trial(run: RunData, d: int) -> Trial:
    """A :class:`Trial` from a run with ``zdd`` and ``a1..ad`` (m/s^2), and the table's other motions it has."""
    a = run.group("a", d)
    start = quiet_lead_in(run)
    active = a[start:]
    energy = np.cumsum(np.sum(a ** 2, axis=1))
    stop = int(min(len(a), np.searchsorted(energy, FIT_ENERGY * energy[-1]) + 1))
    names = tuple(c for c in TABLE_MOTION if c in run.channels)
    motion = np.column_stack([np.asarray(run[c], float) for c in names]) if names else np.zeros((len(a), 0))
    motion = np.nan_to_num(motion - np.nanmean(motion[:start + 1], axis=0))
    return Trial(run.name, np.asarray(run["zdd"], float), a, 1.0 / run.sample_rate, start, max(stop, start + 2),
                 float(np.sqrt(np.sum((active - active.mean(axis=0)) ** 2))), motion, names)


def storey_levels(model: FittedRig, trials: Sequence[Trial]) -> dict[int, tuple[float, float, float, float]]:
    """Per storey ``(stiffness N/m, viscous damping N s/m, peak drift m, peak drift velocity m/s)`` of
    ``model``'s linear part and the ``trials``: the drift and its velocity from the storey's recorded
    relative acceleration (floor less the level below; the table's for storey 1) at its 99th percentile,
    divided by the squared and the first power of mode 1's angular frequency."""
    omega = float(np.min(twin_modes(model)[0]))
    K, C = np.asarray(model.stiffness), np.asarray(model.damping)
    out = {}
    for s in range(1, model.storeys + 1):
        rel = [np.abs(t.a[t.start:, s - 1] - (t.zdd[t.start:] if s == 1 else t.a[t.start:, s - 2])) for t in trials]
        peak = max(float(np.percentile(r, 99)) for r in rel)
        out[s] = (pair_coefficient(K, s - 1, s), pair_coefficient(C, s - 1, s), peak / omega ** 2, peak / omega)
    return out


def joint_tendon_stiffness(K: np.ndarray, mech: Mechanism) -> float:
    """The stiffness (N/m) of the tendon in K between the two levels a joint mechanism ``mech`` acts across
    (its kind's :class:`~momentid.mechanisms.place.Place` ``nodes``; the tendons of
    :func:`momentid.lab.tendons.tendon_layout`)."""
    nodes = registry.get(mech.type).place(mech.location).nodes
    return pair_coefficient(K, *nodes)


def twin_modes(model: FittedRig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(omega (rad/s), zeta, residues (d modes, d floors))`` of the twin's stuck (small-drift) linear part,
    in :func:`~momentid.diagnosis.modal.check.replay`'s form."""
    m = np.asarray(model.masses, float)
    m_half = np.sqrt(m)
    w2, psi = np.linalg.eigh(np.asarray(model.stiffness) / m_half[:, None] / m_half[None, :])
    phi = psi / m_half[:, None]                       # mass-normalised shapes, columns
    gamma = phi.T @ m
    return np.sqrt(w2), np.asarray(model.damping_ratio, float), gamma[:, None] * phi.T


def mechanism_start(linear: FittedRig, kind_name: str, storeys: Iterable[int], trials: Sequence[Trial]) -> FittedRig:
    """A start for the augmented fit with a real-rig kind other than ``joint_friction`` in ``storeys``: each
    record at its kind's declared start (:meth:`~momentid.mechanisms.base.MechanismKind.twin_parameters`
    at the storey's :func:`storey_levels`), the linear part as it is."""
    kind, levels = registry.get(kind_name), storey_levels(linear, trials)
    records = tuple(Mechanism(kind_name, int(s), tuple((n, float(v[1])) for n, v in
                                                         kind.twin_parameters(*levels[s]).items())) for s in storeys)
    return replace(linear, friction=records)


def friction_start(linear: FittedRig, storeys: Sequence[int], loss: float, slip_drift: float,
                   exponent: float) -> FittedRig:
    """A start for the augmented fit: ``linear`` with joint friction in ``storeys`` that has lost ``loss``
    of the storey's stiffness at :data:`REFERENCE_DRIFT`, fully slipping at ``slip_drift`` (m), exponent
    ``exponent``; K stiffened by that loss (K is the stuck joints' stiffness) and the viscous damping
    lowered by :data:`START_DAMPING_SHARE` (the friction dissipates the rest)."""
    K = np.asarray(linear.stiffness)
    share = jf.lost_fraction(REFERENCE_DRIFT, slip_drift, exponent)
    unit = friction_records(storeys, [{"stiffness": 1.0, "slip_drift": slip_drift, "exponent": exponent}]
                                  * len(storeys))
    params = [{"stiffness": loss * joint_tendon_stiffness(K, m) / share, "slip_drift": slip_drift, "exponent": exponent}
              for m in unit]
    if any(p["stiffness"] <= 0 for p in params):
        raise MomentidError(f"storeys {list(storeys)} of stiffness {K.tolist()}: a storey with no positive stiffness "
                            f"cannot carry joint friction")
    return replace(linear, stiffness=K * (1.0 + loss),
                   damping_ratio=np.asarray(linear.damping_ratio) * START_DAMPING_SHARE,
                   friction=friction_records(storeys, params))
