"""Experiment design: Cramér-Rao bounds and a planner for added-mass runs.

How well can an experiment *as designed* identify ``M, C, K, mu``?  The
Cramér-Rao lower bound (CRLB) answers before anything is built: simulate the
designed runs without noise (the linear model, :mod:`momentid.estimation.linear`),
evaluate the errors-in-variables Fisher information at the true parameters
with the scenario's sensor noise (:func:`momentid.estimation.eiv.fisher_information`), and
invert it.  No unbiased estimator can do better; momentid's ``eiv`` estimator
reaches it (see ``benchmarks/accuracy.py``).

:func:`plan` searches added-mass patterns, numbers of runs and excitations for
the cheapest design whose worst parameter meets a target relative standard
deviation.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, replace
from collections.abc import Callable, Iterator, Sequence

import numpy as np

from momentid.core.series import RunData
from momentid.estimation.eiv import fisher_information
from momentid.errors import IdentificationError, ScenarioError, TimeLimitError
from momentid.estimation.layout import Layout
from momentid.estimation.linear import discretize, outputs, simulate_linear
from momentid.lab.scenario import BandLimitedNoise, Run, Scenario
from momentid.lab.sensors import noise_std
from momentid.lab.simulation import ground_motion_of

__all__ = ["Bound", "cramer_rao", "plan", "plan_progress_bar", "Design", "PLAN_TIME_LIMIT_S"]

#: The Fisher information sums frequency bins up to this multiple of the top
#: natural frequency: above it the structure's response is below the noise.
INFORMATION_BAND_FACTOR = 2.0

#: The planner's band-limited noise excitation spans the modes with this margin:
#: from half the first natural frequency ...
NOISE_BAND_LOW_FACTOR = 0.5
#: ... (but not below this many Hz, where a table's stroke runs out) ...
NOISE_BAND_LOW_MIN = 0.05
#: ... up to 1.5 times the top natural frequency ...
NOISE_BAND_HIGH_FACTOR = 1.5
#: ... and below this fraction of the sample rate (clear of the Nyquist frequency).
NOISE_BAND_HIGH_MAX_FRACTION = 0.4

#: Added mass per run as fractions of each floor's mass for the planner's
#: "every floor" patterns (a few percent moves the modes measurably without
#: overloading the rig), and the single fraction of the other two patterns.
EVERY_FLOOR_FRACTIONS = (0.05, 0.1, 0.2)
PATTERN_FRACTION = 0.1

#: The planner's default time limit (s): its work is one noise-free simulation and Fisher information
#: per candidate run (timed on the first before the others start), and a plan that would take
#: longer than a coffee break is refused with the ``max_runs`` that fits.
PLAN_TIME_LIMIT_S = 600.0
#: The planner's band-limited noise ramps in and out over this long (s), at most a quarter of the record.
NOISE_TAPER_S = 1.0


@dataclass(frozen=True)
class Bound:
    """Cramér-Rao bound of one experiment design.

    Attributes
    ----------
    names : tuple of str
        Parameter names (``M[1,1]``, ``C[1,2]``, ..., ``mu``), 1-based.
    values : ndarray, shape (p,)
        True parameter values.
    std : ndarray, shape (p,)
        Lower bound on the standard deviation of each parameter.
    relative : ndarray, shape (p,)
        ``std / |value|``; zero entries relative to their matrix's largest entry.
    covariance : ndarray, shape (p, p)
    """

    names: tuple[str, ...]
    values: np.ndarray
    std: np.ndarray
    relative: np.ndarray
    covariance: np.ndarray

    @property
    def worst(self) -> tuple[str, float]:
        """The parameter with the largest relative bound, and that bound."""
        i = int(np.argmax(self.relative))
        return self.names[i], float(self.relative[i])

    def as_dict(self) -> dict:
        """Per parameter name: its value, CRLB standard deviation and relative bound."""
        return {n: {"value": float(v), "crlb_std": float(s), "relative": float(r)}
                for n, v, s, r in zip(self.names, self.values, self.std, self.relative)}


def parameter_names(layout: Layout) -> tuple[str, ...]:
    """The names of ``layout``'s parameters in theta's order: ``M[i,j]``, ``C[i,j]``, ``K[i,j]`` (1-based),
    ``mu``."""
    names = [""] * layout.p
    d = layout.d
    for i in range(d):
        for j in range(i, d):
            if layout.mass == "full" or i == j:
                names[layout.m[i, j]] = f"M[{i + 1},{j + 1}]"
            names[layout.c[i, j]] = f"C[{i + 1},{j + 1}]"
            names[layout.k[i, j]] = f"K[{i + 1},{j + 1}]"
    names[layout.mu] = "mu"
    return tuple(names)


def _designed_runs(scenario: Scenario, runs) -> tuple[list[RunData], dict]:
    """Noise-free linear-model runs at the sensor rate, and the noise of every channel."""
    s = scenario.structure
    d = s.storeys
    fs = scenario.sensors.sample_rate or scenario.sample_rate
    n = int(round(scenario.duration * fs)) + 1
    t = np.arange(n) / fs
    zdd = ground_motion_of(scenario).acceleration(t)
    groups = [g for g in scenario.sensors.groups if g in ("a", "q", "v")]
    out, sigma = [], {}
    for run in runs:
        dm = np.asarray(run.added_mass, float)
        model = discretize(s.mass_matrix() + np.diag(dm), s.damping_matrix(dm), s.stiffness_matrix(), 1 / fs)
        y = outputs(model, simulate_linear(model, zdd))
        names = ["zdd"] + [f"{g}{i + 1}" for g in groups for i in range(d)]
        values = np.column_stack([zdd] + [y[g] for g in groups])
        rd = RunData(run.name, dm, t, tuple(names), values)
        out.append(rd)
        for j, name in enumerate(names):
            sig = noise_std(scenario.sensors.instrument(name), values[:, j], fs)
            sigma.setdefault(run.name, {})[name] = sig
    return out, sigma


def _run_information(scenario: Scenario, run: Run, layout: Layout, theta: np.ndarray, f_max: float,
                     cache: dict | None) -> np.ndarray:
    key = (id(scenario), tuple(run.added_mass))
    if cache is not None and key in cache:
        return cache[key]
    data, sigma = _designed_runs(scenario, [run])
    info = fisher_information(layout, data, theta, sigma[run.name], f_max=f_max)
    if cache is not None:
        cache[key] = info
    return info


def _information_setup(scenario: Scenario, mass: str = "diagonal") -> tuple[Layout, np.ndarray, float]:
    """The unknowns' layout, their true values and the top of the information band (Hz)."""
    if scenario.sensors.ideal:
        raise ScenarioError(f"{scenario.source}: [sensors] are ideal (noise-free): the Cramér-Rao bound is 0; "
                            f"give the instruments' noise to plan an experiment")
    from momentid.core.analytic import modal_properties
    s = scenario.structure
    layout = Layout(s.storeys, mass)
    theta = layout.pack(s.mass_matrix(), s.damping_matrix(), s.stiffness_matrix(), s.rayleigh_mu)
    f_top = float(modal_properties(s.mass_matrix(), s.damping_matrix(), s.stiffness_matrix()).frequency.max())
    return layout, theta, INFORMATION_BAND_FACTOR * f_top


