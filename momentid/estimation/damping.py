"""The damping answer: each storey mode's damping ratio at small amplitude, right or refused.

The linear modal fit (:mod:`momentid.estimation.modal_select`) gives every mode one damping ratio for a whole
record.  A real rig's damping is not one number: its joints slip more as it shakes harder, so its damping
grows and its frequency falls with amplitude inside one trial; strong shaking drives what no modal model
holds; a sine table forces a mode at its harmonics.  The linear fit's ratio (the *equivalent linear* damping
of that record, kept as :attr:`ModeDamping.equivalent`) then lies far above the structure's own damping:
0.44-2.4 % on the stiff 1-storey rig, whose free decays fall at 0.15-0.3 %.

:func:`resolve_damping` answers with the damping at small amplitude:

* **from the linear fit** when it explains the record to the noise level (:data:`LINEAR_MISFIT`): the
  structure is linear at the record's amplitudes (a level read from the data's own scatter must first pass for
  noise: :func:`_scatter_is_noise`);
* **from free decays** (:mod:`momentid.estimation.ringdown`) when the record holds them, at least
  :data:`~momentid.estimation.ringdown.MIN_CYCLES` cycles of the mode ringing on its own: the envelope against
  the mode's own phase, a constant or amplitude-dependent law by evidence, the limit at small amplitude with a
  Newey-West standard error over the envelope's correlation time (and the spread of the laws' extrapolations
  when the damping depends on amplitude);
* **from the forced response** otherwise: the linear modal model refitted on consecutive windows of
  :data:`WINDOW_CYCLES` cycles of mode 1 (each with its own transient, the record's sensor gains and clock
  offsets; :mod:`momentid.estimation.windows`), the windows' damping ratios pooled with a random effect for
  what they scatter beyond their own errors (model error), Student's t on the windows; their trend's value at
  zero amplitude when the damping grows with amplitude across them, or the frequency falls with it (a joint
  that softens as it slips).

The linear fit's own standard error counts white noise only; its answer carries the windows' error instead
when that is larger (what independent stretches of the record scatter: model error), and any equivalent linear
damping answered carries at least :data:`MODEL_ERROR_SHARE` of itself (what one record cannot show).  A mode
the windows or decays leave too uncertain, on a rig showing no change, is answered by the whole record's fit
with a delete-a-block jackknife error (:mod:`momentid.estimation.jackknife`).

On a rig that changes with amplitude, windows of a mode showing no trend of their own answer their laws' value
at zero amplitude with that extrapolation's error, not their damping at their amplitudes.

A damping ratio is refused, with the reason in words, when its standard error exceeds :data:`MAX_RELATIVE_STD`
of itself, when it is not positive, or when too few independent stretches carry it (:data:`MIN_DOF`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
import scipy.stats

from momentid.core.series import RunData
from momentid.estimation import ringdown
from momentid.estimation.decays import constant_refusal, free_decays, weak_refusal
from momentid.estimation.jackknife import block_jackknife
from momentid.estimation.mode_damping import ModeDamping, Source
from momentid.estimation.noise import LEAD_IN_QUIET_RATIO, quietest_level
from momentid.estimation.periodic import periodic_refusal
from momentid.estimation.windows import WINDOW_CYCLES, drift_words, forced_windows, frequency_trend, random_effects

if TYPE_CHECKING:
    from momentid.estimation.modal_select import ModeSelection

__all__ = ["Source", "ModeDamping", "resolve_damping", "MAX_RELATIVE_STD", "MIN_DOF", "MODEL_ERROR_SHARE",
           "WINDOW_CYCLES"]

#: A linear fit whose residual stays within this factor of the noise level explains the record: the
#: structure is linear at its amplitudes and the fit's damping is the answer (a rig that is not, 2-50x
#: on the shipped real trials, is answered from its free decays).
LINEAR_MISFIT = 1.5
#: ... and so does one whose residual is below this share of the floors' response power (noise-free
#: simulated data, where the residual is the integrator's round-off, many times a noise level of ~0).
NOISE_FREE = 1e-10
#: Noise levels read from the data's own scatter are the sensors' own only when the linear fit's residual
#: reaches at least this share of them (both estimate one variance from thousands of bins when they are; on
#: windows of the shipped rigs the residual is 0.47-0.73 of the scatter, which holds the rigs' distortion) ...
SCATTER_RESIDUAL = 0.8
#: ... and the table shakes: its RMS at least this many times its noise (a shake test drives the table to at
#: least 5x its noise at rest, :data:`~momentid.estimation.noise.LEAD_IN_QUIET_RATIO`).
SHAKING = 1.0 / LEAD_IN_QUIET_RATIO
#: ... and no more than this multiple of the table sensor's RMS in its quietest second (the quietest of some
#: twenty one-second RMS readings of pure noise lies 10-20 % below its level; the floors' scatter on windows
#: of the shipped rigs' shaking is 1.4-32 times the table's quietest second; on the simulated set's records
#: without a lead-in at most 0.92, but for one whose linear fit misses by 3.7x anyway, at 1.6).
QUIETEST_MARGIN = 1.25
#: Fewest windows of a hardening mode's quieter half that answer for it (:func:`_windows_say`).
MIN_QUIET_WINDOWS = 4
#: A record the linear fit explains (:data:`LINEAR_MISFIT`) is believed to hold an amplitude-dependent
#: damping only when the dependence stands out by this many standard errors (the free decays' and the
#: windows' errors are Newey-West and random-effects estimates, not exact: at two a linear rig's beats
#: and leakage read as a trend now and then).
STRONG_SIGMAS = 4.0
#: ... and between this many and that, the hint sends the answer to the windows' value at zero amplitude
#: (an extrapolation, its error as wide as it is) instead of the linear fit's.
HINT_SIGMAS = 3.0
#: A damping ratio whose standard error exceeds this share of itself is not an answer (its 95 % interval
#: then reaches zero: the data do not tell the damping from none).
MAX_RELATIVE_STD = 0.5
#: An equivalent linear damping (the linear fit's, the whole record's, the windows' constant mean) answered as
#: the damping at small amplitude carries at least this share of itself as model error, in quadrature with
#: its own: one record is one amplitude history, and a joint that slips a little more as the rig shakes harder
#: moves the ratio without a residual or a trend that one record shows (a fit passes as linear up to
#: :data:`LINEAR_MISFIT` of its noise).  A floor, below what repeated trials of one rig scatter (the stiff
#: 1-storey rig's five trials: SRIM 0.13-0.17 %, +-13 %; its two El Centro trials' equivalent linear damping
#: 0.440 and 0.447 % a few minutes apart).
MODEL_ERROR_SHARE = 0.05
#: Fewest degrees of freedom (independent stretches less the parameters) of an answer's error.
MIN_DOF = 2
#: The windows' pooled damping and the whole record's may differ by this many of the windows' standard
#: errors when no amplitude dependence explains it; beyond, the windows' estimate is not one.
CONSISTENCY_SIGMAS = 3.0


def resolve_damping(runs: Sequence[RunData], selection: ModeSelection, *, sigma: Sequence[dict],
                    scatter: bool = False) -> tuple[ModeDamping, ...]:
    """Each storey mode's damping at small amplitude, with an honest error, or its refusal.

    Per mode, in this order: the free decays when they show a damping that changes with amplitude;
    else the linear fit when it explains the record to the noise level (its error the larger of its own
    and its windows'; a noise level read from the data's own scatter only when it passes
    :func:`_scatter_is_noise` and no mode hints at the rig changing); else the free decays (a constant
    damping only over a fall of :data:`~momentid.estimation.decays.MIN_CONSTANT_SPAN` that rings down to
    the noise; pooled with the windows when too uncertain alone); else, when the table's motion is
    periodic, the linear fit if it explains the record so and no mode hints at the rig changing with
    amplitude, refused otherwise; else the forced
    response: the windows' value at zero amplitude when their frequency falls with amplitude (even one
    that moves beyond the half-power width, when that value lies below the windows' mean), refused when
    they show no trend while another mode shows the rig changing with amplitude (a frequency that rises
    with it shows a hardening spring, which dissipates nothing, not a change of the damping).  An answer
    refused only as too uncertain, on a rig where no mode hints at a change, gives way to the whole
    record's linear fit with its delete-a-block jackknife error (:class:`_WholeRecord`).

    Parameters
    ----------
    runs : sequence of RunData
        The runs of ``selection`` (``zdd``, ``a1..ad``, m/s^2).
    selection : ModeSelection
        The linear modal fit (:func:`momentid.estimation.modal_select.select_modes`).
    sigma : sequence of dict
        Per run, the noise standard deviation (m/s^2) of every channel (``zdd``, ``a1``, ...).
    scatter : bool
        Some run's noise levels were read from the data's own scatter
        (:func:`~momentid.estimation.noise.local_polynomial_noise`): they hold any distortion of a rig that
        is not linear, so a linear fit that explains the record to them proves nothing.

    Returns
    -------
    tuple of ModeDamping
        One per storey mode, in the order of ``selection.storey``.
    """
    model, fit = selection.model, selection.fit
    freq, zeta = model.omega(fit.theta) / (2 * np.pi), model.zeta(fit.theta)
    base_linear, exact = _explains(runs, fit, sigma, model.d)
    sd = np.sqrt(np.clip(np.diag(fit.covariance), 0, None))
    seconds = sum(run.n_samples / run.sample_rate for run in runs)
    windows = None if exact else forced_windows(runs, selection, sigma, list(selection.storey))
    decays = [None if exact else free_decays(runs, selection, sigma, i, scatter) for i in selection.storey]
    saids = [None if exact else _windows_say(windows[k], float(zeta[i]), float(freq[i]), seconds * freq[i])
             for k, i in enumerate(selection.storey)]
    trends = [0.0 if exact else frequency_trend(w)[1] for w in (windows or [None] * len(saids))]
    # a rig that changes with amplitude in any mode gives no mode's damping at small amplitude from windows
    # without a trend of their own (with or without a quiet lead-in)
    rig_changes = "" if exact else _rig_changes(decays, saids, windows, trends)
    quiet = exact or _rig_quiet(decays, saids, trends)
    # a linear fit that explains the record to its noise level proves the rig linear at its amplitudes; a
    # noise level read from the data's own scatter may hold the rig's distortion (on windows of the shipped
    # rigs the fit then answered 1-3 % for modes damped 0.07-0.2 %): it counts only when it passes what noise
    # must (_scatter_is_noise) and no mode hints at the rig changing
    trusted = base_linear and (not scatter or (quiet and _scatter_is_noise(runs, fit, sigma, model.d)))
    # a periodic table holds a mode at one amplitude (no trend of its own can show), yet the linear fit may
    # answer it (read from the transients, where the mode rings at its own frequency) when it explains the
    # record so and no mode shows a hint of the rig changing
    periodic_linear = trusted and quiet
    whole = _WholeRecord(runs, selection, sigma, trusted and quiet and not rig_changes)
    out = []
    for k, i in enumerate(selection.storey):
        weak = "" if exact else weak_refusal(runs, selection, sigma, i)
        if weak:
            out.append(replace(_unknown(float(zeta[i]), float(freq[i])), refusal=weak))
            continue
        periodic = periodic_refusal(runs, float(freq[i]))
        # a record forced only at a periodic table's harmonics beside the mode (a constant amplitude: no
        # trend can show; the harmonics read the detuning, not the damping) does not prove the rig linear
        linear = (exact or trusted) and not periodic
        decay, said = decays[k], saids[k]
        # a record the linear fit explains must show a strong amplitude dependence (of the damping, or of
        # the frequency: a joint that slips softens too) before it is believed
        needed = STRONG_SIGMAS if linear else ringdown.SLOPE_SIGMAS
        # a trend read from fewer independent stretches than an answer needs is no evidence (Newey-West
        # errors over two stretches are themselves a guess)
        evidence = max(decay.evidence if decay is not None and decay.dof >= MIN_DOF else 0.0,
                       max(said.evidence, abs(trends[k])) if said is not None else 0.0)
        changes = evidence > needed
        if decay is not None and (changes or not linear):
            answer = _decay_answer(decay, windows[k], float(zeta[i]), float(freq[i]), seconds * freq[i])
            if answer.refusal and periodic and periodic_linear and not changes:
                # a periodic table on a rig the linear fit explains, no mode showing a change: decays too poor
                # to answer leave it to the linear fit, read from the transients (change 5)
                answer = _linear_answer(float(zeta[i]), float(sd[model.n + i]), max(fit.dof, 1), said,
                                        float(freq[i]), seconds * freq[i])
            out.append(whole.instead(answer, i, k, periodic, windows))
        elif exact or (linear and evidence <= HINT_SIGMAS) or (periodic and periodic_linear):
            # a linear structure at these amplitudes: the linear fit's damping
            answer = _linear_answer(float(zeta[i]), float(sd[model.n + i]), max(fit.dof, 1), said,
                                    float(freq[i]), seconds * freq[i])
            out.append(whole.instead(answer, i, k, periodic, windows))
        elif periodic:
            out.append(replace(_unknown(float(zeta[i]), float(freq[i])), refusal=periodic))
        elif linear:
            # a hint of amplitude dependence (three standard errors, not four): the windows' value at zero
            # amplitude, with the error of that extrapolation
            out.append(_windows_say(windows[k], float(zeta[i]), float(freq[i]), seconds * freq[i], trend=True))
        else:
            answer = _softening(said, trends[k], windows[k], float(zeta[i]), float(freq[i]), seconds * freq[i])
            if rig_changes and not answer.amplitude_dependent and not answer.refusal:
                answer = _extrapolated(answer, windows[k], rig_changes, float(zeta[i]), float(freq[i]),
                                       seconds * freq[i])
            out.append(whole.instead(answer, i, k, periodic, windows))
    return tuple(_with_model_error(a) for a in out)


def _extrapolated(answer: ModeDamping, windows, rig_changes: str, equivalent: float, f0: float,
                  cycles: float) -> ModeDamping:
    """A mode whose windows show no trend of their own on a rig that changes with amplitude: their damping is
    the damping at their amplitudes, so the answer is their laws' value at zero amplitude with the error of
    that extrapolation (:func:`_windows_say` with ``trend``), refused with both reasons when that is no answer."""
    at_zero = _windows_say(windows, equivalent, f0, cycles, trend=True)
    if at_zero.amplitude_dependent and not at_zero.refusal:
        return at_zero
    lo, hi = answer.amplitude_range
    why = (f"{rig_changes}, and this mode's windows ({lo:.2g}-{hi:.2g} m/s^2) show no trend of their own: their "
           f"damping ({100 * answer.damping_ratio:.3g} %) is the damping at those amplitudes, not at small amplitude")
    return replace(answer, refusal=why + (f"; extrapolated to zero amplitude, {at_zero.refusal}" if at_zero.refusal
                                          else ""))


def _decay_answer(decay, windows, equivalent: float, f0: float, cycles: float) -> ModeDamping:
    """The free decays' answer: refused when their constant is read above small amplitude only (the more
    telling reason first, then their error), else pooled with the forced ``windows``."""
    answer = replace(_answer(decay.zeta0, decay.zeta0_std, decay.dof, Source.FREE_DECAY, decay.amplitude_dependent,
                             decay.slope, decay.exponent, decay.frequency0, decay.frequency_slope,
                             decay.amplitude_range, equivalent, decay.cycles), evidence=decay.evidence)
    unseen = constant_refusal(decay)
    if unseen:       # a constant read above small amplitudes says nothing there, pooled or not
        return replace(answer, refusal=f"{unseen}; {answer.refusal}" if answer.refusal else unseen)
    return _pooled(answer, windows, equivalent, f0, cycles)


def _with_model_error(answer: ModeDamping) -> ModeDamping:
    """``answer`` with its standard error at least :data:`MODEL_ERROR_SHARE` of its ratio (in quadrature) when it
    is an equivalent linear damping (no amplitude law) with a finite error; unchanged otherwise."""
    linear = answer.source in (Source.LINEAR, Source.WHOLE_RECORD, Source.FORCED)
    if answer.amplitude_dependent or not linear or not np.isfinite(answer.damping_ratio_std):
        return answer
    sd = float(np.hypot(answer.damping_ratio_std, MODEL_ERROR_SHARE * answer.damping_ratio))
    floored = _answer(answer.damping_ratio, sd, answer.dof, answer.source, False, answer.slope, answer.exponent,
                      answer.frequency, answer.frequency_slope, answer.amplitude_range, answer.equivalent,
                      answer.cycles)
    return replace(floored, refusal=answer.refusal or floored.refusal, evidence=answer.evidence)


def _softening(said: ModeDamping, trend: float, windows, equivalent: float, f0: float, cycles: float
               ) -> ModeDamping:
    """The windows' answer, or, when it is a constant damping but the mode's frequency falls with its
    amplitude across the windows (``trend``: the t statistic of :func:`~momentid.estimation.windows.frequency_trend`)
    beyond :data:`~momentid.estimation.ringdown.SLOPE_SIGMAS` standard errors
    (a joint that softens as it slips, and dissipates more as it does), their trend's value at zero
    amplitude with the error of that extrapolation: the windows' mean is the damping at their amplitudes,
    not at small amplitude.  Windows refused because the frequency moves beyond the half-power width
    answer so too, when the extrapolation comes out below their mean."""
    if trend >= -ringdown.SLOPE_SIGMAS:
        return said
    drifts = _drift_refusal(windows, equivalent)
    if not drifts:
        return said if said.amplitude_dependent or said.refusal else _windows_say(windows, equivalent, f0, cycles,
                                                                                  trend=True)
    at_zero = _windows_say(windows, equivalent, f0, cycles, trend=True, smear=False)
    z, s = (np.array(x) for x in list(zip(*windows))[:2])
    mean = float(random_effects(z, s, np.ones((z.size, 1)))[0][0])
    if at_zero.refusal or not at_zero.amplitude_dependent or at_zero.damping_ratio > mean:
        # a frequency that moves beyond the half-power width smears the windows' damping upward, and a
        # slipping joint adds damping as it softens: both vanish at zero amplitude, so the extrapolation
        # must come out below the windows' mean; one above it contradicts both, and the refusal stands
        return said
    return at_zero


class _WholeRecord:
    """The whole record's linear fit, its error the larger of its own and the delete-a-block jackknife's
    (computed once, when needed), for an answer refused only as too uncertain.  Only when the fit explains the
    record to a noise level that is the sensors' (``allowed``: :data:`LINEAR_MISFIT`, a window of the flexible
    rig's sine test, at 2.4x, read 0.58 % for 0.26 %; a scatter that passes for noise, the stiff rig's
    Northridge 2 from 15 s, explained to a scatter 1.4x the table's quietest second, read 0.31 % for SRIM's
    0.13-0.17 %), is more certain than the refused estimate, agrees with it within :data:`POOL_SIGMAS`
    (a stiff rig's window, noise from its scatter: 2.8 % against two decays' 0.25 +- 0.20 %) and that shows
    no amplitude law (on both rigs' windows the fit read 2x such); never where a mode hints at the rig
    changing (``allowed``), a table is periodic or a frequency moves beyond the half-power width."""

    def __init__(self, runs, selection, sigma, allowed: bool):
        self.runs, self.selection, self.sigma, self.allowed = runs, selection, sigma, allowed

    @cached_property
    def jackknife(self):
        return block_jackknife(self.runs, self.selection, self.sigma)

    def instead(self, answer: ModeDamping, i: int, k: int, periodic: str, windows) -> ModeDamping:
        """``answer`` (mode ``i``, the ``k``-th storey mode), or the whole record's in its place."""
        model, fit = self.selection.model, self.selection.fit
        z, f0 = float(model.zeta(fit.theta)[i]), float(model.omega(fit.theta)[i] / (2 * np.pi))
        eligible = (self.allowed and _imprecise(answer) and not answer.amplitude_dependent and not periodic
                    and not (windows is not None and _drift_refusal(windows[k], z)))
        if not eligible or self.jackknife is None:
            return answer
        std = max(float(np.sqrt(max(fit.covariance[model.n + i, model.n + i], 0.0))),
                  float(self.jackknife.damping_ratio_std[i]))
        z_r, s_r = answer.damping_ratio, answer.damping_ratio_std
        if np.isfinite(s_r) and (std >= s_r or abs(z - z_r) > POOL_SIGMAS * float(np.hypot(s_r, std))):
            return answer              # no more certain than the refused estimate, or contradicted by it
        whole = _answer(z, std, self.jackknife.dof, Source.WHOLE_RECORD, False, 0.0, 0.0, f0, 0.0,
                        answer.amplitude_range, z, sum(r.n_samples / r.sample_rate for r in self.runs) * f0)
        return replace(answer, refusal=f"{answer.refusal} (and by the {whole.source}: {whole.refusal})"
                       ) if whole.refusal else whole


def _imprecise(answer: ModeDamping) -> bool:
    """Refused only as too uncertain: few stretches, not positive, or a finite error beyond :data:`MAX_RELATIVE_STD`."""
    z, s = answer.damping_ratio, answer.damping_ratio_std
    return bool(answer.refusal and np.isfinite(s) and (answer.dof < MIN_DOF or z <= 0 or s > MAX_RELATIVE_STD * z))


def _linear_answer(zeta: float, std: float, dof: int, said: ModeDamping | None, f0: float, cycles: float
                   ) -> ModeDamping:
    """The linear fit's damping, its error the larger of the fit's own (white noise) and the windows'
    (what independent stretches of the record scatter: :func:`_segment_error`)."""
    std, dof = _segment_error(std, dof, said)
    return _answer(zeta, std, dof, Source.LINEAR, False, 0.0, 0.0, f0, 0.0,
                   said.amplitude_range if said else (0.0, 0.0), zeta, cycles)


def _segment_error(std: float, dof: int, said: ModeDamping | None) -> tuple[float, int]:
    """The linear fit's standard error and degrees of freedom, or the windows' when larger: the fit's own
    counts white noise only; the windows' random-effects error counts what independent stretches of the
    record scatter beyond it (model error: a batch-means estimate of the whole record's error)."""
    if said is None or said.dof < MIN_DOF or not np.isfinite(said.damping_ratio_std):
        return std, dof
    return (said.damping_ratio_std, said.dof) if said.damping_ratio_std > std else (std, dof)


def _rig_quiet(decays, saids, trends) -> bool:
    """No mode of the record shows a hint of the rig changing with amplitude: no free decay's damping
    trend, windows' damping trend or frequency trend (``trends``: t statistics) beyond :data:`HINT_SIGMAS`."""
    for decay, said, t in zip(decays, saids, trends):
        if decay is not None and decay.dof >= MIN_DOF and abs(decay.evidence) > HINT_SIGMAS:
            return False
        if said is not None and max(abs(said.evidence), abs(t)) > HINT_SIGMAS:
            return False
    return True


def _rig_changes(decays, saids, windows, trends) -> str:
    """How the record shows the rig changing with amplitude in some mode ('' when none does): a free decay's
    damping trend or a frequency moving across the windows (``trends``: t statistics), beyond
    :data:`STRONG_SIGMAS` standard errors (the strength that makes a record the linear fit explains
    believed amplitude-dependent), or a frequency that moves by more than its half-power width
    (:func:`~momentid.estimation.windows.drift_words`); a frequency that rises with amplitude is a hardening
    spring, which changes no damping."""
    for k, (decay, said) in enumerate(zip(decays, saids)):
        if decay is not None and decay.dof >= MIN_DOF and decay.evidence > STRONG_SIGMAS:
            return f"the rig's joints change with amplitude (mode {k + 1}'s free decays, {decay.evidence:.2g} sigma)"
        if trends[k] > 0:
            continue             # a frequency that rises with amplitude: a hardening spring, which dissipates nothing
        t = abs(trends[k])
        if said is not None and t > STRONG_SIGMAS:
            return f"the rig changes with amplitude (mode {k + 1}'s frequency moves with it, {t:.2g} sigma)"
        moves = drift_words(windows[k], said.equivalent) if said is not None else ""
        if moves:
            return f"the rig changes with amplitude (mode {k + 1}: {moves})"
    return ""


#: Two estimates of one damping at small amplitude are pooled only when they differ by at most this many
#: standard errors of their difference (beyond, one of them is biased and their mean is no answer).
POOL_SIGMAS = 2.0


def _pooled(decay: ModeDamping, windows, equivalent: float, f0: float, cycles: float) -> ModeDamping:
    """The free decays' answer, or, when it is too uncertain on its own (its standard error beyond
    :data:`MAX_RELATIVE_STD` of it: a single short decay whose extrapolation to small amplitude is wide),
    its inverse-variance mean with the forced windows' value at zero amplitude, when that is positive,
    rests on enough windows and agrees within :data:`POOL_SIGMAS`.  The two come from different stretches
    of the record (the decays ring where the windows' forcing is weak), so their errors are independent."""
    z1, s1 = decay.damping_ratio, decay.damping_ratio_std
    if not (z1 > 0 and decay.dof >= MIN_DOF and np.isfinite(s1) and s1 > MAX_RELATIVE_STD * z1):
        return decay                               # an answer, or refused for a reason pooling cannot mend
    said = _windows_say(windows, equivalent, f0, cycles, trend=True)
    z2, s2 = said.damping_ratio, said.damping_ratio_std
    if not (said.amplitude_dependent and z2 > 0 and said.dof >= MIN_DOF and np.isfinite(s2) and s2 > 0):
        return decay
    if abs(z1 - z2) > POOL_SIGMAS * float(np.hypot(s1, s2)):
        return decay
    w1, w2 = 1 / s1 ** 2, 1 / s2 ** 2
    z, sd = (w1 * z1 + w2 * z2) / (w1 + w2), float(np.sqrt(1 / (w1 + w2)))
    lo = min(decay.amplitude_range[0], said.amplitude_range[0])
    hi = max(decay.amplitude_range[1], said.amplitude_range[1])
    answer = _answer(z, sd, decay.dof + said.dof, Source.POOLED, True, decay.slope, decay.exponent, decay.frequency,
                     decay.frequency_slope, (lo, hi), equivalent, decay.cycles + said.cycles)
    return replace(answer, evidence=decay.evidence,
                   refusal=answer.refusal and f"{answer.refusal} (and by the free decays alone: {decay.refusal})")


def _scatter_is_noise(runs, fit, sigma, d: int) -> bool:
    """Whether noise levels read from the data's own scatter are the sensors' noise, so that a linear fit
    explaining the record to them proves the rig linear at its amplitudes.  Three checks, each of what
    noise must satisfy: the fit's residual reaches that scatter (at least :data:`SCATTER_RESIDUAL` of it; a
    residual well below says the scatter holds more than noise, the distortion of a rig that is not linear);
    the table sensor, of one kind with the floors', reads no less in its quietest second (within
    :data:`QUIETEST_MARGIN`: a sensor's noise lies below all it reads); and the table shakes in every run
    (its RMS at least :data:`SHAKING` times its noise: a table at rest leaves a free decay, which the decays
    read)."""
    for run, sg in zip(runs, sigma):
        floors = max(sg[f"a{j + 1}"] for j in range(d))
        if (float(np.std(run["zdd"])) < SHAKING * sg["zdd"]
                or floors > QUIETEST_MARGIN * quietest_level(run, "zdd")):
            return False
    return fit.scale >= SCATTER_RESIDUAL


def _explains(runs, fit, sigma, d: int) -> tuple[bool, bool]:
    """Whether the linear fit explains the record to its noise level, and whether to round-off (noise-free
    data: nothing else can tell more)."""
    floors = np.mean([np.var(run.group("a", d)) for run in runs])
    noise = np.mean([np.mean([sg[f"a{j + 1}"] ** 2 for j in range(d)]) for sg in sigma])
    exact = fit.scale * noise <= NOISE_FREE * floors
    return exact or fit.scale <= LINEAR_MISFIT ** 2, exact


def _unknown(equivalent: float, f0: float) -> ModeDamping:
    """No estimate at all (refused: the reason is set by the caller or says so)."""
    return _answer(equivalent, np.inf, 1, Source.FORCED, False, 0.0, 0.0, f0, 0.0, (0.0, 0.0), equivalent, 0.0)


def _windows_say(windows, equivalent: float, f0: float, cycles: float, trend: bool = False,
                 smear: bool = True) -> ModeDamping:
    """The forced-response answer from the windows: their damping ratios' trend in amplitude when they
    show one or ``trend`` asks for it (its value at zero amplitude), else their random-effects mean;
    refused (unless ``smear`` is False: a value at zero amplitude, where the spread vanishes) when the
    mode's frequency moves across the windows by more than
    :data:`~momentid.estimation.windows.DRIFT_LIMIT` of its half-power half-width (a linear fit reads
    that spread as damping)."""
    if len(windows) < 2:
        return _unknown(equivalent, f0)
    z, s, f, sf, amp = (np.array(x) for x in zip(*windows))
    b, cov = random_effects(z, s, np.column_stack([np.ones_like(amp), amp]))
    evidence = float(b[1] / np.sqrt(cov[1, 1])) if z.size > 3 and cov[1, 1] > 0 else 0.0     # growing only
    dependent = evidence > ringdown.SLOPE_SIGMAS or (trend and z.size > 3)
    exponent = 1.0 if dependent else 0.0
    if not dependent:
        b, cov = random_effects(z, s, np.ones((z.size, 1)))
        zeta0, var0 = float(b[0]), float(cov[0, 0])
    else:
        # the laws zeta0 + zeta1 A^p of the free decays (joint micro-slip: p = 1/2 to 1): their mean value
        # at zero amplitude, its variance their mean variance plus the variance between them (windows that
        # never reach small amplitudes leave the laws' extrapolations apart, and the answer as uncertain)
        fits = [random_effects(z, s, np.column_stack([np.ones_like(amp), amp ** p])) for p in ringdown.POWERS]
        at_zero = np.array([float(bp[0]) for bp, _ in fits])
        zeta0 = float(np.mean(at_zero))
        var0 = float(np.mean([cp[0, 0] for _, cp in fits]) + (np.var(at_zero, ddof=1) if at_zero.size > 1 else 0.0))
    answer = _answer(zeta0, float(np.sqrt(max(var0, 0.0))), z.size - b.size, Source.FORCED, dependent,
                     float(b[1]) if dependent else 0.0, exponent, f0, 0.0,
                     tuple(np.percentile(amp, [10, 90])), equivalent, cycles)
    slope, _ = frequency_trend(windows)
    refusal = (_drift_refusal(windows, equivalent) if smear else "") or answer.refusal
    if refusal and not answer.refusal and slope > 0 and not trend:
        # a frequency that rises with amplitude is a hardening spring, which dissipates nothing: the spread
        # smears only the windows it moves within; the quieter half, if it stays within the half-power width,
        # reads the damping
        low = [w for w in windows if w.amplitude <= np.median(amp)]
        if MIN_QUIET_WINDOWS <= len(low) < len(windows) and not _drift_refusal(low, equivalent):
            return _windows_say(low, equivalent, f0, cycles)
    if not refusal and not dependent:
        # windows that read the same damping as the whole record, or their estimate is not one: a window
        # too short for the mode, or edges the windows' transients cannot hold
        gap = abs(answer.damping_ratio - equivalent) / max(answer.damping_ratio_std, 1e-12)
        if gap > CONSISTENCY_SIGMAS:
            refusal = (f"the windows of the record read {100 * answer.damping_ratio:.3g} +- "
                       f"{100 * answer.damping_ratio_std:.2g} % where the whole record reads {100 * equivalent:.3g} %, "
                       f"{gap:.2g} standard errors apart, with no amplitude to explain it")
    return replace(answer, evidence=evidence, frequency_slope=slope, refusal=refusal)


def _drift_refusal(windows, equivalent: float) -> str:
    """Why the windows' damping cannot be read from a forced response ('' when it can): the mode's
    frequency moves with its amplitude across the windows by more than
    :data:`~momentid.estimation.windows.DRIFT_LIMIT` of its half-power half-width (a linear fit reads
    that spread as damping)."""
    moves = drift_words(windows, equivalent)
    return f"{moves}, and it never rings free: a forced response reads that spread as damping" if moves else ""


def _answer(z, sd, dof, source, dependent, slope, exponent, f0, f_slope, amplitudes, equivalent, cycles) -> ModeDamping:
    tq = float(scipy.stats.t.ppf(0.975, max(dof, 1)))
    return ModeDamping(
        damping_ratio=float(z), damping_ratio_std=float(sd), interval=(float(z - tq * sd), float(z + tq * sd)),
        dof=int(dof), source=source, amplitude_dependent=bool(dependent), slope=float(slope),
        exponent=float(exponent), frequency=float(f0), frequency_slope=float(f_slope),
        amplitude_range=tuple(float(a) for a in amplitudes), equivalent=float(equivalent), cycles=float(cycles),
        refusal=_refusal(float(z), float(sd), int(dof), float(f0), source))


def _refusal(z: float, sd: float, dof: int, f0: float, source: str) -> str:
    if not np.isfinite(sd):
        return (f"the mode at {f0:.4g} Hz neither rings free in the record nor leaves enough forced windows to "
                f"measure its damping")
    if dof < MIN_DOF:
        return (f"the {source} of the mode at {f0:.4g} Hz hold {dof + 1} independent stretch(es): too few to tell "
                f"model error from damping")
    if z <= 0:
        return f"its damping ratio comes out {100 * z:.3g} % from the {source} (not positive): not a passive mode's"
    if sd > MAX_RELATIVE_STD * z:
        return (f"not determined by the {source}: {100 * z:.3g} +- {100 * sd:.2g} %, the standard error more than "
                f"{MAX_RELATIVE_STD:.0%} of the ratio")
    return ""
