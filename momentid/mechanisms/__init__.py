"""Mechanisms: the physics beyond the linear shear model, one module per kind.

Each module declares a :class:`~momentid.mechanisms.base.MechanismKind` (parameters and bounds,
MuJoCo or sensor effect, screening signature, refit, report wording) and registers it;
:mod:`~momentid.mechanisms.registry` finds them all.  The lab builds truth rigs with them, the
diagnosis screens with them.  See ``docs/mechanisms.md``.
"""

import sys

from momentid.mechanisms.base import GRAVITY, MechanismKind, Param, Refit
from momentid.mechanisms.place import Place, Target
from momentid.mechanisms.registry import (REGISTRY, get, library, load, names, open_search_kind, register, rig_kinds,
                                          sensor_settings, validate)

load(sys.modules[__name__])

__all__ = ["GRAVITY", "MechanismKind", "Param", "Place", "Refit", "Target", "REGISTRY", "get", "library", "load",
           "names", "open_search_kind", "register", "rig_kinds", "sensor_settings", "validate"]
