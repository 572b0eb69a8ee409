"""Scenario files: the structure, excitation, added-mass runs and sensors.

A scenario is a TOML file validated strictly into frozen dataclasses; every
mistake is a one-line :class:`~momentid.errors.ScenarioError` naming the file,
the dotted key and the offending value.  The format is documented in the
README ("Scenario format") and by the shipped files in ``scenarios/``.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import asdict, dataclass, field
from importlib import resources
import os
from pathlib import Path
from typing import Any

import numpy as np

from momentid import mechanisms
from momentid.core.structure import Mechanism, Structure
from momentid.io.structure_table import parse_structure
from momentid.io.plausible import check_added_mass, check_excitation, check_structure
from momentid.io.toml_reader import Table, load_toml
from momentid.errors import ScenarioError
from momentid.lab.motions import BandLimitedNoise, Chirp, Excitation, Harmonics, RecordedMotion, Tracking
from momentid.mechanisms.base import SensorStage

__all__ = [
    "Harmonics",
    "RecordedMotion",
    "BandLimitedNoise",
    "Chirp",
    "Excitation",
    "Run",
    "Instrument",
    "ChannelFault",
    "Sensors",
    "SENSOR_SETS",
    "Scenario",
    "load_scenario",
    "set_key",
    "parse_scenario",
    "default_scenario_path",
    "SENSOR_GROUPS",
]

#: Sensor groups a scenario may ask for; ``a``, ``q``, ``v`` expand to one
#: channel per floor (``a1``..``ad``).
SENSOR_GROUPS = {
    "zdd": ("base absolute acceleration", "m/s^2"),
    "z": ("base (table) displacement", "m"),
    "zd": ("base (table) velocity", "m/s"),
    "a": ("floor absolute acceleration", "m/s^2"),
    "q": ("floor displacement relative to the base", "m"),
    "v": ("floor velocity relative to the base", "m/s"),
}


@dataclass(frozen=True)
class Run:
    """One added-mass run: ``added_mass`` (kg per floor, shape (d,))."""

    name: str
    added_mass: tuple[float, ...]


@dataclass(frozen=True)
class Instrument:
    """Noise and range of one kind of transducer (SI units of its channels).

    Attributes
    ----------
    noise : float
        White measurement noise, RMS at the sensor sample rate.
    noise_density : float
        Noise spectral density (unit/sqrt(Hz)); adds ``density * sqrt(fs / 2)`` RMS.
    relative_noise : float
        Noise RMS as a fraction of each channel's own RMS in the run (for
        studies: "1 % noise").  The three noise terms add in quadrature.
    resolution : float
        Quantisation step (0 = none).
    range : float
        Full scale: readings are clipped to +/- range (0 = unlimited).
    bias : float
        Constant offset added to every channel of this kind.
    """

    noise: float = 0.0
    noise_density: float = 0.0
    relative_noise: float = 0.0
    resolution: float = 0.0
    range: float = 0.0
    bias: float = 0.0

    @property
    def ideal(self) -> bool:
        """Whether the instrument adds nothing to the signal: no noise, resolution, range or bias."""
        return not any((self.noise, self.noise_density, self.relative_noise, self.resolution,
                        self.range, self.bias))


@dataclass(frozen=True)
class ChannelFault:
    """A channel's sensor faults (``[sensors.channel.X]``): one record per registered sensor-fault kind
    stated there (:class:`~momentid.mechanisms.base.SensorFault`: its ``setting`` is the key), which
    :func:`momentid.lab.sensors.measure` applies at each kind's stage with the kind's own ``distort``."""

    records: tuple[Mechanism, ...] = ()

    def apply(self, stage: SensorStage, time: np.ndarray, x: np.ndarray) -> np.ndarray:
        """``x`` (n,) at ``time`` (n,) (s) with this channel's faults of ``stage`` applied, in their order."""
        for record in self.records:
            kind = mechanisms.get(record.type)
            if kind.stage is stage:
                x = kind.distort(time, x, dict(record.parameters))
        return x

    def to_dict(self) -> dict:
        """``{setting: value}``, as ``[sensors.channel.X]`` states it."""
        return {mechanisms.get(r.type).setting.name: v for r in self.records for _, v in r.parameters}


#: Sensor sets: which channel groups a lab records.
SENSOR_SETS = {
    "all": ("zdd", "z", "zd", "a", "q", "v"),
    "accel+disp": ("zdd", "z", "a", "q"),
    "accel": ("zdd", "a"),
}

