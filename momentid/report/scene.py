"""What the viewer shows of an experiment, computed once and without rerun: the :class:`Scene`
(identification, comparison, equation residuals, notes), displacements reconstructed from
accelerations for rigs that record no displacement, the drawing exaggeration, and the check that a
saved result belongs to the recording (:func:`prepare`, :func:`load_result`)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike
import scipy.signal

from momentid.core.series import Experiment, RunData
from momentid.errors import IdentificationError, SensorDataError, ViewerError

if TYPE_CHECKING:
    from momentid.estimation.identified import Identification
    from momentid.estimation.scaled import ModalIdentification

__all__ = ["Scene", "displacements_from_accelerations", "DISPLACEMENT_HIGHPASS", "DISPLACEMENT_ORDER",
           "MAX_EXAGGERATION", "auto_exaggeration", "nice_number", "is_modal", "load_result", "check_result",
           "prepare"]

#: High-pass corner (Hz) of displacements reconstructed from accelerations.  Double
#: integration multiplies a sensor's slowly wandering bias by 1/(2 pi f)^2: below this
#: corner that drift swamps the motion.  0.3 Hz keeps a 1 Hz table sine (the slowest shipped
#: trial) and every mode of a bench-top rig, and is the lower edge of the import's alignment band.
DISPLACEMENT_HIGHPASS = 0.3
#: Order of the zero-phase high-pass (the magnitude of a Butterworth of this order, squared).
DISPLACEMENT_ORDER = 4


@dataclass
class Scene:
    """Everything shown for one experiment, computed once.

    Attributes
    ----------
    experiment : Experiment
    exaggeration : float
        Drawn displacement / true displacement in the 3D views.
    active_run : int
        Index of the run whose tab opens first.
    result : Identification or None
    comparison : Comparison or None
        Only with a result and a nominal structure in the recording.
    residuals : dict of str to ndarray, shape (n, d)
        Equation residual (N) per run, when the run has ``a``, ``q``, ``v``.
    notes : list of str
        What could not be shown, and why.
    overlay : object, optional
        A layer shown beside each run and in the side column (the twin:
        :class:`momentid.report.twin_overlay.TwinOverlay`): ``spatial_views(scene, run)``, ``series_views(scene, run)``,
        ``side_views()`` give its blueprint views, ``log(rec, scene, run)`` and ``log_static(rec)`` its data.
    """

    experiment: Experiment
    exaggeration: float
    active_run: int = 0
    result: object = None
    comparison: object = None
    residuals: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    reconstructed: dict = field(default_factory=dict)
    overlay: object = None

    @property
    def heights(self) -> np.ndarray:
        """Storey heights (m): the structure's, else the lab statement's, else 0.3 m each."""
        d = self.experiment.storeys
        s, stated = self.experiment.structure, self.experiment.statement
        for heights in (s.storey_heights if s is not None else None,
                        stated.storey_heights if stated is not None else None):
            if heights is not None and len(heights) == d:
                return np.asarray(heights, float)
        return np.full(d, 0.3)

    def drawn(self, run: RunData) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Table displacement z (n,) and floor displacements q (n, d) relative to it (m) as drawn:
        recorded, else reconstructed from the accelerations, else None."""
        d = self.experiment.storeys
        z_rec, q_rec = self.reconstructed.get(run.name, (None, None))
        z = run["z"] if run.has("z") else z_rec
        q = _floor_group(run, "q", d)
        return z, (q if q is not None else q_rec)