def cramer_rao(scenario: Scenario, runs: Sequence[Run] | None = None, *, mass: str = "diagonal",
               _cache: dict | None = None) -> Bound:
    """The CRLB of ``scenario``'s experiment (or of ``runs`` under its excitation).

    The sensor noise comes from the scenario's ``[sensors]``
    (:func:`momentid.lab.sensors.noise_std`); a scenario with ideal sensors
    has no finite bound and is refused.  Runs are independent, so their
    Fisher informations add.

    Parameters
    ----------
    scenario : Scenario
        Structure, excitation, sensors and (unless ``runs`` is given) runs.
    runs : sequence of Run, optional
        Added-mass runs to evaluate instead of ``scenario.runs``.
    mass : {"diagonal", "full"}
        Unknowns of the mass matrix, as in :func:`momentid.identify`.

    Returns
    -------
    Bound
        Parameter names, true values, CRLB standard deviations (SI units of
        each parameter), relative ones and the covariance, shape (p, p).

    Raises
    ------
    ScenarioError
        The scenario's sensors are ideal (no noise, no finite bound).
    IdentificationError
        The runs do not identify every unknown (singular information).
    """
    runs = tuple(runs) if runs is not None else scenario.runs
    s = scenario.structure
    layout, theta, f_max = _information_setup(scenario, mass)
    info = sum(_run_information(scenario, run, layout, theta, f_max, _cache) for run in runs)
    try:
        cov = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        raise IdentificationError(f"{scenario.source}: the designed runs do not identify the unknowns "
                                  f"(singular Fisher information)") from None
    std = np.sqrt(np.clip(np.diag(cov), 0, None))
    rel = np.empty_like(std)
    M, C, K, mu = layout.unpack(theta)
    for idx, X in ((layout.m, M), (layout.c, C), (layout.k, K)):
        big = float(np.max(np.abs(X)))
        for i in range(s.storeys):
            for j in range(s.storeys):
                if layout.mass == "diagonal" and X is M and i != j:
                    continue
                p = idx[i, j]
                rel[p] = std[p] / (abs(X[i, j]) if X[i, j] != 0 else big)
    rel[layout.mu] = std[layout.mu] / abs(mu) if mu else std[layout.mu]
    return Bound(parameter_names(layout), theta, std, rel, cov)


