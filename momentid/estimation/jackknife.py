"""A delete-a-block jackknife of the whole record's linear modal fit: its damping ratios' error from the data.

The linear fit's own standard error counts white sensor noise only.  The forced windows
(:mod:`momentid.estimation.windows`) measure what independent stretches scatter beyond it, but each window
is short: for a lightly damped mode their mean is far less certain than the whole record's fit, and the
windows refuse what the record determines.  Here the whole record is refitted :data:`BLOCKS` times, each
time without one of :data:`BLOCKS` consecutive blocks of equal shaking (a quiet lead-in is in every refit;
the stretches before and after the gap become runs of their own, each with its own transient; the
record's sensor gains and clock offsets held); the spread of those refits is the jackknife's variance of
the whole record's damping ratios (Efron's delete-a-group jackknife), model error and the record's
non-stationarity included.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from momentid.core.series import RunData
from momentid.errors import MomentidError
from momentid.estimation.eiv import spectra
from momentid.estimation.modal import refine
from momentid.estimation.noise import quiet_lead_in
from momentid.estimation.windows import refit_bounds

if TYPE_CHECKING:
    from momentid.estimation.modal_select import ModeSelection

__all__ = ["Jackknife", "block_jackknife", "block_edges", "BLOCKS", "MIN_PIECE_CYCLES"]

#: Blocks the record is cut into (each refit leaves one out): the jackknife's error then has BLOCKS - 1
#: degrees of freedom.
BLOCKS = 8
#: A stretch left beside a gap shorter than this many cycles of the lowest storey mode is dropped (too
#: short to hold anything but its own transient).
MIN_PIECE_CYCLES = 2.0


@dataclass(frozen=True)
class Jackknife:
    """The whole record's damping ratios with their delete-a-block jackknife errors (:func:`block_jackknife`).

    Attributes
    ----------
    damping_ratio_std : ndarray, shape (n,)
        Per model mode, the jackknife standard error of the whole record's damping ratio (1).
    refits : ndarray, shape (k, n)
        Per refit (one block left out), every mode's damping ratio.
    dof : int
        ``k - 1``: the degrees of freedom of the error.
    """

    damping_ratio_std: np.ndarray
    refits: np.ndarray
    dof: int


def block_jackknife(runs: Sequence[RunData], selection: ModeSelection, sigma: Sequence[dict],
                    blocks: int = BLOCKS) -> Jackknife | None:
    """The whole record's linear modal fit refitted without each of ``blocks`` consecutive blocks.

    Parameters
    ----------
    runs : sequence of RunData
        The runs of ``selection`` (``zdd``, ``a1..ad``, m/s^2), cut into blocks as one record.
    selection : ModeSelection
        The linear modal fit of the whole record (:func:`momentid.estimation.modal_select.select_modes`).
    sigma : sequence of dict
        Per run, the noise standard deviation (m/s^2) of every channel.
    blocks : int
        Blocks (refits).

    Returns
    -------
    Jackknife or None
        None when fewer than three refits succeed (no spread to read).
    """
    model, fit = selection.model, selection.fit
    f1 = float(np.min(model.omega(fit.theta)[list(selection.storey)]) / (2 * np.pi))
    bounds = refit_bounds(model, fit.theta)
    starts = np.cumsum([0] + [run.n_samples for run in runs])
    edges = block_edges(runs, blocks)
    refits = []
    for a, b in zip(edges[:-1], edges[1:]):
        pieces = _pieces(runs, starts, a, b, f1)
        if not pieces:
            continue
        cut = type(model)(model.d, len(pieces), model.n - model.d, model.quadrature)
        theta = np.concatenate([fit.theta[:model.n_modal]] + [fit.theta[model.sensor_slice(r)] for r, _ in pieces])
        try:
            sp = [spectra(piece, model.d, fit.f_max, sigma=sigma[r], groups=["a"]) for r, piece in pieces]
            refit = refine(cut, sp, [("whole record", theta)], sample_rates=[runs[r].sample_rate for r, _ in pieces],
                           f_max=fit.f_max, free=np.arange(cut.p) < cut.n_modal, fix_nuisance=False,
                           frequency_bounds=bounds)
        except (MomentidError, np.linalg.LinAlgError, ValueError):
            continue                   # a refit that fails adds nothing
        refits.append(cut.zeta(refit.theta))
    if len(refits) < 3:
        return None
    z = np.array(refits)
    k = z.shape[0]
    std = np.sqrt((k - 1) / k * np.sum((z - z.mean(axis=0)) ** 2, axis=0))
    return Jackknife(damping_ratio_std=std, refits=z, dof=k - 1)


def block_edges(runs: Sequence[RunData], blocks: int = BLOCKS) -> np.ndarray:
    """Edges of the jackknife's blocks: ``blocks`` consecutive blocks of equal shaking.

    Each run's quiet lead-in (:func:`~momentid.estimation.noise.quiet_lead_in`) lies before the first
    edge and stays in every refit: a block of sensor noise alone would change no refit, yet count as a
    degree of freedom of the error.

    Parameters
    ----------
    runs : sequence of RunData
        The record's runs, end to end.
    blocks : int
        Blocks.

    Returns
    -------
    ndarray of int, shape (blocks + 1,)
        Sample indices counted over the runs end to end; the last is the record's length.
    """
    starts = np.cumsum([0] + [run.n_samples for run in runs])
    quiet = np.array([quiet_lead_in(run) for run in runs])
    shaking = np.cumsum([0] + [run.n_samples - q for run, q in zip(runs, quiet)])
    at = np.linspace(0, shaking[-1], blocks + 1).round().astype(int)
    r = np.clip(np.searchsorted(shaking, at, side="right") - 1, 0, len(runs) - 1)
    edges = starts[r] + quiet[r] + (at - shaking[r])
    edges[-1] = starts[-1]
    return edges


def _pieces(runs: Sequence[RunData], starts: np.ndarray, a: int, b: int, f1: float) -> list:
    """``(run index, RunData)`` of the record with samples ``a:b`` (counted over the runs end to end) left
    out, stretches shorter than :data:`MIN_PIECE_CYCLES` cycles of ``f1`` (Hz) dropped."""
    out = []
    for r, run in enumerate(runs):
        lo, hi = int(starts[r]), int(starts[r + 1])
        spans = [(lo, hi)] if b <= lo or a >= hi else [(lo, max(lo, a)), (min(hi, b), hi)]
        for s0, s1 in spans:
            if s1 - s0 >= max(16, MIN_PIECE_CYCLES * run.sample_rate / f1):
                out.append((r, run.window(s0 - lo, s1 - lo)))
    return out