#: Which instrument measures each channel group.
INSTRUMENT_OF = {"zdd": "accelerometer", "a": "accelerometer", "z": "displacement",
                 "q": "displacement", "zd": "velocity", "v": "velocity"}


@dataclass(frozen=True)
class Sensors:
    """What the rig measures and how well.

    Attributes
    ----------
    set : str
        ``"all"`` (every channel, the default), ``"accel+disp"``
        (accelerometers and displacement transducers; velocities derived at
        identification) or ``"accel"`` (accelerometers only).
    groups : tuple of str
        Channel groups recorded (see :data:`SENSOR_GROUPS`).
    sample_rate : float or None
        Sensor sample rate (Hz), a divisor of the simulation rate; None = same.
    antialias : float
        Corner (Hz) of the 4th-order Butterworth anti-alias filter applied to
        every channel before sampling (0 = none).
    accelerometer, displacement, velocity : Instrument
    faults : tuple of (channel, ChannelFault)
        Per-channel sensor faults (``[sensors.channel.X]``).
    """

    groups: tuple[str, ...] = SENSOR_SETS["all"]
    set: str = "all"
    sample_rate: float | None = None
    antialias: float = 0.0
    accelerometer: Instrument = field(default_factory=Instrument)
    displacement: Instrument = field(default_factory=Instrument)
    velocity: Instrument = field(default_factory=Instrument)
    faults: tuple[tuple[str, ChannelFault], ...] = ()

    @property
    def ideal(self) -> bool:
        """True when the recorded channels are the simulator's exact values."""
        return (self.accelerometer.ideal and self.displacement.ideal and self.velocity.ideal
                and not self.faults and not self.antialias and self.sample_rate is None)

    def instrument(self, channel: str) -> Instrument:
        """The instrument of ``channel``'s group (``"a2"``: the accelerometer)."""
        group = channel.rstrip("0123456789") or channel
        return getattr(self, INSTRUMENT_OF[group])

    def fault(self, channel: str) -> ChannelFault:
        """The faults stated for ``channel`` (none when it has no ``[sensors.channel.X]``)."""
        return dict(self.faults).get(channel, ChannelFault())

    def channels(self, storeys: int) -> tuple[str, ...]:
        """Channel names in recording order, e.g. ``('zdd', 'a1', ...)``."""
        out: list[str] = []
        for g in self.groups:
            if g in ("a", "q", "v"):
                out.extend(f"{g}{i + 1}" for i in range(storeys))
            else:
                out.append(g)
        return tuple(out)

    def to_dict(self) -> dict:
        """The settings as a JSON-ready dict, with each channel's faults, the groups and :attr:`ideal`."""
        out = asdict(self)
        out["faults"] = {name: f.to_dict() for name, f in self.faults}
        out["groups"] = list(self.groups)
        out["ideal"] = self.ideal
        return out


@dataclass(frozen=True)
class Scenario:
    """A validated scenario.  ``text`` is the file's own text (kept in recordings)."""

    name: str
    description: str
    duration: float
    sample_rate: float
    seed: int
    substeps: int
    structure: Structure
    excitation: Excitation
    runs: tuple[Run, ...]
    sensors: Sensors = field(default_factory=Sensors)
    tracking: Tracking | None = None
    truth: tuple[Mechanism, ...] = ()
    source: str = "<string>"
    text: str = ""

    @property
    def n_samples(self) -> int:
        """Samples per run, at ``t = k / sample_rate`` for k = 0..n-1."""
        return int(round(self.duration * self.sample_rate)) + 1

    @property
    def timestep(self) -> float:
        """Simulation step (s)."""
        return 1.0 / (self.sample_rate * self.substeps)

    def summary(self) -> dict:
        """A JSON-friendly description (what recordings store as metadata).

        Hidden physics (``[truth]``) and per-channel sensor faults are left
        out: a recording carries no trace of them.
        """
        exc = asdict(self.excitation)
        exc["type"] = type(self.excitation).__name__
        if "path" in exc:
            exc["path"] = str(exc["path"])
        return {
            "name": self.name,
            "description": self.description,
            "duration": self.duration,
            "sample_rate": self.sample_rate,
            "seed": self.seed,
            "substeps": self.substeps,
            "excitation": json.loads(json.dumps(exc, default=list)),
            "sensors": {k: v for k, v in self.sensors.to_dict().items() if k != "faults"},
            "tracking": asdict(self.tracking) if self.tracking else None,
        }


def default_scenario_path() -> Path:
    """Path of the embedded default scenario (``momentid run`` with no file).

    Returns
    -------
    Path
        ``default_scenario.toml`` inside the installed package.
    """
    return Path(str(resources.files("momentid.lab") / "default_scenario.toml"))


