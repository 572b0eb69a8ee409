"""What the calibrated twin is made of: the identified structure, its sensors, its extra modes.

:class:`TwinParameters` holds everything the MJCF twin (:mod:`momentid.twin.spec`) is built from:
floor masses, the full symmetric stiffness and damping matrices, each run's floor-sensor calibration
(:class:`SensorModel`: gain, clock offset, bias), and resonances beyond the storeys
(:class:`ExtraMode`).  :func:`from_identification` fills it from either identification momentid
makes: the modal fit of runs without added mass (``ModalIdentification``: K and C from stated
masses, or mass-normalised without them) or the added-mass identification (``Identification``:
M, C, K and the mass-proportional damping ``mu`` that an added mass brings).

:func:`~momentid.lab.tendons.tendon_layout` (re-exported here) writes K and C exactly as fixed tendons.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from momentid.core.series import Experiment
from momentid.errors import IdentificationError
from momentid.lab.rig_model import RigModel
from momentid.lab.tendons import Tendon, pair_coefficient, tendon_layout

if TYPE_CHECKING:
    from momentid.estimation.identified import Identification
    from momentid.estimation.scaled import ModalIdentification

__all__ = ["SensorModel", "ExtraMode", "TwinParameters", "Tendon", "tendon_layout", "pair_coefficient",
           "from_identification", "matrices_from_modes", "masses_from_shapes", "DEFAULT_STOREY_HEIGHT"]

#: Storey height (m) drawn when neither the recording's model nor the lab states one (drawing only).
DEFAULT_STOREY_HEIGHT = 0.3


@dataclass(frozen=True)
class SensorModel:
    """The floor sensors of one run, as the twin reads its floors.

    Floor sensor ``j`` reads ``gain_j * a_j(t - clock_offset_j) + bias_j`` where ``a_j`` is the floor's
    absolute acceleration and time is the table sensor's clock (the table sensor is the reference:
    gain 1, no offset).

    Attributes
    ----------
    gain : ndarray, shape (d,)
        Gain (1) relative to the table sensor.
    clock_offset : ndarray, shape (d,)
        Clock offset (s) relative to the table sensor; positive: the sensor reads late.
    bias : ndarray, shape (d,)
        Constant offset (m/s^2).
    """

    gain: np.ndarray
    clock_offset: np.ndarray
    bias: np.ndarray

    @classmethod
    def ideal(cls, d: int) -> SensorModel:
        """Gain 1, no clock offset, no bias on ``d`` floors."""
        return cls(np.ones(d), np.zeros(d), np.zeros(d))

    def with_bias(self, bias: ArrayLike) -> SensorModel:
        """The same sensors with ``bias`` (m/s^2, shape (d,))."""
        return SensorModel(self.gain, self.clock_offset, np.asarray(bias, float))

    def to_dict(self) -> dict:
        """Gains (1), clock offsets (s) and biases (m/s^2) as lists."""
        return {"gain": self.gain.tolist(), "clock_offset_s": self.clock_offset.tolist(),
                "bias_m_s2": self.bias.tolist()}


@dataclass(frozen=True)
class ExtraMode:
    """A resonance beyond the storey modes, seen by the floor sensors but not carried by K and C
    (torsion, out-of-plane sway, a loose part).

    Floor sensor ``j`` reads ``residues[j] * eta''`` on top of its floor, with
    ``eta'' + 2 zeta w eta' + w^2 eta = -z''`` (``w = 2 pi frequency``, ``z''`` the table acceleration):
    the modal model's term ``-R_j s^2 / (s^2 + 2 zeta w s + w^2)`` of the table-to-floor transfer.

    Attributes
    ----------
    frequency : float
        Undamped natural frequency (Hz).
    damping_ratio : float
        Damping ratio (1).
    residues : ndarray, shape (d,)
        Per floor sensor (1).
    """

    frequency: float
    damping_ratio: float
    residues: np.ndarray

    def to_dict(self) -> dict:
        """The mode's frequency (Hz), damping ratio and residues as JSON-ready values."""
        return {"frequency_hz": self.frequency, "damping_ratio": self.damping_ratio,
                "residues": self.residues.tolist()}


