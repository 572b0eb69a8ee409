"""Stages that run on the worker processes give what they give one after the other, bit for bit."""

from __future__ import annotations

from threadpoolctl import threadpool_limits

from momentid.diagnosis.added_mass import selection as selection
from momentid.diagnosis.added_mass.residuals import equation_residuals, fit_linear_model
from momentid.diagnosis.added_mass.selection import screen
from momentid.diagnosis.added_mass.sensor_faults import check_sensors


def _screened(experiment):
    with threadpool_limits(limits=1, user_api="blas"):   # as diagnose() runs its stages, and a worker its job
        model = fit_linear_model(experiment, None)
        residuals = equation_residuals(model)
        out = screen(model, residuals, check_sensors(model))
    return [(c.kind.name, c.place, c.parameters, c.std, c.explained, c.domain) for c in out.candidates], out.pool


def _first_seconds(experiment, seconds: float):
    """``experiment`` with every run cut to its first ``seconds`` (each replay costs that much less)."""
    from dataclasses import replace

    runs = tuple(r.window(0, int(round(seconds * r.sample_rate))) for r in experiment.runs)
    return replace(experiment, runs=runs)


def test_screening_on_the_workers_is_screening_in_turn(simulated, monkeypatch):
    experiment = _first_seconds(simulated("hidden/flexible_floor3", ideal=True), 8.0)
    forked, forked_pool = _screened(experiment)
    monkeypatch.setattr(selection, "run_forked", lambda job, tasks: [job(t) for t in tasks])   # here, in turn
    here, here_pool = _screened(experiment)
    # Every candidate, in the same order, with the same numbers: the jobs are deterministic and
    # single-threaded, and their results are merged in the order one screen gives them.
    assert forked == here and len(forked) > 10
    assert [(c.kind, c.place) for c in forked_pool] == [(c.kind, c.place) for c in here_pool]


def test_replays_on_the_workers_are_replays_in_turn(simulated, monkeypatch):
    """A size search replays its grid and its curvature's neighbours side by side, and a score its
    training runs: on threads (the friction's law runs natively), on forked workers, and one after the
    other, the same numbers."""
    from momentid import mechanisms
    from momentid.core import processes
    from momentid.diagnosis.added_mass import resimulation as refit
    from momentid.diagnosis.added_mass.augmented import Entry, records
    from momentid.lab import native_forces

    experiment = _first_seconds(simulated("hidden/friction_storey2"), 8.0)   # as long as the equality needs
    with threadpool_limits(limits=1, user_api="blas"):
        model = fit_linear_model(experiment, None)
    kind = mechanisms.get("coulomb_friction")
    entry = Entry(kind, kind.place(2), {"force": 0.2})
    threads = []

    def searched():
        refitter = refit.Refitter(model, None)   # its caches empty
        structure = refitter.better_of((refitter.linear_structure, model.nominal), [entry])
        params, std = refitter.resimulate(structure, entry, span=(0.8, 2.0), grid=3)
        found = Entry(kind, entry.place, params)
        return structure, params, std, refitter.score_joint(structure, [found], records([found]))

    def counted(job, tasks):
        threads.append(len(tasks))
        return processes.run_threaded(job, tasks)

    assert native_forces.threadable(records([entry]))
    monkeypatch.setattr(refit, "run_threaded", counted)
    on_threads = searched()
    assert threads   # the batches went to threads
    monkeypatch.setattr(refit, "run_threaded", processes.run_forked)   # forked workers
    forked = searched()
    in_turn = lambda job, tasks: [job(t) for t in tasks]   # noqa: E731
    monkeypatch.setattr(refit, "run_threaded", in_turn)
    monkeypatch.setattr(refit, "run_forked", in_turn)
    here = searched()
    # Each replay is deterministic and single-threaded: equal, not close.
    assert on_threads == forked == here and 0.2 < forked[1]["force"] < 0.4


def test_native_and_plain_replays_share_the_threads(simulated):
    """Replays with a native force and replays of models with none, side by side on threads (the
    installed native callback leaves a model without forces alone): each as alone."""
    from momentid import mechanisms
    from momentid.core.processes import run_threaded
    from momentid.diagnosis.added_mass import resimulation as refit
    from momentid.diagnosis.added_mass.augmented import Entry

    experiment = _first_seconds(simulated("hidden/friction_storey2"), 8.0)
    with threadpool_limits(limits=1, user_api="blas"):
        model = fit_linear_model(experiment, None)
    refitter = refit.Refitter(model, None)
    friction, damper = mechanisms.get("coulomb_friction"), mechanisms.get("extra_damper")
    trials = [(refitter.linear_structure, [Entry(friction, friction.place(2), {"force": f})]) for f in (0.2, 0.3)]
    trials += [(refitter.linear_structure, [Entry(damper, damper.place(2), {"c": c})]) for c in (1.0, 2.0)]
    trials += [(refitter.linear_structure, [])]
    order = [0, 2, 1, 3, 4, 0, 4, 2]
    alone = [refitter.misfit(*trials[i]) for i in order]
    assert run_threaded(lambda i: refitter.misfit(*trials[i]), order) == alone


def test_the_size_searchs_opening_is_the_one_scipy_asks_for():
    """``brent_opening`` names the first three points scipy's bounded search evaluates, replayed side
    by side before it asks (a wrong prediction would waste a replay each search)."""
    import math

    import numpy as np
    import scipy.optimize

    from momentid.diagnosis.added_mass.resimulation import brent_opening
    grid = np.linspace(math.log(0.3), math.log(3.0), 11)
    for bounds, xatol in (((math.log(0.5 * 0.2), math.log(5.0 * 0.2)), 0.005), ((math.log(0.5), math.log(2.0)), 0.02),
                          ((grid[3], grid[5]), 0.005)):
        for low in (bounds[0] - 1.0, bounds[1] + 1.0, 0.5 * (bounds[0] + bounds[1])):   # minimum below, above, inside
            asked, values = [], []

            def f(u):
                asked.append(u)
                values.append((u - low) ** 2)
                return values[-1]
            scipy.optimize.minimize_scalar(f, bounds=bounds, method="bounded", options={"xatol": xatol})
            # equal, not close: they are the cache's keys
            assert asked[:2] == brent_opening(bounds, xatol)
            assert asked[2:3] == brent_opening(bounds, xatol, (values[0], values[1]))
