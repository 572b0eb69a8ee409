"""Where a mechanism acts: a storey, a floor, a floor against the table, two floors, or a sensor channel.

A mechanism kind declares its :class:`Target`; one mechanism sits at one :class:`Place` of it.  The
rest of the project asks the place, never the target's name, what it needs:

- a **link** (a storey, a floor against the table, two floors) is a force element between two
  nodes of the rig, ``lower`` and ``upper`` (0 is the table, ``j`` floor ``j``): it stretches by
  ``x = q_upper - q_lower`` (floor displacements relative to the table, ``q_0 = 0``) and a force
  ``f`` resisting the stretch puts ``f w`` into the floor forces, ``w`` (:meth:`Place.direction`)
  being ``-1`` on the upper floor and ``+1`` on the lower one (when it is a floor);
- a **floor** place is floor ``j`` itself (what is bolted to it): a force there is ``f`` on floor ``j``;
- a **channel** place is one recorded channel (``zdd``, ``a3``, ``q2``).

A place's :attr:`Place.location` (``{"storey": 2}``, ``{"floor": 3}``, ``{"floors": [1, 3]}``,
``{"channel": "a2"}``) is how scenarios' ``[truth]`` tables and reports name it.
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass

import numpy as np

__all__ = ["Target", "Place", "location_words"]


class Target(enum.Enum):
    """What kind of place a mechanism sits on (see the module docstring)."""

    STOREY = "storey"              # across storey i: floor i against floor i-1 (storey 1: against the table)
    FLOOR = "floor"                # on floor j itself (its added mass, its attachment)
    FLOOR_TABLE = "floor_table"    # between floor j and the table
    FLOORS = "floors"              # between floors i < j, more than a storey apart (a brace over storeys)
    CHANNEL = "channel"            # on one sensor channel

    @property
    def key(self) -> str:
        """The key of a place of this target in a ``[truth]`` record and a report's location."""
        return "floor" if self is Target.FLOOR_TABLE else self.value

    @property
    def link(self) -> bool:
        """A force element between two nodes of the rig (a storey, a floor against the table, two floors)."""
        return self in (Target.STOREY, Target.FLOOR_TABLE, Target.FLOORS)

    def places(self, storeys: int) -> tuple[Place, ...]:
        """Every place of this target in a rig of ``storeys`` storeys, lowest first.

        Two floors are taken more than a storey apart (adjacent floors are a storey); channels are
        the table accelerometer's and each floor's accelerometer and displacement transducer.
        """
        d = storeys
        if self is Target.FLOORS:
            return tuple(Place(self, (i, j)) for j in range(3, d + 1) for i in range(1, j - 1))
        if self is Target.CHANNEL:
            return tuple(Place(self, c) for c in ("zdd", *(f"a{j}" for j in range(1, d + 1)),
                                                  *(f"q{j}" for j in range(1, d + 1))))
        return tuple(Place(self, j) for j in range(1, d + 1))


