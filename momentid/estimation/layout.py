"""Where each unknown of the added-mass estimators sits in ``theta``, and the memory their
equation form needs (refused before any work when it cannot fit).

``theta = [M entries, C entries (symmetric), K entries (symmetric), mu]``: see :class:`Layout`.
"""

from __future__ import annotations

import numpy as np

from momentid.errors import IdentificationError

__all__ = ["Layout", "equation_form_bytes", "require_equation_memory"]


class Layout:
    """Where each unknown sits in ``theta``.

    Parameters
    ----------
    d : int
        Storeys.
    mass : {"diagonal", "full"}
        Diagonal (d unknowns) or symmetric (d(d+1)/2) mass matrix.
    """

    def __init__(self, d: int, mass: str = "diagonal"):
        if mass not in ("diagonal", "full"):
            raise IdentificationError(f"mass = {mass!r}: expected 'diagonal' or 'full'")
        self.d = d
        self.mass = mass
        pairs = [(i, j) for i in range(d) for j in range(i, d)]
        sym = np.zeros((d, d), dtype=int)
        for n, (i, j) in enumerate(pairs):
            sym[i, j] = sym[j, i] = n
        if mass == "diagonal":
            self.m = np.diag(np.arange(d))
            self.m_columns = np.arange(d)
            start = d
        else:
            self.m = sym.copy()
            self.m_columns = np.arange(len(pairs))
            start = len(pairs)
        self.c = start + sym
        self.k = start + len(pairs) + sym
        self.mu = start + 2 * len(pairs)
        self.p = self.mu + 1

    def floor_columns(self, j: int) -> np.ndarray:
        """The unknowns that floor ``j``'s equation involves, in regressor order."""
        m = [self.m[j, j]] if self.mass == "diagonal" else list(self.m[j])
        return np.concatenate([m, self.c[j], self.k[j], [self.mu]])

    def unpack(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """``(M, C, K, mu)`` from ``theta``."""
        if self.mass == "diagonal":
            M = np.diag(theta[np.diag(self.m)])
        else:
            M = theta[self.m]
        return M, theta[self.c], theta[self.k], float(theta[self.mu])

    def pack(self, M: np.ndarray, C: np.ndarray, K: np.ndarray, mu: float) -> np.ndarray:
        """``theta`` (p,) from ``M``, ``C``, ``K`` (d, d) and ``mu``: the inverse of :meth:`unpack`."""
        theta = np.zeros(self.p)
        for (idx, X) in ((self.m, M), (self.c, C), (self.k, K)):
            if X is M and self.mass == "diagonal":
                theta[np.diag(idx)] = np.diag(X)
            else:
                theta[idx] = X
        theta[self.mu] = mu
        return theta


#: Float arrays of ``p x p`` (``p`` unknowns) the equation form's solve holds at its peak: the
#: triangular factor, its column-scaled copy, the SVD's workspace, its inverse, and the covariance.
_SQUARE_ARRAYS = 6


def equation_form_bytes(layout: Layout) -> float:
    """Peak memory (bytes) of the equation form's solve for ``layout``, however long the record.

    The per-floor triangular factors are stacked (``d (s + 1)`` rows of ``p + 1`` columns, ``s`` the
    unknowns one floor's equation involves), factored again (a second copy) and then inverted and
    decomposed (:data:`_SQUARE_ARRAYS` square arrays of ``p x p``).  It grows as ``d^4``: 16 unknowns
    for 3 storeys, 40,401 (and tens of GB) for 200.
    """
    p = layout.p
    rows = sum(len(layout.floor_columns(j)) + 1 for j in range(layout.d))
    return 8.0 * (2.0 * rows * (p + 1) + _SQUARE_ARRAYS * p * p)


def require_equation_memory(layout: Layout, source: object) -> None:
    """Refuse, before any work, an identification whose equation form cannot fit in memory (``source``: the
    recording, named in the message).

    Raises
    ------
    ResourceError
        Naming the storeys, the unknowns, the estimate and the largest number of storeys that fits.
    """
    from momentid.core.resources import MEMORY_SHARE, available_memory, require_memory

    needed = equation_form_bytes(layout)
    fits = layout.d
    while fits > 1 and equation_form_bytes(Layout(fits, layout.mass)) > available_memory() * MEMORY_SHARE:
        fits = max(1, int(fits * 0.9))
    require_memory(needed, f"{source}: identification of {layout.d} storeys ({layout.p} unknowns, "
                   f"{layout.mass} mass matrix)",
                   f"its memory grows as the storeys^4: about {fits} storeys fit on this machine; "
                   f"identify a substructure (fewer floors) or a condensed model")