@dataclass(frozen=True)
class Design:
    """One candidate design and its bound."""

    label: str
    excitation: str
    runs: tuple[Run, ...]
    bound: Bound

    @property
    def added_mass_total(self) -> float:
        """The mass added over all the design's runs (kg)."""
        return float(sum(np.sum(r.added_mass) for r in self.runs))


def _patterns(masses: np.ndarray) -> dict[str, np.ndarray]:
    d = masses.size
    out = {}
    for f in EVERY_FLOOR_FRACTIONS:
        out[f"{f * 100:g} % of every floor"] = f * masses
    percent = f"{PATTERN_FRACTION * 100:g} %"
    top = np.zeros(d)
    top[-1] = PATTERN_FRACTION * masses[-1]
    out[f"{percent} on the top floor"] = top
    alt = np.where(np.arange(d) % 2 == 0, PATTERN_FRACTION * masses, 0.0)
    out[f"{percent} on floors 1, 3, ..."] = alt
    return out


def plan(scenario: Scenario, *, target: float = 0.01, max_runs: int = 4, time_limit: float | None = PLAN_TIME_LIMIT_S,
         progress: Callable[[int, int], None] | None = None) -> tuple[list[Design], Design | None]:
    """Evaluate candidate designs; return all and the recommended one.

    Candidates: the scenario's excitation and a band-limited noise of the
    same RMS table acceleration covering every mode; a reference run plus
    1..``max_runs - 1`` runs of each added-mass pattern (scaled 1x, 2x, ...
    for repeated runs).  Recommended: the design meeting ``target`` (worst
    relative CRLB std over every parameter, ``mu`` included) with the fewest
    runs, then the least added mass.

    Parameters
    ----------
    scenario : Scenario
        Structure, excitation and sensor noise of the rig (its runs are ignored).
    target : float
        Largest acceptable relative standard deviation of every parameter.
    max_runs : int
        Most runs a candidate design may have, the reference run included.
    time_limit : float or None
        Seconds the plan may take on this machine, estimated from its first candidate run before
        the others start (None: no limit).
    progress : callable, optional
        ``progress(done, total)`` after each design: designs evaluated so far, and in all.

    Returns
    -------
    designs : list of Design
        Every candidate with its :class:`Bound`.
    recommended : Design or None
        The cheapest design meeting ``target``; None when none does.

    Raises
    ------
    TimeLimitError
        The plan would take longer than ``time_limit`` (the message says which ``max_runs`` fits).
    ResourceError
        Its designs would not fit in memory.
    """
    from momentid.core.analytic import modal_properties
    if not (isinstance(max_runs, int) and max_runs >= 2):
        raise ScenarioError(f"max_runs = {max_runs!r}: expected an integer >= 2 (a reference run and one more)")
    s = scenario.structure
    masses = np.asarray(s.masses)
    f = modal_properties(s.mass_matrix(), s.damping_matrix(), s.stiffness_matrix()).frequency
    fs = scenario.sample_rate
    t = np.arange(scenario.n_samples) / fs
    rms = float(np.sqrt(np.mean(ground_motion_of(scenario).acceleration(t) ** 2)))
    band = (max(NOISE_BAND_LOW_FACTOR * f.min(), NOISE_BAND_LOW_MIN),
            min(NOISE_BAND_HIGH_FACTOR * f.max(), NOISE_BAND_HIGH_MAX_FRACTION * fs))
    noise = BandLimitedNoise(rms=rms, band=band, seed=scenario.seed, taper=min(NOISE_TAPER_S, scenario.duration / 4))
    excitations = {"scenario": scenario,
                   f"noise {noise.band[0]:.2g}-{noise.band[1]:.2g} Hz": replace(scenario, excitation=noise)}
    patterns = _patterns(masses)
    reference = Run("reference", tuple(np.zeros(s.storeys)))
    cache: dict = {}
    total = len(excitations) * (1 + len(patterns) * (max_runs - 1))   # candidate runs (at most: some repeat)
    _affordable(scenario, reference, cache, total, len(excitations), len(patterns), max_runs, time_limit)
    designs = []
    for ex_label, sc in excitations.items():
        for label, pattern in patterns.items():
            for extra in range(1, max_runs):
                runs = (reference,) + tuple(Run(f"added{k + 1}", tuple((k + 1) * pattern)) for k in range(extra))
                bound = cramer_rao(sc, runs, _cache=cache)
                designs.append(Design(f"{extra + 1} runs, {label}", ex_label, runs, bound))
                if progress is not None:
                    progress(len(designs), len(excitations) * len(patterns) * (max_runs - 1))
    meeting = [d for d in designs if d.bound.worst[1] <= target]
    best = min(meeting, key=lambda d: (len(d.runs), d.added_mass_total)) if meeting else None
    return designs, best


