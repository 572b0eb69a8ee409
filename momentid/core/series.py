"""Time series of an experiment: what simulation produces and recordings hold.

Arrays are time-first: ``values`` has shape ``(n_samples, n_channels)``.
Channel names follow one vocabulary everywhere (recordings, CSV import,
identification): ``zdd`` base absolute acceleration (m/s^2), ``z``/``zd``
base displacement/velocity (m, m/s), ``a1..ad`` floor absolute accelerations
(m/s^2), ``q1..qd`` floor displacements relative to the base (m), ``v1..vd``
floor velocities relative to the base (m/s); floor 1 is the lowest.  An imported
table sensor's other motions (:data:`TABLE_MOTION`): ``table_ay``, ``table_az`` its
acceleration across the shaking axis and along gravity (m/s^2), ``table_wx``,
``table_wy``, ``table_wz`` its angular rates about the shaking, cross and gravity
axes (rad/s), each less its mean.
"""

from __future__ import annotations

from collections.abc import Iterable
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from momentid.errors import SensorDataError
from momentid.core.structure import LabStatement, Structure

__all__ = ["RunData", "Experiment", "UNITS", "TABLE_MOTION", "channel_unit", "json_safe", "run_name_problem"]

#: SI unit of each channel group.
UNITS = {"zdd": "m/s^2", "z": "m", "zd": "m/s", "a": "m/s^2", "q": "m", "v": "m/s",
         "table_ay": "m/s^2", "table_az": "m/s^2", "table_wx": "rad/s", "table_wy": "rad/s", "table_wz": "rad/s"}
#: The table sensor's motions besides the shaking axis, in this order.
TABLE_MOTION = ("table_ay", "table_az", "table_wx", "table_wy", "table_wz")


