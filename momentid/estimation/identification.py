"""Identify M, C, K and the Rayleigh coefficients from added-mass runs.

Unknowns ``theta = [M entries, C entries (symmetric), K entries (symmetric),
mu]``; M is diagonal (the shear model) or, with ``mass="full"``, symmetric
(the paper's general count ``3/2 d^2 + 3/2 d + 1``).  Estimators:

``"equation"`` (method.md eq. 3)
    Every run on its own, with the absolute floor accelerations ``a``::

        M a + C v + K q + mu dM v = -dM a

    The reference run (``dM = 0``) fixes the matrices up to scale, runs with
    added mass fix the scale and ``mu``.  Exact for noise-free data; does not
    need the table to repeat its motion between runs.

``"difference"`` (the paper's eq. 2 / 15)
    Each added-mass run minus the reference run, with relative accelerations
    ``q'' = a - z''``; requires the same table motion in every run::

        M (q_i'' - q_1'') + C (v_i - v_1) + K (q_i - q_1) + mu dM_i v_i = -dM_i a_i

``"eiv"`` (:mod:`momentid.estimation.eiv`)
    Errors-in-variables maximum likelihood in the frequency domain, started
    from the equation form on low-passed signals: unbiased by noise on every
    channel (table accelerometer included), with standard errors at the
    Cramér-Rao bound.

``"auto"`` (default)
    ``"equation"`` when the data satisfy eq. (3) to round-off (noise-free
    virtual data) or the recording says its sensors are ideal, ``"eiv"``
    otherwise.

The equation forms stream the samples in blocks through a QR update per
floor equation (each floor's equation touches only its own row of unknowns),
so memory stays flat for long records.  ``kappa`` follows from
``C = mu M + kappa K`` by least squares.
"""

from __future__ import annotations

from collections.abc import Sequence
import contextlib
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
from threadpoolctl import threadpool_limits

from momentid.core.analytic import modal_properties
from momentid.core.processes import in_background
from momentid.core.series import Experiment
from momentid.errors import IdentificationError
from momentid.estimation.equation_form import (MAX_CONDITION, check_times, equation_form, equation_residual,
                                               exact_fit, identify_stream)
from momentid.estimation.identified import (MAX_NOISE_EXCESS, DampingFit, Identification, damping_models,
                                            identification_result)
from momentid.estimation.layout import Layout, equation_form_bytes, require_equation_memory
from momentid.estimation.reconstruct import Prefilter, suggest_band
from momentid.io.run_checks import check_run

if TYPE_CHECKING:
    from momentid.estimation.scaled import ModalIdentification

__all__ = ["Identification", "identify", "equation_residual", "damping_models", "DampingFit", "ESTIMATORS",
           "MAX_CONDITION", "MAX_NOISE_EXCESS", "Layout", "equation_form_bytes", "require_equation_memory",
           "identify_stream"]

ESTIMATORS = ("auto", "equation", "difference", "eiv", "modal")


def _ideal(experiment: Experiment) -> bool:
    sensors = experiment.scenario.get("sensors") if experiment.scenario else None
    return bool(sensors and sensors.get("ideal"))