def _affordable(scenario: Scenario, reference: Run, cache: dict, total: int, n_excitations: int, n_patterns: int,
                max_runs: int, time_limit: float | None) -> None:
    """Refuse a plan that would not fit in memory or in ``time_limit``, before its work starts.

    The time of one candidate run is measured on the first one the plan needs (the reference run
    under the scenario's excitation, kept in ``cache``), so the estimate is this machine's today.
    """
    from momentid.core.resources import require_memory

    layout, theta, f_max = _information_setup(scenario)
    p = layout.p
    designs = n_excitations * n_patterns * (max_runs - 1)
    require_memory(8.0 * (designs * (p * p + 3 * p) + total * p * p),
                   f"{scenario.source}: plan of {designs} designs ({p} parameters each)",
                   "lower max_runs (momentid plan --max-runs)")
    start = time.perf_counter()
    _run_information(scenario, reference, layout, theta, f_max, cache)   # the reference run's, kept
    each = time.perf_counter() - start
    estimate = each * total
    if time_limit is not None and estimate > time_limit:
        fit = int((time_limit / each / n_excitations - 1) // n_patterns) + 1
        fits = (f"at most {fit} runs (--max-runs {fit}) fit in that time" if fit >= 2 else
                "not even two runs fit in that time")
        raise TimeLimitError(f"{scenario.source}: plan of up to {max_runs} runs ({total} candidate runs, "
                             f"{each:.2g} s each)", estimate, time_limit,
                             f"{fits}; raise the limit to go past it (momentid plan --time-limit SECONDS)")


@contextlib.contextmanager
def plan_progress_bar(enabled: bool) -> Iterator[Callable[[int, int], None] | None]:
    """A ``progress(done, total)`` for :func:`plan` that draws a bar on stderr (None when not ``enabled``)."""
    if not enabled:
        yield None
        return
    from tqdm import tqdm

    with tqdm(unit="design", desc="plan", leave=False, dynamic_ncols=True) as bar:
        def progress(done: int, total: int) -> None:
            bar.total = total
            bar.update(done - bar.n)
        yield progress