def json_safe(obj: Any) -> Any:
    """``obj`` with non-finite floats as None (strict JSON), through dicts, lists and tuples."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    return obj


def run_name_problem(name: object) -> str | None:
    """Why ``name`` cannot name a run, or None when it can.

    A run name is printed in one-line reports and becomes part of file names: it must be a non-empty
    string of at most 200 printable characters, without line breaks, tabs or other control characters,
    without ``/`` or ``\\``, without ``..``, without ``,`` (``--runs`` separates names by commas), and
    without leading or trailing spaces.  Spaces inside ("El Centro Trial 1") are fine.
    """
    import unicodedata

    if not isinstance(name, str) or not name:
        return "an empty name"
    if len(name) > 200:
        return f"{len(name)} characters (at most 200)"
    bad = next((c for c in name if unicodedata.category(c)[0] == "C"), None)
    if bad is not None:
        return f"the control character {bad!r} (a line break or tab breaks every printed report line)"
    for part in ("/", "\\", ".."):
        if part in name:
            return f"{part!r} (a run name becomes part of file names)"
    if "," in name:
        return "',' (--runs lists run names separated by commas: this run could never be chosen)"
    if name != name.strip():
        return "leading or trailing spaces"
    return None


def channel_unit(name: str) -> str:
    """Unit of channel ``name`` (``'a2'`` -> ``'m/s^2'``)."""
    if name in UNITS:
        return UNITS[name]
    group = name.rstrip("0123456789")
    if group in UNITS and group != name:
        return UNITS[group]
    return "1"


@dataclass(frozen=True)
class RunData:
    """One run of the experiment.

    Attributes
    ----------
    name : str
        Run name (unique in the experiment).
    added_mass : ndarray, shape (d,)
        Masses bolted to floors 1..d for this run (kg).
    time : ndarray, shape (n,)
        Sample times (s), strictly increasing.
    channels : tuple of str, length c
        Channel names, see the module docstring.
    values : ndarray, shape (n, c)
        Samples in SI units.
    """

    name: str
    added_mass: np.ndarray
    time: np.ndarray
    channels: tuple[str, ...]
    values: np.ndarray
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        n = self.time.shape[0]
        if self.values.shape != (n, len(self.channels)):
            raise SensorDataError(
                f"run {self.name!r}: values have shape {self.values.shape}, expected "
                f"({n}, {len(self.channels)}) for {n} samples of channels {list(self.channels)}"
            )

    @property
    def n_samples(self) -> int:
        """Number of samples of the run."""
        return self.time.shape[0]

    @property
    def sample_rate(self) -> float:
        """Mean sample rate (Hz)."""
        if self.n_samples < 2:
            return float("nan")
        return (self.n_samples - 1) / (self.time[-1] - self.time[0])

    def window(self, start: int, stop: int | None = None, name: str | None = None) -> RunData:
        """Samples ``start:stop`` as a run of their own, its time from 0 (a record cut out of this one).

        Parameters
        ----------
        start, stop : int
            Sample indices (``stop`` None: to the end; past the end: the end).
        name : str, optional
            The window's name (default: this run's).

        Returns
        -------
        RunData
            The same channels and added masses; ``meta`` (what an import recorded of the whole run) is not
            carried.

        Raises
        ------
        SensorDataError
            ``start`` outside the run, or ``stop`` not after it.
        """
        if not 0 <= start < self.n_samples or (stop is not None and stop <= start):
            raise SensorDataError(f"run {self.name!r}: window of samples {start}:{stop}; expected 0 <= start < stop, "
                                  f"start below the run's {self.n_samples} samples")
        s = slice(start, stop)
        return RunData(name=self.name if name is None else name, added_mass=self.added_mass,
                       time=self.time[s] - self.time[start], channels=self.channels, values=self.values[s])

    def has(self, channel: str) -> bool:
        """Whether the run holds channel ``channel`` (``"zdd"``, ``"a1"``, ...)."""
        return channel in self.channels

    def __getitem__(self, channel: str) -> np.ndarray:
        """Column of ``channel``, shape (n,)."""
        try:
            return self.values[:, self.channels.index(channel)]
        except ValueError:
            raise SensorDataError(
                f"run {self.name!r}: no channel {channel!r}; it has {', '.join(self.channels)}"
            ) from None

    def group(self, prefix: str, storeys: int | None = None) -> np.ndarray:
        """Per-floor channels ``prefix1..prefixd`` as shape (n, d)."""
        d = storeys if storeys is not None else self.added_mass.shape[0]
        return np.column_stack([self[f"{prefix}{i + 1}"] for i in range(d)])


@dataclass(frozen=True)
class Experiment:
    """All runs of one experiment plus what the file says about the rig.

    Attributes
    ----------
    runs : tuple of RunData
    structure : Structure or None
        The nominal (analytic) model the experiment was run or described with.
    scenario : dict
        Scenario summary (name, duration, sample rate, excitation, ...).
    scenario_text : str
        The scenario file's text, when the experiment came from a scenario.
    source : str
        Where it was read from (a path) or ``'<memory>'``.
    complete : bool
        False when runs were lost (a truncated recording was recovered).
    notes : tuple of str
        What was repaired or recovered while reading.
    statement : LabStatement or None
        What the lab states short of a full nominal model (stated masses, noise
        levels); None for simulated experiments, which carry ``structure``.
    """

    runs: tuple[RunData, ...]
    structure: Structure | None = None
    scenario: dict = field(default_factory=dict)
    scenario_text: str = ""
    source: str = "<memory>"
    complete: bool = True
    notes: tuple[str, ...] = ()
    statement: LabStatement | None = None

    @property
    def storeys(self) -> int:
        """Number of storeys ``d`` (the length of the first run's added-mass vector)."""
        return self.runs[0].added_mass.shape[0]

    @property
    def name(self) -> str:
        """The scenario's name, ``"experiment"`` when it has none."""
        return self.scenario.get("name", "experiment")

    def run(self, name: str) -> RunData:
        """The run named ``name``; a :class:`~momentid.errors.SensorDataError` when there is none."""
        for r in self.runs:
            if r.name == name:
                return r
        raise SensorDataError(
            f"{self.source}: no run named {name!r}; runs are {', '.join(r.name for r in self.runs)}"
        )

    def select(self, names: Iterable[str] | None = None) -> tuple[RunData, ...]:
        """The runs named ``names``, in that order (every run when None).

        A run named twice is refused: its samples would count twice, and every standard error
        would shrink by sqrt(2) with no new information.
        """
        if names is None:
            return self.runs
        names = list(names)
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice or not names:
            raise SensorDataError(f"{self.source}: runs = {names}: expected each run at most once and at least one "
                                  + (f"(run {twice[0]!r} is named {names.count(twice[0])} times: the same data would "
                                     f"count as new evidence)" if twice else "run"))
        return tuple(self.run(n) for n in names)
