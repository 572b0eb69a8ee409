"""The registry of mechanism kinds: every module of :mod:`momentid.mechanisms` declares its own.

A kind registers itself with the :func:`register` class decorator when its module is imported;
:func:`load` imports every module of the package (``pkgutil.iter_modules``), so adding a
mechanism is one new file in ``momentid/mechanisms/`` and nothing else.  See ``docs/mechanisms.md``.
"""

from __future__ import annotations

import importlib
import pkgutil
from types import ModuleType

from momentid.core.structure import Mechanism
from momentid.errors import ModelError
from momentid.mechanisms.base import MechanismKind
from momentid.mechanisms.place import Target

__all__ = ["REGISTRY", "register", "load", "get", "names", "library", "real_rig_kinds", "rig_kinds", "open_search_kind",
           "validate", "sensor_settings"]

#: name -> kind, in the order the package's modules are imported (alphabetical).
REGISTRY: dict[str, MechanismKind] = {}

#: Modules of the package that declare no kind.
_INFRASTRUCTURE = {"base", "place", "registry", "sizing"}


def register(cls: type[MechanismKind]) -> type[MechanismKind]:
    """Class decorator: put one instance of ``cls`` in :data:`REGISTRY` under ``cls.name``."""
    if not isinstance(getattr(cls, "name", None), str) or not isinstance(getattr(cls, "target", None), Target):
        raise ModelError(f"{cls.__qualname__}: a mechanism kind needs a str `name` and a Target `target`")
    known = REGISTRY.get(cls.name)
    if known is not None and type(known).__qualname__ != cls.__qualname__:
        raise ModelError(f"mechanism {cls.name!r} registered twice ({type(known).__module__} and {cls.__module__})")
    REGISTRY[cls.name] = cls.registered = cls()
    return cls


def load(package: ModuleType) -> dict[str, MechanismKind]:
    """Import every module of ``package`` (:mod:`momentid.mechanisms` loads itself) so its kinds register."""
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if info.name not in _INFRASTRUCTURE and not info.name.startswith("_"):
            importlib.import_module(f"{package.__name__}.{info.name}")
    return REGISTRY


def get(name: str) -> MechanismKind:
    """The kind called ``name``; :class:`ModelError` naming the known ones otherwise."""
    try:
        return REGISTRY[name]
    except KeyError:
        raise ModelError(f"unknown mechanism {name!r}: expected one of {', '.join(REGISTRY)}") from None


def names() -> tuple[str, ...]:
    """Every registered kind's name."""
    return tuple(REGISTRY)


def library() -> tuple[MechanismKind, ...]:
    """The kinds the diagnosis can name (every kind but the truth-only ones)."""
    return tuple(k for k in REGISTRY.values() if not k.truth_only)


def real_rig_kinds() -> tuple[MechanismKind, ...]:
    """The kinds the accelerometer-only diagnosis fits on a real rig's twin (``real_rig``)."""
    return tuple(k for k in REGISTRY.values() if k.real_rig)


def rig_kinds() -> tuple[MechanismKind, ...]:
    """The kinds a rig's model can carry (a scenario's ``[truth]``): every kind but the sensor faults."""
    return tuple(k for k in REGISTRY.values() if k.target is not Target.CHANNEL)


def sensor_settings() -> dict[str, MechanismKind]:
    """The sensor-fault kinds by the key that states each in a scenario's ``[sensors.channel.X]``."""
    return {k.setting.name: k for k in REGISTRY.values() if k.target is Target.CHANNEL and hasattr(k, "setting")}


def open_search_kind(target: Target) -> MechanismKind:
    """The kind whose records hold the open search's law at places of ``target``."""
    for kind in REGISTRY.values():
        if kind.open_search and kind.target is target:
            return kind
    raise ModelError(f"no open-search kind registered for the target {target.value!r}")


def validate(mech: Mechanism, storeys: int) -> None:
    """Raise :class:`ModelError` unless ``mech`` is a valid record of a registered rig kind."""
    get(mech.type).validate(mech, storeys)