def identify(experiment: Experiment, *, estimator: str = "auto", mass: str = "diagonal",
             runs: Sequence[str] | None = None, times: Sequence[float] | None = None,
             prefilter: Prefilter | str | None = "auto") -> Identification | ModalIdentification:
    """Identify a shear building's dynamics from shake-table runs.

    What comes out depends on what the runs hold:

    * **Runs with added mass** (the Majcher 2025 method): M, C, K, the Rayleigh
      coefficients mu and kappa, with standard errors (:class:`Identification`).
    * **No run adds mass** (most real labs): the table-to-floor transfer fixes
      M^-1 K and M^-1 C only.  Natural frequencies, damping ratios and mode
      shapes with standard errors, M^-1 K and M^-1 C; with floor masses stated
      by the lab (``experiment.statement.masses``, or the nominal model's)
      also K and C in SI units
      (:class:`~momentid.estimation.scaled.ModalIdentification`, see
      :mod:`momentid.estimation.modal`).  Accelerometers only suffice, at any
      sample rate above ~2.4 x the top mode.

    Sensor noise levels come from :func:`momentid.estimation.noise.estimate_noise`:
    stated by the lab, the quiet seconds before the table moves, or a band above
    the structure's response (high-rate recordings); the result says which.

    Parameters
    ----------
    experiment : Experiment
        Runs with the table acceleration ``zdd`` and floor accelerations
        ``a1..ad`` (m/s^2), plus displacements/velocities where measured (the
        added-mass estimators reconstruct missing ones, see
        :mod:`momentid.estimation.reconstruct`).
    estimator : {"auto", "equation", "difference", "eiv", "modal"}
        ``"auto"`` (default): ``"modal"`` when no run of the experiment adds
        mass; otherwise ``"equation"`` for noise-free data, ``"eiv"`` for noisy
        data (select only reference runs of an added-mass experiment with
        ``"modal"`` explicitly).
        ``"equation"``: method.md eq. (3) by least squares, every run on its
        own.  ``"difference"``: the paper's eq. (2), each run minus the
        reference run (same table motion needed).  ``"eiv"``: errors-in-variables
        maximum likelihood, unbiased by noise on every channel.  ``"modal"``:
        the modal errors-in-variables fit for runs without added mass.
    mass : {"diagonal", "full"}
        Shape of the identified mass matrix (added-mass estimators).
    runs : sequence of str, optional
        Names of the runs to use (all by default).
    times : sequence of float, optional
        Equation forms only: use just the samples nearest these times (s).
        ``times=[5.0]`` with ``estimator="difference"`` is the paper's system.
    prefilter : Prefilter, "auto" or None
        Band applied to every channel before the equation forms.  "auto":
        none for ideal (noise-free) recordings, else a zero-phase low-pass
        just above the structure's response band.

    Returns
    -------
    Identification or ModalIdentification
        Both have ``modes()``, ``to_dict()`` (with ``frequency_hz`` and
        ``damping_ratio`` lists, mode 1 first), ``notes`` and ``warnings``.
        ``warnings`` lists what the data contradict or cannot support
        (unstable modes, non-positive masses, a fit stopped at its iteration
        cap, poorly excited modes, sensors that physics places on other floors
        than listed: :func:`momentid.io.placement.placement_warnings`); the CLI
        prints each as ``WARNING:``.

    Raises
    ------
    IdentificationError
        The runs cannot identify the unknowns: a single run with added mass,
        too little excitation, no source for the noise level.
    SensorDataError
        A needed channel is missing, or data are unusable (gaps, clipping).

    Examples
    --------
    >>> result = identify(experiment)                      # doctest: +SKIP
    >>> result.modes().frequency, result.to_dict()["damping_ratio"]   # doctest: +SKIP
    """
    # The work is thousands of small dense products: BLAS threads only add
    # synchronisation (300x slower for 8x8 expm on a busy 2-core machine).
    with threadpool_limits(limits=1, user_api="blas"):
        if estimator == "modal" or (estimator == "auto" and not _adds_mass(experiment, None)):
            result = _identify_modal(experiment, runs, times)
        else:
            result = _identify(experiment, estimator=estimator, mass=mass, runs=runs, times=times,
                               prefilter=prefilter)
    from momentid.io.placement import placement_warnings  # sensors on other floors than listed (issue 18)
    return replace(result, warnings=(*placement_warnings(experiment), *result.warnings))


def _adds_mass(experiment: Experiment, runs) -> bool:
    selected = experiment.select(runs)
    return any(np.any(r.added_mass) for r in selected)


def _identify_modal(experiment: Experiment, runs, times):
    from momentid.estimation.scaled import identify_modal

    if times is not None:
        raise IdentificationError(f"times = {list(times)}: chosen instants work only with the equation forms, "
                                  f"which need runs with added mass")
    if _adds_mass(experiment, runs):
        raise IdentificationError(
            f"{experiment.source}: estimator 'modal' fits runs without added mass, but some selected runs "
            f"add mass: select the reference runs (--runs) or use 'eiv'")
    return identify_modal(experiment, runs)


def _nominal_fit(experiment: Experiment, layout: Layout, selected, f_max: float, stated):
    """The errors-in-variables fit started from the lab's nominal model, as a job (None: no nominal
    model, or a full mass matrix)."""
    s0 = experiment.structure
    if s0 is None or layout.mass != "diagonal":
        return None
    from momentid.estimation.eiv import fit_eiv
    nominal = layout.pack(s0.mass_matrix(), s0.damping_matrix(), s0.stiffness_matrix(), s0.rayleigh_mu)
    f_nominal = max(f_max, 2.0 * float(modal_properties(s0.mass_matrix(), s0.damping_matrix(),
                                                         s0.stiffness_matrix()).frequency.max()))
    return lambda: fit_eiv(layout, selected, nominal, stated=stated, f_max=f_nominal)


