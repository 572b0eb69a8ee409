"""Held-out proof of the joint-friction twin on a real rig's trials: one fold per held-out trial.

For a held-out trial, with the other trials of the same rig state for training:

* ``nrmse_linear_refit``: the linear twin (:class:`~momentid.twin.fit.FittedRig` without friction)
  fitted to the training trials by re-simulation (:func:`~momentid.twin.fit.fit_twin`),
  replayed on the held-out trial;
* ``nrmse_after``: the augmented twin (the same plus ``joint_friction`` in every storey) fitted the
  same way, from the linear twin, replayed on the held-out trial;
* ``nrmse_linear_own``: a linear twin fitted to the held-out trial itself (the best any model without
  amplitude dependence does on it);
* ``noise_nrmse``: what the held-out trial's sensor noise alone leaves
  (:func:`~momentid.diagnosis.modal.check.noise_nrmse`, on the own twin's modes).

The held-out trial's outputs enter none of the first two.  :func:`amplitude_trend` identifies the
augmented twin's own simulated trials exactly as the recordings are identified
(:func:`~momentid.estimation.scaled.identify_modal`, per trial), so that its predicted change of mode
1 with the response amplitude can be held to the recordings' (the identification's smearing of a
drifting frequency into damping is then the same on both sides).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from momentid.core.series import Experiment
from momentid.diagnosis.modal import check as mc
from momentid.twin import fit as twin_fit
from momentid.errors import IdentificationError
from momentid.estimation.noise import estimate_noise
from momentid.estimation.scaled import amplitude_trend as trend_of, identify_modal

__all__ = ["Fold", "hold_out", "linear_start", "amplitude_trend", "FRICTION_STARTS"]

#: Starts of the augmented fit (stiffness lost at the reference drift as a share of the storey's,
#: slip drift in m, exponent); the fit keeps the one that explains the training trials best.
FRICTION_STARTS = ((0.02, 0.03, -0.5),)
#: Optimiser evaluations of the augmented fit (each costs a Jacobian of all its physical parameters: the
#: augmented fit is ~80 % of `diagnose`'s CPU).  On the shipped rig's four folds (benchmarks/real_folds.py)
#: 10 hold every criterion (after/refit 0.24-0.61); 12 cost ~20 % more CPU (on the sine_2p0 fold they
#: reached 18.6 % against 20.4 % held-out NRMSE, in a probe without the command's one-thread BLAS).
AUGMENTED_NFEV = 10
#: Seed of the sensor noise added to a simulated trial before it is identified.
NOISE_SEED = 7


@dataclass(frozen=True)
class Fold:
    """One held-out trial's result (see the module docstring)."""

    held_out: str
    training: tuple
    nrmse_linear_refit: float
    nrmse_after: float
    nrmse_linear_own: float
    noise_nrmse: float
    linear: twin_fit.FitResult
    augmented: twin_fit.FitResult
    own: twin_fit.FitResult
    seconds: float = 0.0
    cpu_seconds: float = 0.0

    def to_dict(self) -> dict:
        return {"held_out": self.held_out, "training": list(self.training),
                "nrmse_linear_refit": self.nrmse_linear_refit, "nrmse_after": self.nrmse_after,
                "nrmse_linear_own": self.nrmse_linear_own, "noise_nrmse": self.noise_nrmse,
                "ratio_to_linear_refit": self.nrmse_after / self.nrmse_linear_refit,
                "ratio_to_linear_own": self.nrmse_after / self.nrmse_linear_own,
                "training_nrmse": {"linear": self.linear.nrmse, "augmented": self.augmented.nrmse},
                "linear": self.linear.model.to_dict(), "augmented": self.augmented.model.to_dict(),
                "own": self.own.model.to_dict(), "seconds": self.seconds,
                "cpu_seconds": self.cpu_seconds}


def linear_start(experiment: Experiment, names) -> twin_fit.FittedRig:
    """The linear twin of the modal identification of run(s) ``names`` (a name or a list) with the lab's
    stated masses.

    Raises
    ------
    IdentificationError
        No stated masses (the twin's forces need them).
    """
    ident = identify_modal(experiment, [names] if isinstance(names, str) else list(names))
    if ident.K is None:
        raise IdentificationError(f"{experiment.source}: no floor masses stated: the twin needs them "
                                  f"(experiment.toml [structure] masses)")
    return twin_fit.FittedRig(np.asarray(ident.masses, float), ident.K, np.clip(ident.linear_damping_ratio, 1e-4, None))