def load_scenario(path: str | os.PathLike, *, overrides: dict | None = None) -> Scenario:
    """Read and validate a scenario file, optionally with some keys replaced.

    Parameters
    ----------
    path : str or Path
        The TOML file.  Relative record paths inside it are resolved against
        the file's folder.
    overrides : dict, optional
        ``{"dotted.key": value}`` put into the parsed TOML before validation
        (see :func:`set_key`), e.g. ``{"scenario.duration": 2.0}``; the
        variant is validated as strictly as the file itself.

    Returns
    -------
    Scenario

    Raises
    ------
    ScenarioError
        On any invalid content; the message names file, key and value.
    """
    path = Path(path)
    data = load_toml(path)
    for key, value in (overrides or {}).items():
        set_key(data, key, value)
    text = path.read_text(encoding="utf-8")
    return parse_scenario(data, source=path, text=text)


#: Names that become file names (``out/<name>.mcap``) and recording topics: letters, digits,
#: ``_``, ``-`` and ``.``, starting with a letter or digit, so no name can leave its folder.
_SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,99}")


def _file_safe(tab: Table, key: str, default: str) -> str:
    value = tab.string(key, default)
    if not _SAFE_NAME.fullmatch(value):
        raise ScenarioError(f"{tab.file}: key {tab.key(key)!r} = {value!r}: expected a plain name (letters, "
                            f"digits, '_', '-', '.'; at most 100 characters, no '/' and no leading '.')")
    return value


def set_key(data: dict, key: str, value: Any) -> None:
    """Set the dotted ``key`` of parsed scenario TOML ``data`` in place.

    The one way momentid varies a scenario (sweeps, benchmarks, tests).
    Integer parts index arrays of tables (``runs.1.added_mass``, from 0); a
    table the data leave out is created (parsing then refuses unknown ones).

    Parameters
    ----------
    data : dict
        Parsed TOML, as :func:`momentid.io.toml_reader.load_toml` returns it.
    key : str
        Dotted key, e.g. ``"sensors.accelerometer.relative_noise"``.
    value
        Any TOML value (number, string, array, table as a dict).

    Raises
    ------
    ScenarioError
        When a part of ``key`` indexes past an array or into a plain value.
    """
    parts = key.split(".")
    node = data
    for depth, part in enumerate(parts):
        if isinstance(node, list):
            if not part.isdigit() or int(part) >= len(node):
                raise ScenarioError(f"'{'.'.join(parts[:depth])}' is an array of {len(node)} tables: "
                                    f"expected an index 0..{len(node) - 1} after it, got '{part}'")
            part = int(part)
        elif not isinstance(node, dict):
            raise ScenarioError(f"'{'.'.join(parts[:depth])}' = {node!r} is a value, not a table")
        if depth == len(parts) - 1:
            node[part] = value
        else:
            if isinstance(node, dict) and part not in node:
                node[part] = {}
            node = node[part]


def parse_scenario(data: dict, *, source: str | os.PathLike = "<string>", text: str = "") -> Scenario:
    """Validate already-parsed TOML ``data`` (see :func:`load_scenario`)."""
    source = Path(source) if not isinstance(source, Path) else source
    top = Table(data, source)
    meta = top.table("scenario")
    name = _file_safe(meta, "name", source.stem if source.suffix else "scenario")
    description = meta.string("description", "")
    duration = meta.number("duration", positive=True)
    sample_rate = meta.number("sample_rate", 1000.0, positive=True)
    seed = meta.integer("seed", 0, minimum=0)
    meta.finish()

    structure = _parse_structure(top.table("structure"))
    d = structure.storeys
    excitation, tracking = _parse_excitation(top.table("excitation"), source, seed)
    runs = []
    for i, tab in enumerate(top.tables("runs")):
        added = tab.numbers("added_mass", length=d, nonnegative=True, scalar_ok=True)
        check_added_mass(tab, added)
        runs.append(Run(name=_file_safe(tab, "name", f"run{i + 1}"), added_mass=added))
        tab.finish()
    names = [r.name for r in runs]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise ScenarioError(f"{source}: key 'runs.name' = {dup!r}: expected unique run names")

    sensors = _parse_sensors(top.table("sensors", {}), structure.storeys, sample_rate)
    truth = _parse_truth(top.table("truth", {}), structure.storeys)
    sim = top.table("simulation", {})
    substeps = sim.integer("substeps", 1, minimum=1)
    sim.finish()
    top.finish()

    if not math.isfinite(duration * sample_rate):
        raise ScenarioError(f"{source}: key 'scenario.duration' = {duration!r}: expected a duration whose "
                            f"sample count at sample_rate {sample_rate} Hz is a finite number")
    n = int(round(duration * sample_rate))
    if abs(n - duration * sample_rate) > 1e-6 * max(1.0, n):
        raise ScenarioError(
            f"{source}: key 'scenario.duration' = {duration!r}: expected a whole number of samples "
            f"at sample_rate {sample_rate} Hz"
        )
    return Scenario(
        name=name, description=description, duration=duration, sample_rate=sample_rate,
        seed=seed, substeps=substeps, structure=structure, excitation=excitation,
        runs=tuple(runs), sensors=sensors, tracking=tracking, truth=truth, source=str(source),
        text=text,
    )