def _identify(experiment: Experiment, *, estimator: str, mass: str, runs, times,
              prefilter) -> Identification:
    """The added-mass estimators of :func:`identify`."""
    if estimator not in ESTIMATORS:
        raise IdentificationError(f"estimator = {estimator!r}: expected one of {', '.join(ESTIMATORS)}")
    ideal = _ideal(experiment)
    selected = experiment.select(runs)
    names = tuple(r.name for r in selected)
    if len(selected) < 2:
        raise IdentificationError(
            f"{experiment.source}: {len(selected)} run(s) {list(names)}: expected at least two "
            f"(a reference run and a run with added mass), or estimator 'modal' for the modes of runs "
            f"without added mass"
        )
    d = selected[0].added_mass.shape[0]
    if all(not np.any(r.added_mass) for r in selected):
        raise IdentificationError(
            f"{experiment.source}: no run among {list(names)} adds mass: estimator {estimator!r} fixes M, C, K "
            f"only up to scale; use estimator 'modal' (or 'auto'), which identifies the modes and, with stated "
            f"masses, K and C"
        )
    notes: list[str] = []
    checked = []
    for run in selected:
        if run.has("a1") and not ideal:
            run, repairs = check_run(run, experiment.source)
            notes.extend(repairs)
        checked.append(run)
    selected = tuple(checked)
    check_times(selected, times)
    layout = Layout(d, mass)
    if estimator == "auto" and times is not None:
        estimator = "equation"
    if estimator == "eiv" and times is not None:
        raise IdentificationError(f"times = {list(times)}: only the equation forms work at chosen instants; "
                                  f"use estimator 'equation' or 'difference'")
    if estimator == "auto":
        exact = equation_form(experiment, selected, layout, "equation", times, Prefilter(), names, notes)
        if ideal or exact_fit(exact, selected):
            return exact
        estimator = "eiv"
        notes.append(f"equation residual {exact.residual_rms:.3g} N is above round-off: the data carry "
                     f"noise, so the errors-in-variables estimator is used")
    if prefilter == "auto":
        band = (Prefilter() if ideal or estimator == "difference" or times is not None
                else Prefilter(high=suggest_band(selected[0], d)))
    else:
        band = prefilter or Prefilter()
    if band.active:
        notes.append(f"equation form on signals filtered to {band.low:g}-{band.high or 'inf'} Hz")
    eq_name = "difference" if estimator == "difference" else "equation"
    try:
        start = equation_form(experiment, selected, layout, eq_name, times, band, names, notes)
    except IdentificationError as exc:
        if estimator != "eiv":
            raise
        raise IdentificationError(f"estimator 'eiv' starts from the equation form, which failed: {exc}") from None
    if estimator != "eiv":
        return start
    from momentid.estimation.eiv import fit_eiv
    f_top = float(start.modes().frequency.max())
    f_max = max(band.high or 0.0, 2.0 * f_top)
    stated = dict(experiment.statement.noise) if experiment.statement is not None else None
    job = _nominal_fit(experiment, layout, selected, f_max, stated)
    with in_background(job) if job else contextlib.nullcontext() as nominal_fit:
        # (started beside the first fit, on the other core: it is wanted whenever the data carry physics
        # the linear model lacks, and side by side the two take little longer than the first alone)
        fit = fit_eiv(layout, selected, start.theta, f_max=f_max, stated=stated)
        if fit.scale > 1.5 and job is not None:
            # The residual sits well above the noise: the equation-form start (biased by noise, badly so
            # for accelerometer-only data) may have led to a local minimum. Try the lab's nominal model.
            second = nominal_fit()
            if second.cost < fit.cost:
                fit = second
                notes.append("errors-in-variables fit restarted from the nominal model (lower cost)")
    notes.append(f"errors-in-variables fit over 0-{f_max:.3g} Hz: {fit.nfev} model evaluations, "
                 f"residual variance factor {fit.scale:.3g} (1 = at the noise level)")
    notes.append(f"noise levels: {'; '.join(fit.noise_sources)}")
    return identification_result(layout, fit.theta, "eiv", fit.n_residuals, start.rank, start.condition,
                   float(np.sqrt(fit.scale)), names, fit.covariance, notes, capped=fit.capped)