def hold_out(experiment: Experiment, held: str, training, *, substeps: int | None = None,
             max_nfev: int = twin_fit.MAX_NFEV, augmented_nfev: int = AUGMENTED_NFEV,
             starts=FRICTION_STARTS, start: twin_fit.FittedRig | None = None) -> Fold:
    """Fit the linear and the augmented twin on ``training`` and check them on ``held`` (module docstring).

    Parameters
    ----------
    experiment : Experiment
        Runs without added mass, ``zdd`` and ``a1..ad`` (m/s^2), stated floor masses.
    held : str
        The held-out run.
    training : sequence of str
        The training runs (``held`` not among them).
    start : RigModel, optional
        The linear fit's start (default: the modal identification of the quietest training run).
    """
    import time

    began, cpu = time.perf_counter(), time.process_time()
    d = experiment.storeys
    trials = {n: twin_fit.trial(experiment.run(n), d) for n in list(training) + [held]}
    train = [trials[n] for n in training]
    quietest = min(training, key=lambda n: float(np.sqrt(np.mean(trials[n].a[trials[n].start:] ** 2))))
    start = linear_start(experiment, quietest) if start is None else start
    linear = twin_fit.fit_twin(train, start, substeps=substeps, max_nfev=max_nfev)

    def augmented_fit(guess):
        return twin_fit.fit_twin(train, guess, substeps=substeps, max_nfev=augmented_nfev)

    def own_fit(model):
        return twin_fit.fit_twin([trials[held]], model, substeps=substeps, max_nfev=max_nfev)

    # the held-out trial's own fit runs beside the augmented fits (threads: MuJoCo releases the GIL), filling
    # the cores while the augmented fit's single rollouts and Python run; each fit is the same on its own
    guesses = [twin_fit.friction_start(linear.model, tuple(range(1, d + 1)), loss, slip, chi)
               for loss, slip, chi in starts]
    jobs = [lambda: own_fit(linear.model)] + [lambda guess=guess: augmented_fit(guess) for guess in guesses]
    fits = twin_fit.each(lambda job: job(), jobs)
    own, augmented = fits[0], min(fits[1:], key=lambda fit: fit.cost)
    tr = trials[held]
    omega, zeta, residues = twin_fit.twin_modes(own.model)
    noise = mc.noise_nrmse(omega, zeta, residues, own.model.gain, experiment.run(held), experiment)
    return Fold(held_out=held, training=tuple(training),
                nrmse_linear_refit=twin_fit.nrmse(linear.model, tr, substeps),
                nrmse_after=twin_fit.nrmse(augmented.model, tr, substeps),
                nrmse_linear_own=own.nrmse[held], noise_nrmse=noise, linear=linear, augmented=augmented, own=own,
                seconds=time.perf_counter() - began, cpu_seconds=time.process_time() - cpu)


def _simulated_experiment(experiment: Experiment, model: twin_fit.FittedRig, names, substeps: int | None) -> Experiment:
    """``experiment``'s runs ``names`` with their floor channels replaced by ``model``'s simulation, read by its
    sensors, plus white noise at each channel's measured level (the identification needs a noise floor)."""
    rng = np.random.default_rng(NOISE_SEED)
    d = experiment.storeys
    runs = []
    for n in names:
        run = experiment.run(n)
        tr = twin_fit.trial(run, d)
        a = twin_fit.predict(model, tr, substeps)
        sigma = estimate_noise(run).sigma
        values = run.values.copy()
        for j in range(d):
            values[:, run.channels.index(f"a{j + 1}")] = a[:, j] + rng.normal(0.0, sigma[f"a{j + 1}"], a.shape[0])
        runs.append(replace(run, values=values))
    return replace(experiment, runs=tuple(runs))


def amplitude_trend(experiment: Experiment, model: twin_fit.FittedRig, names,
                    substeps: int | None = None):
    """Mode 1 against the response amplitude, as the twin ``model`` predicts it on the runs ``names``.

    Returns
    -------
    AmplitudeTrend
        :func:`~momentid.estimation.scaled.amplitude_trend` of the per-run identification of the twin's
        simulated runs.
    """
    simulated = _simulated_experiment(experiment, model, names, substeps)
    return trend_of([identify_modal(simulated, [n]) for n in names])
