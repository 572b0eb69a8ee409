"""Stages 1 and 2 of the added-mass diagnosis: the linear model, and what it leaves in the floor equations.

*Linear model* (:func:`fit_linear_model`): identified from the training runs (errors-in-variables
for noisy data), beside the nominal model the lab states, and the band the diagnosis works in.

*Equation residual* (:func:`equation_residuals`): the force per floor the linear model leaves
unexplained, on band-limited signals, compared with what sensor noise alone leaves (the same
propagation applied to synthetic noise of the measured levels).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from momentid.core.analytic import modal_properties
from momentid.core.series import Experiment, RunData
from momentid.core.structure import Structure
from momentid.diagnosis.added_mass.kinematic_check import noise_sigma
from momentid.diagnosis.thresholds import BLOCK_S, EXCESS
from momentid.errors import IdentificationError
from momentid.estimation.identification import identify
from momentid.estimation.identified import Identification
from momentid.estimation.linear import discretize, outputs, simulate_linear
from momentid.estimation.reconstruct import Prefilter, prepare_run, suggest_band
from momentid.estimation.reconstruct import band_filter

__all__ = ["LinearModel", "ResidualRow", "EquationResiduals", "fit_linear_model", "equation_residuals",
           "band_signals", "top_mode", "blocks", "replay_outputs", "replay_noise", "nrmse"]

#: Band of the diagnosis (noisy data): at least this multiple of the top natural frequency, so the
#: band reaches well above the modes, where a nonlinear storey force puts its harmonics ...
BAND_OVER_TOP_MODE = 2.5
#: ... and at most this fraction of the sample rate (the anti-alias filters roll off above).
BAND_OVER_SAMPLE_RATE = 0.4
#: Noise-free data: the residual's floor is the round-off of the force balance, this fraction of
#: the inertia forces' RMS.
ROUND_OFF = 1e-7
#: Seed of the synthetic sensor noise run ``k`` is given in the equation residual's noise level
#: (``NOISE_SEED + k``): reproducible diagnoses.
NOISE_SEED = 0
#: Seed of the synthetic table-channel noise of the replay noise level.
REPLAY_NOISE_SEED = 7


@dataclass(frozen=True)
class LinearModel:
    """Stage 1: the linear model identified from the training runs, and the diagnosis's band.

    Attributes
    ----------
    experiment : Experiment
        Everything recorded.
    holdout : RunData or None
        The run held out for the before/after replay (the last, with three or more runs).
    train : Experiment
        The other runs: every fit and screening uses only them.
    result : IdentificationResult
        The identified M, C, K (and Rayleigh mu, kappa) of the training runs.
    nominal : Structure or None
        The model the lab states, if any; ``nominal_result`` is it in the shape of ``result``.
    f_top, f_low : float
        Highest and lowest natural frequency (Hz) of the model (``f_top`` at least the nominal's).
    band : Prefilter
        Low-pass of every signal the diagnosis compares (none for noise-free data).
    ideal : bool
        Noise-free data (identified by the plain equation error).
    """

    experiment: Experiment
    holdout: RunData | None
    train: Experiment
    result: object
    nominal: Structure | None
    nominal_result: object | None
    f_top: float
    f_low: float
    band: Prefilter
    ideal: bool

    @property
    def storeys(self) -> int:
        """Number of storeys ``d``."""
        return self.experiment.storeys

    @property
    def evaluation_run(self) -> RunData:
        """The run the before/after replay is shown on: the held-out one, else the last."""
        return self.holdout if self.holdout is not None else self.experiment.runs[-1]


@dataclass(frozen=True)
class ResidualRow:
    """One training run's equation residual.

    Attributes
    ----------
    run : RunData
    signals : dict of str to ndarray
        Band-limited ``'a'``, ``'v'``, ``'q'`` (n, d) (and ``'zdd'`` (n,)).
    residual : ndarray, shape (n, d)
        Floor forces (N) the model leaves unexplained.
    noise : ndarray, shape (n, d)
        The same residual of synthetic sensor noise alone.
    """

    run: RunData
    signals: dict
    residual: np.ndarray
    noise: np.ndarray


@dataclass(frozen=True)
class EquationResiduals:
    """Stage 2: the equation residual of the identified model (and of the nominal one).

    ``excess``: per floor, residual RMS / noise-only RMS; ``mismatch``: one of them above
    :data:`~momentid.diagnosis.thresholds.EXCESS`.  ``nominal_rows`` / ``nominal_mismatch``: the same
    for the lab's nominal model (None / False without one).
    """

    rows: tuple[ResidualRow, ...]
    noise_floor: np.ndarray
    excess: dict
    mismatch: bool
    nominal_rows: tuple[ResidualRow, ...] | None
    nominal_mismatch: bool

    @property
    def located_rows(self) -> tuple[ResidualRow, ...]:
        """The rows to localise: the nominal model's when it shows the mismatch (nothing absorbed
        by a fit), else the identified model's."""
        return self.nominal_rows if self.nominal_mismatch else self.rows


