"""The DFT bins of one run that the errors-in-variables fits use (:func:`momentid.estimation.eiv.spectra`
makes them; :mod:`~momentid.estimation.eiv`, :mod:`~momentid.estimation.eiv_jacobian` and the modal fit read them)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Spectra"]


@dataclass(frozen=True)
class Spectra:
    """The DFT bins of one run that the fit uses.

    Attributes
    ----------
    run : str
    added_mass : ndarray, shape (d,)
    h : float
        Sample interval (s).
    groups : list of str
        Output groups, e.g. ``['a', 'q']``.
    z : ndarray, shape (m,)
        ``exp(2 pi i k / N)`` of the bins used.
    U : ndarray, shape (m,)
        Table acceleration DFT (normalised by sqrt(N)).
    Y : ndarray, shape (m, n_out)
        Output DFTs.
    sigma_u : float
        Input noise RMS (m/s^2) per normalised bin.
    sigma_y : ndarray, shape (n_out,)
        Output noise RMS per channel.
    """

    run: str
    added_mass: np.ndarray
    h: float
    groups: list
    z: np.ndarray
    U: np.ndarray
    Y: np.ndarray
    sigma_u: float
    sigma_y: np.ndarray
    freq: np.ndarray
    forces: np.ndarray | None = None     # (d, m) floor directions of extra force signals
    F: np.ndarray | None = None          # (bins, m) DFTs of the extra force signals
    noise_source: str = ""               # where sigma_u, sigma_y came from (see momentid.estimation.noise)
