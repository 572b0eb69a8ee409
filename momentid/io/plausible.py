"""Plausible ranges of a scenario's physical values, checked when the file is read.

A finite but absurd value (``masses = [1e308, ...]``) passes a type check and then overflows deep
inside the simulation (a mass matrix of inf, an eigen-solver's traceback).  Each range below spans
every shake-table rig with orders of magnitude to spare, so it refuses only typing slips and
overflow bait, never a real rig; the message names the file, the key, the value and the range.
"""

from __future__ import annotations

from collections.abc import Sequence
import math
from typing import Any

from momentid.core.structure import Structure
from momentid.errors import ScenarioError
from momentid.io.toml_reader import Table

__all__ = ["MASS_RANGE", "FREQUENCY_RANGE", "STIFFNESS_RANGE", "HEIGHT_RANGE", "MAX_DAMPING_RATIO",
           "MAX_STROKE", "MAX_ACCELERATION", "MAX_SCALE", "implausible", "check_structure", "check_added_mass",
           "check_excitation"]

#: Floor masses (kg): a gram-scale desk model to ten times the heaviest payload a shake table
#: carries (E-Defense: 1.2e6 kg).
MASS_RANGE = (1e-3, 1e7)
#: Natural frequencies (Hz) of a shear building: below the sway of the tallest towers (about
#: 0.1 Hz) to above any storey mode a table excites.
FREQUENCY_RANGE = (1e-2, 1e3)
#: Storey stiffnesses (N/m): the lightest floor at the lowest frequency to the heaviest at the
#: highest (k = m (2 pi f)^2).
STIFFNESS_RANGE = (MASS_RANGE[0] * (2 * math.pi * FREQUENCY_RANGE[0]) ** 2,
                   MASS_RANGE[1] * (2 * math.pi * FREQUENCY_RANGE[1]) ** 2)
#: Storey heights (m): a millimetre model to a kilometre tower.
HEIGHT_RANGE = (1e-3, 1e3)
#: Rayleigh damping giving more than this ratio of critical at every frequency of FREQUENCY_RANGE
#: (mu = 2 zeta omega, kappa = 2 zeta / omega) is no structure (1 % to 5 % is usual).
MAX_DAMPING_RATIO = 10.0
#: Table displacement amplitude (m): ten times the largest stroke of a shake table (+-1 m).
MAX_STROKE = 10.0
#: Table acceleration RMS (m/s^2): about 100 g, twenty times what the strongest tables reach.
MAX_ACCELERATION = 1e3
#: Factor on a recorded accelerogram, and run-to-run tracking error relative to the motion: a
#: hundred times the record, or an error a hundred times the motion, is a slip.
MAX_SCALE = 100.0


def _refuse(tab: Table, key: str, value: float, what: str, low: float, high: float, unit: str) -> ScenarioError:
    return ScenarioError(f"{tab.file}: key '{key}' = {value!r}: expected {what} between {low:.3g} and {high:.3g} "
                         f"{unit} (no shake-table rig is outside that)")


def _each(tab: Table, name: str, values, what: str, span: tuple[float, float], unit: str) -> None:
    for i, value in enumerate(values):
        if not span[0] <= value <= span[1]:
            key = tab.key(name) + (f"[{i}]" if isinstance(tab.data.get(name), list) else "")
            raise _refuse(tab, key, value, what, *span, unit)


def _structure_ranges(structure: Structure) -> list[tuple[str, tuple, str, tuple[float, float], str]]:
    """(key, values, what, range, unit) of every value of ``structure`` the ranges bound."""
    mu_max = 2 * MAX_DAMPING_RATIO * 2 * math.pi * FREQUENCY_RANGE[1]
    kappa_max = 2 * MAX_DAMPING_RATIO / (2 * math.pi * FREQUENCY_RANGE[0])
    damping = f"at most {MAX_DAMPING_RATIO:g} x critical damping over {FREQUENCY_RANGE[0]:g}-{FREQUENCY_RANGE[1]:g} Hz"
    return [("masses", structure.masses, "a floor mass", MASS_RANGE, "kg"),
            ("storey_stiffness", structure.storey_stiffness, "a storey stiffness", STIFFNESS_RANGE, "N/m"),
            ("storey_height", structure.storey_heights, "a storey height", HEIGHT_RANGE, "m"),
            ("base_mass", (structure.base_mass,), "a table platen mass", MASS_RANGE, "kg"),
            ("rayleigh_mu", (structure.rayleigh_mu,), f"Rayleigh mu ({damping})", (0.0, mu_max), "1/s"),
            ("rayleigh_kappa", (structure.rayleigh_kappa,), f"Rayleigh kappa ({damping})", (0.0, kappa_max), "s")]