def displacements_from_accelerations(acc: np.ndarray, dt: float,
                                     highpass: float = DISPLACEMENT_HIGHPASS) -> np.ndarray:
    """Displacements from accelerations by band-limited double integration, without drift.

    In the frequency domain ``X(f) = -A(f) / (2 pi f)^2 H(f)`` with ``H`` the
    zero-phase high-pass ``1 / (1 + (highpass / f)^(2 n))`` (the squared
    magnitude of an order-``n`` Butterworth, :data:`DISPLACEMENT_ORDER`), so a
    constant or slowly drifting bias gives no ramp.  The record is zero-padded
    to twice its length against wrap-around after removing the least-squares
    line (a sensor's bias and its linear drift); ``nan`` samples count as 0 m/s^2.

    Parameters
    ----------
    acc : ndarray, shape (n,) or (n, k)
        Accelerations (m/s^2), time-first.
    dt : float
        Sample interval (s).
    highpass : float
        Corner (Hz) below which motion is dropped.

    Returns
    -------
    ndarray, same shape as ``acc``
        Displacements (m).
    """
    a = scipy.signal.detrend(np.nan_to_num(np.asarray(acc, float)), axis=0)  # bias and its linear drift
    n = a.shape[0]
    f = np.fft.rfftfreq(2 * n, dt)
    gain = np.zeros_like(f)
    f_pos = f[1:]
    gain[1:] = -1.0 / ((2 * np.pi * f_pos) ** 2 * (1.0 + (highpass / f_pos) ** (2 * DISPLACEMENT_ORDER)))
    spectrum = np.fft.rfft(a, n=2 * n, axis=0)
    shape = (-1,) + (1,) * (a.ndim - 1)
    return np.fft.irfft(spectrum * gain.reshape(shape), n=2 * n, axis=0)[:n]


def _reconstruct(run: RunData, d: int) -> tuple[np.ndarray, np.ndarray] | None:
    """``(z, q)`` of a run that records ``zdd`` and ``a1..ad`` but no ``q``: from the accelerations."""
    a = _floor_group(run, "a", d)
    if a is None or not run.has("zdd") or _floor_group(run, "q", d) is not None or run.n_samples < 4:
        return None
    dt = float(run.time[1] - run.time[0])
    x = displacements_from_accelerations(np.column_stack([run["zdd"], a]), dt)
    return x[:, 0], x[:, 1:] - x[:, :1]


def _floor_group(run: RunData, prefix: str, d: int) -> np.ndarray | None:
    names = [f"{prefix}{i + 1}" for i in range(d)]
    return run.group(prefix, d) if all(run.has(n) for n in names) else None


def nice_number(x: float) -> float:
    """Largest 1-2-5 number not above ``x``."""
    decade = 10.0 ** math.floor(math.log10(x))
    return next(m * decade for m in (5, 2, 1) if m * decade <= x)


#: Largest exaggeration / the default one (which draws the largest displacement at about a fifth of
#: the building height): 1e4 draws it 2000 building heights away, where nothing is left to see (and
#: beyond, the viewer's float32 positions overflow).
MAX_EXAGGERATION = 1e4


def auto_exaggeration(experiment: Experiment, heights: ArrayLike | None = None, reconstructed: dict | None = None
                      ) -> float:
    """A 1-2-5 factor that draws the largest recorded displacement at about a
    fifth of the building height (never below 1).

    Parameters
    ----------
    experiment : Experiment
    heights : array_like, optional
        Storey heights (m); default 0.3 m each.
    reconstructed : dict, optional
        ``{run name: (z, q)}`` displacements drawn for runs that record none.

    Returns
    -------
    float
    """
    d = experiment.storeys
    height = float(np.sum(heights)) if heights is not None else 0.3 * d
    peak = 0.0
    for run in experiment.runs:
        z_rec, q_rec = (reconstructed or {}).get(run.name, (None, None))
        q = _floor_group(run, "q", d)
        q = q if q is not None else q_rec
        z = run["z"] if run.has("z") else z_rec if z_rec is not None else np.zeros(run.n_samples)
        absolute = z[:, None] + (q if q is not None else 0.0)
        peak = max(peak, float(np.max(np.abs(z), initial=0.0)), float(np.max(np.abs(absolute), initial=0.0)))
    if not math.isfinite(peak) or peak <= 0.0:
        return 1.0
    return max(1.0, nice_number(0.2 * height / peak))