def band_signals(run: RunData, d: int, band: Prefilter) -> dict[str, np.ndarray]:
    """Band-limited ``a``, ``v``, ``q`` (n, d) of ``run`` (and its table acceleration ``zdd``)."""
    s = prepare_run(run, d, band)
    if "zdd" not in s and run.has("zdd"):
        s["zdd"] = run["zdd"]
    return s


def floor_residual(result: Identification, signals: dict, added_mass: ArrayLike) -> np.ndarray:
    """``(M + dM) a + (C + mu dM) v + K q``, shape (n, d) (N), from ``signals`` ``a``, ``v``, ``q`` (n, d) (SI)
    and the run's added masses (d,) (kg)."""
    D = np.diag(added_mass)
    return (signals["a"] @ (result.M + D).T + signals["v"] @ (result.C + result.mu * D).T
            + signals["q"] @ result.K.T)


def blocks(n: int, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Alternate blocks of ``BLOCK_S`` seconds: (train mask, test mask), shape (n,) each."""
    idx = (np.arange(n) / (fs * BLOCK_S)).astype(int) % 2
    return idx == 0, idx == 1


def nominal_result(structure: Structure, like: Identification) -> Identification:
    """The nominal model in the shape of an identification result."""
    return replace(like, M=structure.mass_matrix(), C=structure.damping_matrix(), K=structure.stiffness_matrix(),
                   mu=structure.rayleigh_mu, kappa=structure.rayleigh_kappa, covariance=None)


def top_mode(identified: float, nominal: float | None, shown: float) -> float:
    """The top natural frequency (Hz) the diagnosis works to: its band, refit and checks scale with it.

    The identified model's top mode, except that a badly disturbed fit (a linear fit of a strongly
    nonlinear rig) must neither shrink the band nor widen it with a mode the data do not hold:

    - the top mode of the nominal model the lab states, when it states one, is a floor;
    - a top mode above both that and ``shown``, the band where the data hold their power
      (:func:`~momentid.estimation.reconstruct.suggest_band`: twice the frequency below which 99.5 % of
      the floors' relative acceleration power lies), is an artefact of the fit and is cut to the larger
      of the two.  (A linear fit of a rig that meets a stop can make a storey all but rigid: a mode at
      tens of hertz, six times the data's band, that would open the band to noise.)

    Parameters
    ----------
    identified : float
        The identified model's top natural frequency (Hz; not finite for an unstable fit).
    nominal : float or None
        The nominal model's top natural frequency (Hz), None without one.
    shown : float
        The data's band (Hz).
    """
    floor = nominal if nominal is not None else 0.0
    if not math.isfinite(identified):
        return nominal if nominal is not None else identified
    return min(max(identified, floor), max(floor, shown))


def fit_linear_model(experiment: Experiment, result: Identification | None = None) -> LinearModel:
    """Stage 1: identify the linear model from the training runs; choose the band.

    ``result``: the training runs' identification when it is already known (a compound diagnosis's
    corrected recordings, identified while their correction was sized).
    """
    runs, d = experiment.runs, experiment.storeys
    if len(runs) < 2:
        raise IdentificationError(f"{experiment.source}: diagnosis needs at least two runs, got {len(runs)}")
    hold = runs[-1] if len(runs) >= 3 else None
    train = replace(experiment, runs=tuple(r for r in runs if r is not hold))
    result = identify(train) if result is None else result
    nominal = experiment.structure
    f_nom = None if nominal is None else float(modal_properties(
        nominal.mass_matrix(), nominal.damping_matrix(), nominal.stiffness_matrix()).frequency.max())
    shown = suggest_band(runs[0], d)
    f_top = top_mode(float(result.modes().frequency.max()), f_nom, shown)
    freqs = result.modes().frequency
    f_low = float(np.min(freqs)) if np.all(np.isfinite(freqs)) else 0.5 * f_top
    ideal = result.estimator == "equation"
    band = Prefilter() if ideal else Prefilter(high=min(max(shown, BAND_OVER_TOP_MODE * f_top),
                                                         BAND_OVER_SAMPLE_RATE * runs[0].sample_rate))
    return LinearModel(experiment=experiment, holdout=hold, train=train, result=result, nominal=nominal,
                       nominal_result=nominal_result(nominal, result) if nominal is not None else None,
                       f_top=f_top, f_low=f_low, band=band, ideal=ideal)


def _rms(parts) -> np.ndarray:
    return np.sqrt(np.mean(np.concatenate(parts) ** 2, axis=0))


def equation_residuals(model: LinearModel) -> EquationResiduals:
    """Stage 2: each training run's floor residual, its noise-only level, and the excess per floor."""
    d, result, band = model.storeys, model.result, model.band
    rows = []
    for k, run in enumerate(model.train.runs):
        s = band_signals(run, d, band)
        sig = noise_sigma(run)
        rng = np.random.default_rng(NOISE_SEED + k)
        noise = np.column_stack([rng.standard_normal(run.n_samples) * sig[c] for c in run.channels])
        sn = band_signals(replace(run, values=noise), d, band)
        rows.append(ResidualRow(run, s, floor_residual(result, s, run.added_mass),
                                floor_residual(result, sn, run.added_mass)))
    rms = _rms([r.residual for r in rows])
    rms_noise = _rms([r.noise for r in rows])
    inertia = _rms([r.signals["a"] @ result.M.T for r in rows])
    noise_floor = np.maximum(rms_noise, ROUND_OFF * inertia)
    excess = {f"floor{j + 1}": float(rms[j] / noise_floor[j]) for j in range(d)}
    nominal_rows, nominal_mismatch = None, False
    if model.nominal_result is not None:
        # The nominal model the lab states: when it is right but for the missing physics, its residual
        # is that physics alone, undisturbed by what a linear fit absorbed.
        nominal_rows = tuple(replace(r, residual=floor_residual(model.nominal_result, r.signals, r.run.added_mass))
                             for r in rows)
        nominal_mismatch = bool(np.max(_rms([r.residual for r in nominal_rows]) / noise_floor) > EXCESS)
    return EquationResiduals(rows=tuple(rows), noise_floor=noise_floor, excess=excess,
                             mismatch=max(excess.values()) > EXCESS, nominal_rows=nominal_rows,
                             nominal_mismatch=nominal_mismatch)


# ----------------------------------------------------------------------------- replays of the linear model

def replay_outputs(result: Identification, run: RunData, zdd: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Channels (``'a'``, ``'q'``, ``'v'``: (n, d)) of ``run`` replayed through the linear model,
    driven by ``zdd`` (n,) (default: the run's recorded table acceleration)."""
    dm = np.diag(run.added_mass)
    linear = discretize(result.M + dm, result.C + result.mu * dm, result.K, 1 / run.sample_rate)
    return outputs(linear, simulate_linear(linear, run["zdd"] if zdd is None else zdd))


def replay_noise(result: Identification, run: RunData, d: int, band: Prefilter) -> dict[str, np.ndarray]:
    """RMS per channel group (``'a'``, ``'q'``: (d,)) that sensor noise alone leaves between a
    band-limited recording and a replay of the right model: the channel's own noise plus the
    table accelerometer's noise carried through the structure into the replay (which the
    structure's resonances amplify: with a narrow-band excitation it is the larger part)."""
    fs = run.sample_rate
    sig = noise_sigma(run)
    gain = math.sqrt(2 * band.high / fs) if band.high else 1.0
    rng = np.random.default_rng(REPLAY_NOISE_SEED)
    carried = replay_outputs(result, run, rng.standard_normal(run.n_samples) * sig.get("zdd", 0.0))
    out = {}
    for g in ("a", "q"):
        own = np.array([sig.get(f"{g}{j + 1}", 0.0) for j in range(d)]) * gain
        prop = np.sqrt(np.mean(band_filter(carried[g], fs, band) ** 2, axis=0))
        out[g] = np.sqrt(own ** 2 + prop ** 2)
    return out


def nrmse(simulated: dict, measured: dict, fs: float, band: Prefilter) -> float:
    """Mean over channels of RMS(measured - simulated) / RMS(measured), band-limited."""
    errs = []
    for g in measured:
        m = band_filter(measured[g], fs, band)
        s = band_filter(simulated[g], fs, band)
        errs.append(np.sqrt(np.mean((m - s) ** 2, axis=0)) / np.sqrt(np.mean(m ** 2, axis=0)))
    return float(np.mean(np.concatenate(errs)))