@dataclass(frozen=True)
class TwinParameters:
    """Everything the MJCF twin is built from (SI units; floor 1 is the lowest).

    Attributes
    ----------
    masses : ndarray, shape (d,)
        Floor masses (kg); for a mass-normalised twin, in proportion with mean 1 (:func:`masses_from_shapes`).
    K, C : ndarray, shape (d, d)
        Symmetric stiffness (N/m) and damping (N s/m) of the floors relative to the table.
    storey_heights : ndarray, shape (d,)
        Storey heights (m), for drawing.
    sensors : dict of str to SensorModel
        Each calibrated run's floor sensors.
    nominal : SensorModel
        The sensors the twin's MJCF carries (the mean over the calibrated runs): for a new simulation
        and for runs the calibration did not use.
    extra_modes : tuple of ExtraMode
    mass_normalised : bool
        No masses were stated: masses, K and C are the rig's divided by its (unknown) mean floor mass.
    added_mass_damping : float
        ``mu`` (1/s): joint damping per kilogram of added mass (added-mass identification; 0 otherwise).
    source : str
        ``"modal"`` (runs without added mass) or ``"added-mass"``.
    runs : tuple of str
        The runs the identification used.
    notes : tuple of str
    """

    masses: np.ndarray
    K: np.ndarray
    C: np.ndarray
    storey_heights: np.ndarray
    sensors: dict
    nominal: SensorModel
    extra_modes: tuple = ()
    mass_normalised: bool = False
    added_mass_damping: float = 0.0
    source: str = "modal"
    runs: tuple = ()
    notes: tuple = field(default=())

    @property
    def storeys(self) -> int:
        """Number of storeys ``d``."""
        return self.masses.shape[0]

    def rig(self, added_mass: ArrayLike | None = None) -> RigModel:
        """The rig MuJoCo builds (sensors and extra modes apart) with ``added_mass`` (kg, (d,); none by
        default): K and C as tendons, each floor joint damped by ``mu dm`` (:attr:`added_mass_damping`)."""
        dm = np.zeros(self.storeys) if added_mass is None else np.asarray(added_mass, float)
        return RigModel.from_matrices(self.masses, self.K, self.C, self.storey_heights,
                                      joint_damping=self.added_mass_damping * dm, added_mass=dm)

    def sensors_of(self, run: str) -> SensorModel:
        """The calibrated sensors of ``run``, else the nominal ones."""
        return self.sensors.get(run, self.nominal)