def _parse_truth(tab: Table, storeys: int) -> tuple[Mechanism, ...]:
    if not tab.data:
        return ()
    out = []
    for m in tab.tables("mechanisms"):
        # the rig kinds of the mechanism registry, each with its parameters, units and bounds
        kind = mechanisms.get(m.string("type", choices=tuple(k.name for k in mechanisms.rig_kinds())))
        where = kind.target.key
        loc = (m.integers(where, length=2, minimum=1) if kind.target is mechanisms.Target.FLOORS
               else m.integer(where, minimum=1))
        problem = kind.place(loc).problem(storeys)
        if problem is not None:
            raise m.error(where, problem)
        params = []
        for p in kind.params:
            value = m.number(p.name)
            if not p.admits(value):
                raise m.error(p.name, p.expected())
            params.append((p.name, value))
        m.finish()
        out.append(Mechanism(kind.name, loc, tuple(params)))
    tab.finish()
    return tuple(out)


def public_text(text: str) -> str:
    """Scenario text without what a lab would not know: ``[truth]`` and per-channel sensor faults."""
    out, hidden = [], False
    for line in text.splitlines():
        head = line.strip()
        if head.startswith("["):
            name = head.strip("[] ").split("#")[0].strip("[] ")
            hidden = name == "truth" or name.startswith("truth.") or name.startswith("sensors.channel")
        if not hidden:
            out.append(line)
    return "\n".join(out) + "\n"


def _parse_instrument(tab: Table | None) -> Instrument:
    if tab is None:
        return Instrument()
    out = Instrument(**{k: tab.number(k, 0.0, nonnegative=True)
                        for k in ("noise", "noise_density", "relative_noise", "resolution", "range")},
                     bias=tab.number("bias", 0.0))
    tab.finish()
    return out


def _parse_sensors(sens: Table, storeys: int, sample_rate: float) -> Sensors:
    kind = sens.string("set", "all", choices=tuple(SENSOR_SETS))
    if kind == "all":
        groups = sens.strings("channels", SENSOR_SETS["all"])
    else:
        if sens.has("channels"):
            raise sens.error("channels", f"no 'channels' with set = {kind!r} (the set fixes them)")
        groups = SENSOR_SETS[kind]
    for g in groups:
        if g not in SENSOR_GROUPS:
            raise ScenarioError(
                f"{sens.file}: key 'sensors.channels' = {g!r}: expected one of {', '.join(SENSOR_GROUPS)}"
            )
    if len(set(groups)) != len(groups):
        raise ScenarioError(f"{sens.file}: key 'sensors.channels' = {list(groups)!r}: expected no repeats")
    rate = sens.number("sample_rate", None, positive=True)
    if rate is not None:
        ratio = sample_rate / rate
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise sens.error("sample_rate", f"a whole divisor of scenario.sample_rate ({sample_rate:g} Hz)")
        if round(ratio) == 1:
            rate = None
    antialias = sens.number("antialias", 0.0, nonnegative=True)
    nyquist = (rate or sample_rate) / 2
    if antialias >= nyquist:
        raise sens.error("antialias", f"a corner below the sensor Nyquist frequency ({nyquist:g} Hz), or 0")
    instruments = {k: _parse_instrument(sens.table(k, None))
                   for k in ("accelerometer", "displacement", "velocity")}
    faults = []
    ch_tab = sens.table("channel", {})
    names = Sensors(groups=SENSOR_SETS["all"]).channels(storeys)
    for name in list(ch_tab.data):
        if name not in names:
            raise ch_tab.error(name, f"a channel name ({', '.join(names)})")
        faults.append((name, _parse_channel_fault(ch_tab.table(name), name)))
    ch_tab.finish()
    sens.finish()
    return Sensors(groups=tuple(groups), set=kind, sample_rate=rate, antialias=antialias,
                   faults=tuple(faults), **instruments)