def load_result(path: str | os.PathLike, experiment: Experiment) -> Identification | ModalIdentification:
    """Read an identification saved by ``momentid identify --json``: of runs with added mass (M, C, K,
    mu, kappa) or without (the modes: :func:`momentid.report.modal_result.modal_from_dict`).

    Parameters
    ----------
    path : str or Path
        The JSON file.
    experiment : Experiment
        The recording it must belong to (checked by :func:`check_result`).

    Returns
    -------
    Identification or ModalIdentification

    Raises
    ------
    ViewerError
        The file is missing or not such a JSON object, or belongs to another recording.
    """
    from momentid.estimation.identified import Identification
    from momentid.report.modal_result import MODAL_KEYS, is_modal_payload, modal_from_dict

    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise ViewerError(f"{path}: result file not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ViewerError(f"{path}: not a JSON result of `momentid identify --json` ({exc})") from None
    if is_modal_payload(data):        # runs without added mass: the modes, and K, C with stated masses
        result = modal_from_dict(data, str(path))
        check_result(result, experiment, source=str(path))
        return result
    if isinstance(data, dict) and isinstance(data.get("runs"), list) and data["runs"] and \
            all(isinstance(r, dict) for r in data["runs"]):
        raise ViewerError(f"{path}: a result of `momentid identify --per-run --json` (one fit per run); "
                          f"expected one fit: `momentid identify --json --runs RUN` without --per-run")
    missing = [k for k in ("M", "C", "K", "mu", "kappa", "runs") if not isinstance(data, dict) or k not in data]
    if missing:
        raise ViewerError(f"{path}: not a result of `momentid identify --json`: missing "
                          f"{', '.join(missing)} (expected keys M, C, K, mu, kappa, runs with added mass, or "
                          f"{', '.join(MODAL_KEYS)} without)")

    def number(key, default=math.nan):
        value = data.get(key)
        return default if value is None else value

    try:
        M, C, K = (np.asarray(data[k], float) for k in ("M", "C", "K"))
        d = M.shape[0] if M.ndim == 2 else -1
        if any(m.shape != (d, d) for m in (M, C, K)):
            raise ValueError(f"M, C, K have shapes {M.shape}, {C.shape}, {K.shape}, expected square and equal")
        result = Identification(
            M=M, C=C, K=K, mu=float(data["mu"]), kappa=float(data["kappa"]),
            damping_misfit=float(number("damping_misfit")), estimator=str(data.get("estimator", "?")),
            n_equations=int(number("n_equations", 0)), n_unknowns=int(number("n_unknowns", 0)),
            rank=int(number("rank", 0)), condition=float(number("condition")),
            residual_rms=float(number("residual_rms")), runs=tuple(str(r) for r in data["runs"]),
        )
    except (TypeError, ValueError) as exc:
        raise ViewerError(f"{path}: not a result of `momentid identify --json`: {exc}") from None
    check_result(result, experiment, source=str(path))
    return result


def check_result(result: Identification | ModalIdentification, experiment: Experiment, source: str = "result") -> None:
    """Refuse a result that does not belong to ``experiment`` (storeys, run names).

    Raises
    ------
    ViewerError
    """
    names = [r.name for r in experiment.runs]
    if result.storeys != experiment.storeys:
        raise ViewerError(f"{source}: the result is for {result.storeys} storeys but {experiment.source} "
                          f"records {experiment.storeys}: it belongs to another recording")
    unknown = [r for r in result.runs if r not in names]
    if unknown:
        raise ViewerError(f"{source}: runs {', '.join(unknown)} are not in {experiment.source} (its runs: "
                          f"{', '.join(names)}): the result belongs to another recording")


def prepare(experiment: Experiment, *, result: Identification | ModalIdentification | None = None,
            exaggeration: float | None = None, run: str | None = None, identify_options: dict | None = None,
            identify: bool = True) -> Scene:
    """Identify (unless ``result`` is given), compare and collect what to show.

    Parameters
    ----------
    experiment : Experiment
    result : Identification, optional
        Shown instead of identifying again; must belong to ``experiment``.
    exaggeration : float, optional
        Drawn / true displacement; default :func:`auto_exaggeration`.
    run : str, optional
        The run whose tab opens first (default: the first run).
    identify_options : dict, optional
        Keyword arguments of :func:`momentid.estimation.identification` (estimator, runs, times).
    identify : bool
        Identify when no ``result`` is given (False: show none, e.g. beside a twin that carries its own).

    Returns
    -------
    Scene

    Raises
    ------
    ViewerError
        Bad exaggeration, unknown run name, or a result of another recording.
    """
    from momentid.estimation.comparison import compare
    from momentid.estimation.equation_form import equation_residual
    from momentid.estimation.identification import identify as identify_experiment

    names = [r.name for r in experiment.runs]
    if run is not None and run not in names:
        raise ViewerError(f"{experiment.source}: no run named {run!r}; runs are {', '.join(names)}")
    if exaggeration is not None and not (math.isfinite(exaggeration) and exaggeration > 0):
        raise ViewerError(f"exaggeration must be a positive number, got {exaggeration!r}")
    scene = Scene(experiment, exaggeration=1.0, active_run=names.index(run) if run else 0)
    for r in experiment.runs:
        got = _reconstruct(r, experiment.storeys)
        if got is not None:
            scene.reconstructed[r.name] = got
    default = auto_exaggeration(experiment, scene.heights, scene.reconstructed)
    if exaggeration is not None and exaggeration > MAX_EXAGGERATION * default:
        raise ViewerError(f"exaggeration = {exaggeration!r}: would draw the largest displacement at about "
                          f"{exaggeration / default / 5:.3g} building heights; expected at most "
                          f"{MAX_EXAGGERATION * default:g} (the default here is {default:g})")
    scene.exaggeration = exaggeration if exaggeration is not None else default
    if result is not None:
        check_result(result, experiment)
    elif not identify:
        scene.notes.append("not identified: the twin's parameters are shown instead")
    else:
        try:
            result = identify_experiment(experiment, **(identify_options or {}))
        except (IdentificationError, SensorDataError) as exc:
            scene.notes.append(f"not identified: {exc}")
    scene.result = result
    if result is not None:
        if experiment.structure is not None and not is_modal(result):
            scene.comparison = compare(result, experiment.structure)
        else:
            scene.notes.append("the recording holds no nominal structure: no analytic comparison")
        for r in experiment.runs:
            if is_modal(result):
                break  # a modal fit of acceleration records has no eq. (3) residual to draw
            try:
                scene.residuals[r.name] = equation_residual(result, r)
            except SensorDataError as exc:
                scene.notes.append(f"no residual for run {r.name!r}: {exc}")
    d = experiment.storeys
    for r in experiment.runs:
        if r.name in scene.reconstructed:
            scene.notes.append(f"run {r.name!r} records accelerations only: the 3D view draws displacements "
                               f"reconstructed from them (double integration above {DISPLACEMENT_HIGHPASS:g} Hz, "
                               f"drift-free; slower motion is not drawn)")
            continue
        if _floor_group(r, "q", d) is None:
            scene.notes.append(f"run {r.name!r} has no q1..q{d}: its floors are drawn at rest on the table")
        if not r.has("z"):
            scene.notes.append(f"run {r.name!r} has no z: its table is drawn at rest")
    for r in experiment.runs:
        scene.notes += [f"run {r.name!r}: {n}" for n in r.meta.get("notes", ())]
    return scene


def is_modal(result: object) -> bool:
    """True for the modal fit of runs without added mass (it has no M, mu, kappa of eq. (3))."""
    from momentid.estimation.scaled import ModalIdentification

    return isinstance(result, ModalIdentification)