def matrices_from_modes(frequency: ArrayLike, damping_ratio: ArrayLike, shapes: ArrayLike, masses: ArrayLike
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric K and C with exactly these modes' frequencies and damping ratios and the mass matrix
    ``diag(masses)``: the M-orthonormal set nearest to the shapes (polar decomposition of
    ``M^1/2 Phi``), as :mod:`momentid.estimation.scaled` derives K and C from stated masses.

    Parameters
    ----------
    frequency : ndarray, shape (d,)
        Hz.
    damping_ratio : ndarray, shape (d,)
    shapes : ndarray, shape (d, d)
        One mode per column.
    masses : ndarray, shape (d,)
        kg.

    Returns
    -------
    K, C : ndarray, shape (d, d)
    """
    w = 2 * np.pi * np.asarray(frequency, float)
    m_half = np.sqrt(np.asarray(masses, float))
    phi = np.asarray(shapes, float)
    phi = phi / np.sqrt(np.sum(masses * phi.T ** 2, axis=1))[None, :]
    U, _, Vt = np.linalg.svd(m_half[:, None] * phi)
    S = m_half[:, None] * (U @ Vt)
    return S @ np.diag(w ** 2) @ S.T, S @ np.diag(2 * np.asarray(damping_ratio, float) * w) @ S.T


def masses_from_shapes(shapes: ArrayLike) -> np.ndarray | None:
    """Floor masses, mean 1 kg, in the proportions that make the mode shapes most nearly orthogonal.

    Orthogonality ``phi_i^T M phi_k = 0`` (``i < k``) is linear in the diagonal of ``M``: its least-squares
    null vector (the right singular vector of the smallest singular value; exact for two storeys).

    Parameters
    ----------
    shapes : ndarray, shape (d, d)
        One mode per column.

    Returns
    -------
    ndarray, shape (d,), or None
        None when the null vector is not all of one sign (no positive masses make them orthogonal).
    """
    phi = np.asarray(shapes, float)
    d = phi.shape[0]
    if d == 1:
        return np.ones(1)
    phi = phi / np.linalg.norm(phi, axis=0)[None, :]
    rows = [phi[:, i] * phi[:, k] for i in range(d) for k in range(i + 1, d)]
    m = np.linalg.svd(np.array(rows))[2][-1]
    m = m * np.sign(m.sum())
    return m / m.mean() if np.all(m > 0) else None


def _heights(experiment: Experiment, d: int) -> np.ndarray:
    s, stated = experiment.structure, experiment.statement
    for heights in (s.storey_heights if s is not None else None,
                    stated.storey_heights if stated is not None else None):
        if heights is not None and len(heights) == d:
            return np.asarray(heights, float)
    return np.full(d, DEFAULT_STOREY_HEIGHT)


def _extra_modes(result) -> tuple:
    """The modal identification's resonances beyond the storeys
    (:attr:`~momentid.estimation.scaled.ModalIdentification.extra_modes`), each as the twin's oscillator
    with its in-phase residues."""
    return tuple(ExtraMode(float(mode.frequency), float(mode.damping_ratio), np.asarray(mode.residues, float).copy())
                 for mode in result.extra_modes)


def _complex_extra_modes(result) -> list[str]:
    """Notes on extra modes fitted as complex (quadrature residues): the twin's oscillator reads its
    in-phase residues only."""
    out = []
    for mode in result.extra_modes:
        quadrature = mode.residues_quadrature
        if quadrature is not None and np.any(quadrature):
            in_phase, off = (", ".join(f"{x:.3g}" for x in values) for values in (mode.residues, quadrature))
            out.append(f"extra mode at {mode.frequency:.4g} Hz was fitted as a complex mode (quadrature residues "
                       f"{off}; in phase {in_phase}): the twin's oscillator carries the in-phase residues only")
    return out


def _mean_sensors(sensors: dict, d: int) -> SensorModel:
    if not sensors:
        return SensorModel.ideal(d)
    models = list(sensors.values())
    return SensorModel(np.mean([s.gain for s in models], axis=0), np.mean([s.clock_offset for s in models], axis=0),
                       np.zeros(d))


def from_identification(result: Identification | ModalIdentification, experiment: Experiment) -> TwinParameters:
    """The twin's parameters from an identification of ``experiment``.

    Parameters
    ----------
    result : ModalIdentification or Identification
        From :func:`momentid.estimation.identification.identify` (diagonal mass matrix).
    experiment : Experiment
        The recording it was identified from (storey heights for drawing).

    Returns
    -------
    TwinParameters

    Raises
    ------
    IdentificationError
        A full (non-diagonal) identified mass matrix, which the twin's floors cannot carry.
    """
    from momentid.estimation.scaled import ModalIdentification

    d = experiment.storeys
    heights = _heights(experiment, d)
    if isinstance(result, ModalIdentification):
        sensors = {run: SensorModel(np.asarray(result.sensor_gain[r], float),
                                    np.asarray(result.sensor_offset[r], float), np.zeros(d))
                   for r, run in enumerate(result.runs)}
        notes = []
        if result.K is not None:
            masses, K, C, normalised = np.asarray(result.masses, float), result.K, result.C, False
        else:
            masses = masses_from_shapes(result.shapes)
            how = "in the proportions that make the identified mode shapes orthogonal"
            if masses is None:
                masses, how = np.ones(d), "equal (no positive proportions make the identified shapes orthogonal)"
            K, C = matrices_from_modes(result.frequency, result.linear_damping_ratio, result.shapes, masses)
            normalised = True
            notes.append(f"no floor masses stated: a mass-normalised twin, floor masses {how}, "
                         f"{', '.join(f'{m:.4g}' for m in masses)} (mean 1): its modes, damping ratios and sensor "
                         f"readings are the rig's; its masses, K and C are the rig's divided by its mean floor mass "
                         f"(kg), unknown")
        notes += _complex_extra_modes(result)
        return TwinParameters(masses=masses, K=np.asarray(K, float), C=np.asarray(C, float), storey_heights=heights,
                              sensors=sensors, nominal=_mean_sensors(sensors, d),
                              extra_modes=_extra_modes(result), mass_normalised=normalised, source="modal",
                              runs=tuple(result.runs), notes=tuple(notes))
    M = np.asarray(result.M, float)
    if np.any(M - np.diag(np.diag(M))):
        raise IdentificationError(f"{experiment.source}: the identified mass matrix is full: the twin's floors "
                                  f"carry a diagonal one (identify with mass='diagonal')")
    ideal = {run: SensorModel.ideal(d) for run in result.runs}
    return TwinParameters(masses=np.diag(M).copy(), K=np.asarray(result.K, float), C=np.asarray(result.C, float),
                          storey_heights=heights, sensors=ideal, nominal=SensorModel.ideal(d),
                          added_mass_damping=float(result.mu), source="added-mass", runs=tuple(result.runs),
                          notes=("the added-mass identification does not calibrate sensors: the twin's sensors "
                                 "are ideal (gain 1, no clock offset)",))