def _parse_channel_fault(tab: Table, channel: str) -> ChannelFault:
    """``[sensors.channel.X]``: each key the setting of a registered sensor-fault kind, within its bounds."""
    records = []
    for kind in mechanisms.sensor_settings().values():
        setting = kind.setting
        positive = setting.low == 0 and setting.low_open
        value = tab.number(setting.name, None, positive=positive, nonnegative=setting.low == 0 and not positive)
        if value is not None:
            if not setting.admits(value):
                raise tab.error(setting.name, setting.expected())
            records.append(kind.record(channel, value))
    tab.finish()
    return ChannelFault(tuple(records))


def _parse_structure(tab: Table) -> Structure:
    """The scenario's ``[structure]``: a full nominal model (:func:`momentid.io.structure_table.parse_structure`)
    within the plausible ranges of :mod:`momentid.io.plausible`."""
    structure = parse_structure(tab, require_model=True)
    check_structure(tab, structure)
    return structure


def _parse_excitation(tab: Table, source: Path, seed: int) -> tuple[Excitation, Tracking | None]:
    kind = tab.string("type", choices=("harmonic", "harmonics", "record", "noise", "chirp"))
    tracking = None
    if tab.has("tracking_error"):
        band = tab.numbers("tracking_band", (0.5, 20.0), length=2, positive=True)
        if not band[0] < band[1]:
            raise tab.error("tracking_band", "[low, high] in Hz with low < high")
        tracking = Tracking(error=tab.number("tracking_error", positive=True), band=(band[0], band[1]))
    if kind == "harmonic":
        amp = (tab.number("amplitude", positive=True),)
        omega = (_angular(tab, "angular_frequency", "frequency", plural=False),)
        phase = (tab.number("phase", 0.0),)
        exc: Excitation = Harmonics(amp, omega, phase)
    elif kind == "harmonics":
        amp = tab.numbers("amplitudes", positive=True)
        omega = _angular(tab, "angular_frequencies", "frequencies", plural=True, length=len(amp))
        phase = tab.numbers("phases", (0.0,) * len(amp), length=len(amp))
        exc = Harmonics(amp, omega, phase)
    elif kind == "record":
        raw = tab.string("file")
        tab.string("format", "at2", choices=("at2",))   # the one format: checked, nothing to keep
        path = Path(raw).expanduser()
        if not path.is_absolute():
            path = (source.parent / path) if source.suffix else path
        path = path.resolve()
        if not path.is_file():
            raise ScenarioError(
                f"{source}: key '{tab.key('file')}' = {raw!r}: record file not found (looked for {path})"
            )
        exc = RecordedMotion(
            path=path,
            scale=tab.number("scale", 1.0, positive=True),
            highpass=tab.number("highpass", 0.1, nonnegative=True),
            taper=tab.number("taper", 1.0, nonnegative=True),
        )
    elif kind == "chirp":
        exc = Chirp(amplitude=tab.number("amplitude", positive=True),
                    f_start=tab.number("f_start", positive=True), f_end=tab.number("f_end", positive=True),
                    sweep=tab.string("sweep", "linear", choices=("linear", "log")),
                    taper=tab.number("taper", 1.0, nonnegative=True))
    else:
        band = tab.numbers("band", length=2, positive=True)
        if not band[0] < band[1]:
            raise tab.error("band", "[low, high] in Hz with low < high")
        exc = BandLimitedNoise(
            rms=tab.number("rms", positive=True),
            band=(band[0], band[1]),
            seed=tab.integer("seed", seed, minimum=0),
            taper=tab.number("taper", 1.0, nonnegative=True),
        )
    check_excitation(tab, exc, tracking)
    tab.finish()
    return exc, tracking


def _angular(tab: Table, omega_key: str, hz_key: str, *, plural: bool, length: int | None = None):
    if tab.has(omega_key) == tab.has(hz_key):
        raise ScenarioError(
            f"{tab.file}: table '{tab.prefix}': expected exactly one of '{omega_key}' (rad/s) or '{hz_key}' (Hz)"
        )
    if plural:
        if tab.has(omega_key):
            return tab.numbers(omega_key, length=length, positive=True)
        return tuple(2 * np.pi * f for f in tab.numbers(hz_key, length=length, positive=True))
    if tab.has(omega_key):
        return tab.number(omega_key, positive=True)
    return 2 * np.pi * tab.number(hz_key, positive=True)
