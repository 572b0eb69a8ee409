"""The one parser of a ``[structure]`` table (scenario files and ``experiment.toml``).

A full nominal model (``masses``, ``storey_stiffness`` and damping, either as
``rayleigh_mu``/``rayleigh_kappa`` or as a ``[structure.damping]`` table with
``damping_ratios`` of two ``modes`` or ``rayleigh_mu``/``rayleigh_kappa``)
gives a :class:`~momentid.core.structure.Structure`.  A scenario needs one.
An import may state less, as a real lab usually does: ``storeys`` and/or
``masses`` (and ``storey_height``) give a
:class:`~momentid.core.structure.LabStatement`.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from momentid.core import analytic
from momentid.core.resources import require_memory
from momentid.core.structure import LabStatement, Structure
from momentid.errors import ScenarioError
from momentid.io.toml_reader import Table
from momentid.io.plausible import MASS_RANGE  # one range for scenarios, imports and recordings

__all__ = ["parse_structure", "implausible_mass", "DEFAULT_STOREY_HEIGHT", "DEFAULT_BASE_MASS", "MASS_RANGE",
           "MODEL_BYTES_PER_STOREY2"]

#: Storey height (m) of a nominal model that states none (it only scales drawings).
DEFAULT_STOREY_HEIGHT = 0.3
#: Shake-table platen mass (kg) of a nominal model that states none (the base motion is prescribed).
DEFAULT_BASE_MASS = 100.0
#: Keys that only a full nominal model has.
MODEL_KEYS = ("storey_stiffness", "rayleigh_mu", "rayleigh_kappa", "damping", "base_mass")
#: Memory (bytes) a model needs per storey squared: its d x d mass, damping and stiffness matrices
#: and their copies in identification (8 of them at 8 bytes); checked before anything of size d is
#: allocated, so ``storeys = 1000000000`` is refused in one line.
MODEL_BYTES_PER_STOREY2 = 64.0


def implausible_mass(masses: Iterable[float]) -> int | None:
    """Index of the first mass (kg) outside :data:`MASS_RANGE` (or not finite), None when all are plausible."""
    for i, m in enumerate(masses):
        if not MASS_RANGE[0] <= m <= MASS_RANGE[1]:  # nan fails too
            return i
    return None


def _storeys(tab: Table) -> tuple[int, tuple[float, ...] | None]:
    masses = tab.numbers("masses", positive=True) if tab.has("masses") else None
    if masses is None and not tab.has("storeys"):
        raise ScenarioError(f"{tab.file}: missing key '{tab.key('masses')}' (or '{tab.key('storeys')}'); "
                            f"expected the floor masses in kg, floor 1 first, or the number of storeys")
    if masses is not None:
        bad = implausible_mass(masses)
        if bad is not None:
            raise ScenarioError(f"{tab.file}: key '{tab.key('masses')}[{bad}]' = {masses[bad]!r}: expected a floor "
                                f"mass between {MASS_RANGE[0]:g} and {MASS_RANGE[1]:g} kg")
    d = len(masses) if masses is not None else tab.integer("storeys", minimum=1)
    if tab.has("storeys") and tab.integer("storeys", minimum=1) != d:
        raise tab.error("storeys", f"the number of entries in 'masses' ({d})")
    require_memory(MODEL_BYTES_PER_STOREY2 * float(d) ** 2, f"{tab.file}: a model of {tab.key('storeys')} = {d}",
                   "state the number of storeys of the rig (one per floor sensor)")
    return d, masses


def _damping(tab: Table, masses: tuple[float, ...], stiffness: tuple[float, ...],
             flat_default: bool) -> tuple[float, float]:
    """``(mu, kappa)`` from flat keys or from the ``damping`` table (``flat_default``: which one is
    asked for when neither is there)."""
    flat = tab.has("rayleigh_mu") or tab.has("rayleigh_kappa")
    if flat and tab.has("damping"):
        raise tab.error("damping", "either rayleigh_mu/rayleigh_kappa in [structure] or a [structure.damping] "
                                   "table, not both")
    if flat or (flat_default and not tab.has("damping")):
        return tab.number("rayleigh_mu", nonnegative=True), tab.number("rayleigh_kappa", nonnegative=True)
    damp = tab.table("damping")
    if damp.has("damping_ratios"):
        if damp.has("rayleigh_mu") or damp.has("rayleigh_kappa"):
            raise damp.error("damping_ratios", "either damping_ratios or rayleigh_mu/rayleigh_kappa, not both")
        if len(masses) < 2:
            raise damp.error("damping_ratios", "rayleigh_mu/rayleigh_kappa (one storey has only one mode)")
        ratios = damp.numbers("damping_ratios", length=2, nonnegative=True)
        modes = damp.integers("modes", (1, 2), length=2)
        M, K = np.diag(masses), analytic.shear_stiffness(stiffness)
        mu, kappa = analytic.rayleigh_coefficients(M, K, ratios, tuple(modes), file=tab.file, key=damp.prefix)
        if mu < 0 or kappa < 0:
            raise damp.error("damping_ratios", f"ratios that give non-negative Rayleigh coefficients "
                                               f"(got mu={mu:.4g}, kappa={kappa:.4g})")
    else:
        mu = damp.number("rayleigh_mu", nonnegative=True)
        kappa = damp.number("rayleigh_kappa", nonnegative=True)
    damp.finish()
    return mu, kappa


def parse_structure(tab: Table, *, require_model: bool) -> Structure | LabStatement:
    """Parse a ``[structure]`` table.

    Parameters
    ----------
    tab : Table
        The table (its file and key path name every error).
    require_model : bool
        True for a scenario (a full nominal model or an error); False for an
        import, where ``storeys`` or ``masses`` alone is a lab statement.

    Returns
    -------
    Structure or LabStatement
        ``Structure`` when stiffness and damping are stated (masses then
        required), else ``LabStatement(storeys, masses or None,
        storey_heights or None)``.

    Raises
    ------
    ScenarioError
        Naming the file, the key and the value.
    """
    d, masses = _storeys(tab)
    heights = (tab.numbers("storey_height", length=d, positive=True, scalar_ok=True)
               if tab.has("storey_height") else None)
    stated = [k for k in MODEL_KEYS if tab.has(k)]
    if not require_model and not stated:
        tab.finish()
        return LabStatement(storeys=d, masses=masses, storey_heights=heights)
    if masses is None:
        raise ScenarioError(f"{tab.file}: missing key '{tab.key('masses')}'; expected the floor masses (kg) "
                            f"of the nominal model that '{tab.key(stated[0])}' belongs to")
    stiffness = tab.numbers("storey_stiffness", length=d, positive=True, scalar_ok=True)
    mu, kappa = _damping(tab, masses, stiffness, flat_default=not require_model)
    base_mass = tab.number("base_mass", DEFAULT_BASE_MASS, positive=True)
    tab.finish()
    return Structure(masses=masses, storey_stiffness=stiffness,
                     storey_heights=heights or (DEFAULT_STOREY_HEIGHT,) * d,
                     rayleigh_mu=mu, rayleigh_kappa=kappa, base_mass=base_mass)
