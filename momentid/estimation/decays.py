"""A mode's free decays in a record: whether it stands above the noise at all, its ring-downs fitted,
and when a constant damping read from them is the damping at small amplitude.

:func:`weak_refusal` refuses a mode the sensors barely see; :func:`free_decays` fits the stretches where
it rings on its own (:mod:`momentid.estimation.ringdown`); :func:`constant_refusal` says when a constant
damping those decays read is only the damping at their own amplitudes: they fall too little
(:data:`MIN_CONSTANT_SPAN`) or stop far above the sensors' noise (:data:`NEAR_REST`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from momentid.core.series import RunData
from momentid.estimation import ringdown
from momentid.estimation.noise import quietest_level
from momentid.estimation.windows import MIN_SIGNAL_TO_NOISE, band_noise

if TYPE_CHECKING:
    from momentid.estimation.modal_select import ModeSelection

__all__ = ["weak_refusal", "free_decays", "constant_refusal", "MIN_CONSTANT_SPAN", "NEAR_REST"]

#: A constant damping read from free decays is the damping at small amplitude only when they fall by at
#: least this factor with no sign of a trend: a shorter fall cannot tell a constant damping from one that
#: grows with amplitude as a joint's micro-slip makes it (both shipped rigs damp 2-3x more at 2-4 m/s^2
#: than near 0.2 m/s^2, and a decay from 4.3 to 2.5 m/s^2 shows no trend of its own) ...
MIN_CONSTANT_SPAN = 3.0
#: ... and only when the quietest of them rang until the sensors' noise cut it
#: (:attr:`~momentid.estimation.ringdown.DecayFit.rest` within this factor of
#: :data:`~momentid.estimation.ringdown.MIN_SNR`; such decays end at 0.85-1.10 x it on both shipped rigs,
#: the envelope being smoothed).  Decays that the record's end or the table's forcing cut higher up show the
#: damping at their own amplitudes: 20 s windows of the flexible rig read 0.20-0.40 % from decays that stopped
#: at 2-23 x the cut, where their trials' decays, ringing down to the noise, read 0.09-0.14 %.
NEAR_REST = 1.5


def weak_refusal(runs: Sequence[RunData], selection: ModeSelection, sigma: Sequence[dict], i: int) -> str:
    """Why mode ``i``'s damping cannot be read at all ('' when it can).

    In no run does its relative acceleration on its strongest floor, band-passed around it, stand
    :data:`MIN_SIGNAL_TO_NOISE` times above the white sensor noise in that band, or the mode sits at
    the sampling's Nyquist limit.

    Parameters
    ----------
    runs : sequence of RunData
        The runs of ``selection`` (``zdd``, ``a1..ad``, m/s^2), each with its ``sample_rate`` (Hz).
    selection : ModeSelection
        The linear modal fit: ``model.omega`` and ``model.residues`` at ``fit.theta``, ``storey``.
    sigma : sequence of dict
        Per run, the white noise standard deviation (m/s^2) of ``zdd`` and each ``a<j>``.
    i : int
        The mode's index in the model.

    Returns
    -------
    str
        The refusal in words, or ``''``.
    """
    model, theta = selection.model, selection.fit.theta
    freq, R = model.omega(theta) / (2 * np.pi), model.residues(theta)
    j = int(np.argmax(np.abs(R[i])))
    best = None
    for r, run in enumerate(runs):
        fs = run.sample_rate
        band = ringdown.band_for(freq[i], [freq[k] for k in selection.storey], fs)
        if not band[0] < band[1] or not freq[i] < 0.49 * fs:
            continue
        env, _, _ = ringdown.envelope(run["zdd"] - run[f"a{j + 1}"], band, fs)
        rms = float(np.sqrt(np.mean(env ** 2) / 2))
        noise = band_noise(sigma[r], j, band, fs)
        if best is None or rms / max(noise, 1e-300) > best[0]:
            best = (rms / max(noise, 1e-300), rms, noise, band)
    if best is None:
        return (f"the mode at {freq[i]:.4g} Hz lies at the sampling's Nyquist limit: it is not a mode the "
                f"sensors can resolve")
    ratio, rms, noise, band = best
    if ratio >= MIN_SIGNAL_TO_NOISE:
        return ""
    return (f"the mode at {freq[i]:.4g} Hz stands barely above the sensor noise: its response in "
            f"{band[0]:.3g}-{band[1]:.3g} Hz is {rms:.2g} m/s^2 RMS, {ratio:.2g}x the noise there ({noise:.2g} m/s^2; "
            f"at least {MIN_SIGNAL_TO_NOISE:g}x is needed to read a damping)")


def free_decays(runs: Sequence[RunData], selection: ModeSelection, sigma: Sequence[dict], i: int,
                scatter: bool = False) -> ringdown.DecayFit | None:
    """:class:`~momentid.estimation.ringdown.DecayFit` of mode ``i``'s free decays, or None (too few).

    Parameters
    ----------
    runs, selection, sigma, i
        As for :func:`weak_refusal`.
    scatter : bool
        The noise levels are the data's own scatter, an upper bound that holds the rig's distortion; the
        table's netted from its motion is then at most its level in its quietest second (netting more
        would take real forcing for noise, and a forced stretch for a free one), and so is each floor's
        (the sensors taken alike: a ring-down after a strong sine stops stands 10-30x above its floor's
        true noise, and below the scatter of the sine's distortion).

    Returns
    -------
    DecayFit or None
    """
    model, theta = selection.model, selection.fit.theta
    freq, zeta, R = model.omega(theta) / (2 * np.pi), model.zeta(theta), model.residues(theta)
    j = int(np.argmax(np.abs(R[i])))
    rings, corr = [], 1
    for r, run in enumerate(runs):
        fs = run.sample_rate
        gain, offset = model.sensors(theta, r)
        floor = ringdown.advance(offset[j], run[f"a{j + 1}"], fs) / gain[j]
        band = ringdown.band_for(freq[i], [freq[k] for k in selection.storey], fs)
        corr = int(round(ringdown.correlation_time(band, freq[i]) * fs))
        table = min(sigma[r]["zdd"], quietest_level(run, "zdd")) if scatter else sigma[r]["zdd"]
        relative = float(np.hypot(sigma[r]["zdd"], sigma[r][f"a{j + 1}"]))
        if scatter:
            # the sensors taken alike (as the scatter estimate takes the table as noisy as the floors): the
            # floor's noise at most the table's quiet level too, not the distortion of the strongest shaking
            relative = min(relative, float(np.sqrt(2.0)) * table)
        rings += ringdown.ring_downs(run.name, run["zdd"], run["zdd"] - floor, fs, freq[i], zeta[i], R[i, j], band,
                                     table, relative)
    if not rings or sum(rg.cycles for rg in rings) < ringdown.MIN_CYCLES:
        return None
    return ringdown.fit_decay(rings, corr)


def constant_refusal(decay: ringdown.DecayFit) -> str:
    """Why a constant damping read from free decays is not the damping at small amplitude ('' when it is,
    or when the decays read a damping that changes with amplitude: its law extrapolates instead).

    Parameters
    ----------
    decay : DecayFit
        The mode's free decays (:func:`free_decays`).

    Returns
    -------
    str
        The refusal in words, or ``''``.
    """
    if decay.amplitude_dependent:
        return ""
    lo, hi = decay.amplitude_range
    there = f"({100 * decay.zeta0:.3g} % at {lo:.2g}-{hi:.2g} m/s^2)"
    if decay.span < MIN_CONSTANT_SPAN:
        return (f"the free decays fall only {decay.span:.2g}x and show no trend: too short a fall to tell a constant "
                f"damping {there} from one that grows with amplitude, so the damping at small amplitude is not read "
                f"(at least {MIN_CONSTANT_SPAN:g}x is needed)")
    if decay.rest > NEAR_REST * ringdown.MIN_SNR:
        return (f"the free decays show a constant damping {there} but stop {decay.rest / ringdown.MIN_SNR:.2g}x above "
                f"where the sensors' noise would end them (the record or the table's forcing ends them first): "
                f"below their amplitudes the damping is not seen, so the damping at small amplitude is not read")
    return ""