def implausible(structure: Structure) -> str | None:
    """The first value of ``structure`` outside its range, in words (None when all are within)."""
    for key, values, what, span, unit in _structure_ranges(structure):
        for value in values:
            if not span[0] <= value <= span[1]:
                return f"{key} = {value!r}: expected {what} between {span[0]:.3g} and {span[1]:.3g} {unit}"
    return None


def check_structure(tab: Table, structure: Structure) -> None:
    """Refuse a ``[structure]`` whose masses, stiffnesses, heights or damping lie outside the ranges."""
    damping = tab.table("damping") if isinstance(tab.data.get("damping"), dict) else tab
    for key, values, what, span, unit in _structure_ranges(structure):
        where = damping if key.startswith("rayleigh") and damping.has(key) else tab
        if where.has(key):
            _each(where, key, values, what, span, unit)
        elif key.startswith("rayleigh") and damping.has("damping_ratios"):   # computed from the ratios
            _each(damping, "damping_ratios", values, what, span, unit)


def check_excitation(tab: Table, excitation: Any, tracking: Any) -> None:
    """Refuse an ``[excitation]`` whose amplitude, frequencies or scale lie outside the ranges
    (``excitation``: Harmonics, BandLimitedNoise, RecordedMotion or Chirp of :mod:`momentid.lab.motions`;
    ``tracking``: its Tracking, or None)."""
    band = (0.0, FREQUENCY_RANGE[1])
    if hasattr(excitation, "amplitudes"):   # harmonics, given in rad/s or in Hz
        name = "amplitude" if tab.has("amplitude") else "amplitudes"
        _each(tab, name, excitation.amplitudes, "a table displacement amplitude", (0.0, MAX_STROKE), "m")
        name = next(n for n in ("angular_frequency", "angular_frequencies", "frequency", "frequencies") if tab.has(n))
        if name.startswith("angular"):
            _each(tab, name, excitation.angular_frequencies, "an angular frequency",
                  (0.0, 2 * math.pi * band[1]), "rad/s")
        else:   # as written (2 pi x 1e308 Hz is already inf)
            given = tab.data[name]
            _each(tab, name, given if isinstance(given, list) else (given,), "a frequency", band, "Hz")
    if hasattr(excitation, "rms"):          # band-limited noise
        _each(tab, "rms", (excitation.rms,), "a table acceleration RMS", (0.0, MAX_ACCELERATION), "m/s^2")
        _each(tab, "band", excitation.band, "a band edge", band, "Hz")
    if hasattr(excitation, "scale"):        # a record
        _each(tab, "scale", (excitation.scale,), "a record scale", (0.0, MAX_SCALE), "")
    if hasattr(excitation, "sweep"):        # a chirp
        _each(tab, "amplitude", (excitation.amplitude,), "a table acceleration amplitude", (0.0, MAX_ACCELERATION),
              "m/s^2")
        for name in ("f_start", "f_end"):
            _each(tab, name, (getattr(excitation, name),), "a frequency", band, "Hz")
    if tracking is not None:
        _each(tab, "tracking_error", (tracking.error,), "a tracking error (share of the motion)", (0.0, MAX_SCALE), "")
        _each(tab, "tracking_band", tracking.band, "a band edge", band, "Hz")


def check_added_mass(tab: Table, added: Sequence[float]) -> None:
    """Refuse a run's added mass above the heaviest floor mass of :data:`MASS_RANGE`."""
    _each(tab, "added_mass", added, "an added mass", (0.0, MASS_RANGE[1]), "kg")