@dataclass(frozen=True)
class Place:
    """One place of a :class:`Target`.

    Attributes
    ----------
    target : Target
    index : int, (int, int) or str
        The storey or floor number (1 = lowest), the two floors ``(lower, upper)`` of
        ``Target.FLOORS``, or the channel name of ``Target.CHANNEL``.
    """

    target: Target
    index: int | tuple[int, int] | str

    @classmethod
    def at(cls, target: Target, location: dict) -> Place:
        """The place of ``target`` a report's ``location`` names (:attr:`location` read back)."""
        value = location[target.key]
        return cls(target, tuple(value) if isinstance(value, (list, tuple)) else value)

    # ---------------------------------------------------------------- naming

    @property
    def location(self) -> dict:
        """``{key: index}`` (``floors``: a list of two)."""
        return {self.target.key: list(self.index) if isinstance(self.index, tuple) else self.index}

    @property
    def words(self) -> str:
        """The place in words: ``storey 2``, ``floor 3``, ``floor 3 against the table``, ``floors 1 and 3``,
        ``channel a2``."""
        if self.target is Target.FLOOR_TABLE:
            return f"floor {self.index} against the table"
        if self.target is Target.FLOORS:
            return f"floors {self.index[0]} and {self.index[1]}"
        return f"{self.target.key} {self.index}"

    @property
    def level(self) -> int:
        """The floor the place belongs to (its upper floor; a channel's floor, 0 for the table's):
        the order in which the diagnosis visits places."""
        if self.target is Target.CHANNEL:
            digits = re.sub(r"\D", "", str(self.index))
            return int(digits) if digits else 0
        return self.nodes[1] if self.target.link else int(self.index)

    def problem(self, storeys: int) -> str | None:
        """What is wrong with this place in a rig of ``storeys`` storeys (None: nothing)."""
        d, i = storeys, self.index
        if self.target is Target.CHANNEL:
            return None if isinstance(i, str) and i else "a channel name"
        if self.target is Target.FLOORS:
            ok = (isinstance(i, tuple) and len(i) == 2 and all(isinstance(k, int) for k in i)
                  and 1 <= i[0] < i[1] <= d)
            return None if ok else f"two floor numbers i < j in 1..{d}"
        if isinstance(i, bool) or not isinstance(i, int) or not 1 <= i <= d:
            return f"a {self.target.key} number in 1..{d}"
        return None

    # ---------------------------------------------------------------- a link's geometry

    @property
    def nodes(self) -> tuple[int, int]:
        """A link's ``(lower, upper)`` nodes (0: the table, ``j``: floor ``j``)."""
        if self.target is Target.STOREY:
            return self.index - 1, self.index
        if self.target is Target.FLOOR_TABLE:
            return 0, self.index
        if self.target is Target.FLOORS:
            return self.index
        raise ValueError(f"{self.words} is not a link between two nodes of the rig")

    def direction(self, storeys: int) -> np.ndarray:
        """Floor forces (d,) of a unit force resisting the link's stretch (``-1`` on its upper floor,
        ``+1`` on its lower one); a floor place: ``+1`` on its floor."""
        w = np.zeros(storeys)
        if self.target is Target.FLOOR:
            w[self.index - 1] = 1.0
            return w
        lower, upper = self.nodes
        w[upper - 1] = -1.0
        if lower > 0:
            w[lower - 1] = 1.0
        return w

    def stretch(self, x: np.ndarray) -> np.ndarray:
        """The link's stretch (n,) from floor signals (n, d) relative to the table (``q``, ``v``); a floor
        place: its floor's signal."""
        if self.target is Target.FLOOR:
            return x[:, self.index - 1]
        lower, upper = self.nodes
        return x[:, upper - 1] - x[:, lower - 1] if lower > 0 else x[:, upper - 1]

    def columns(self, phi: np.ndarray, storeys: int) -> np.ndarray:
        """Floor forces (n, d) of a force ``phi`` (n,) at this place (resisting a link's stretch)."""
        return np.outer(phi, self.direction(storeys))

    def force(self, floor_forces: np.ndarray) -> np.ndarray:
        """The least-squares force (n,) at this place behind floor forces (n, d)."""
        w = self.direction(floor_forces.shape[1])
        return floor_forces @ w / float(w @ w)

    def above(self, added_mass: np.ndarray) -> np.ndarray | float:
        """Added mass (kg) carried by the link: on its upper floor and every floor above it; from a
        run's added masses (d,) or each sample's (n, d)."""
        upper = self.nodes[1] if self.target.link else self.index
        return np.asarray(added_mass)[..., upper - 1:].sum(axis=-1)


def _range(values, unit: str) -> str:
    lo, hi = values
    return f"{lo:.3g}-{hi:.3g} {unit}"


def location_words(location: dict) -> str:
    """A report's ``location`` in words, never as JSON: its own ``words`` when it has them, else a
    :class:`Place`'s (``storey 2``, ``floors 1 and 3``), else each key it holds said in words (a
    sensor, a mode's band and its share of the misfit power, a time window).

    Parameters
    ----------
    location : dict

    Returns
    -------
    str
    """
    if not location:
        return "no particular place"
    if isinstance(location.get("words"), str):
        return location["words"]
    for target in Target:
        if target.key in location and target is not Target.FLOOR_TABLE:
            try:
                return Place.at(target, location).words
            except (TypeError, ValueError):
                break
    parts = []
    sensor = str(location.get("sensor", ""))
    if sensor:
        floor = re.fullmatch(r"a(\d+)", sensor)
        parts.append(f"the floor-{floor.group(1)} sensor" if floor else f"sensor {sensor}")
    if "mode" in location:
        inside = [_range(location["band_hz"], "Hz")] if "band_hz" in location else []
        if "band_share" in location:
            inside.append(f"{100 * location['band_share']:.0f} % of its misfit power")
        parts.append(f"mode-{location['mode']} band" + (f" ({', '.join(inside)})" if inside else ""))
    if "worst_window_s" in location:
        parts.append(f"worst in {_range(location['worst_window_s'], 's')}")
    known = {"sensor", "mode", "band_hz", "band_share", "worst_window_s", "worst_window_nrmse", "words"}
    parts += [f"{key.replace('_', ' ')} {value}" for key, value in location.items() if key not in known]
    return ", ".join(parts)
