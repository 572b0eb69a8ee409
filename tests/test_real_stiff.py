"""The second real rig, the stiff 1-storey (data/mini_shake_table/stiff_1storey): damping right or refused.

Its mode rings at 22 Hz with 0.15-0.3 % damping in records of 22 s; its joints add damping and soften it
as it shakes harder (the free decays fall at 0.2 % near 0.2 m/s^2 and 0.4 % near 4 m/s^2); the sine
trials force it at the harmonics of a 2 Hz table.  The peer (SRIM, the data README) puts mode 1 at
21.61-22.04 Hz with 0.13-0.17 % damping.  The linear fit of a whole trial reads 0.44-2.4 %: its
damping is the equivalent linear one at the trial's amplitude.  momentid's damping answer is the
damping at small amplitude, or a refusal with its reason.
"""

from __future__ import annotations

import functools

import numpy as np

import momentid as mi
from conftest import DATA
from momentid.estimation.damping import Source
from momentid.estimation.periodic import FORCED_LINE
from momentid.estimation.scaled import identify_per_run

RIG = DATA / "mini_shake_table" / "stiff_1storey"
#: SRIM of the data README: mode 1 (Hz) per clean trial, damping ratio 0.13-0.17 % on all of them.
SRIM_FREQUENCY = {"el_centro_1": 21.98, "el_centro_2": 22.00, "northridge_1": 21.82, "sine_1": 21.61,
                  "sine_2": 22.04}
SRIM_DAMPING = (0.0013, 0.0017)


@functools.lru_cache(maxsize=1)
def per_run():
    experiment = mi.import_folder(RIG)
    return experiment, dict(zip([r.name for r in experiment.runs], identify_per_run(experiment)))


def test_every_trial_identifies_with_no_wrong_refusal():
    """El Centro 2 was refused for a clock offset at the fit's bound: the import now reads the floor's
    2.3-sample delay from the data, and every trial identifies."""
    _, results = per_run()
    assert set(results) == {"el_centro_1", "el_centro_2", "northridge_1", "northridge_2", "sine_1", "sine_2"}
    for name, r in results.items():
        # within a sample of the table's clock once the import has applied the common delay
        assert np.all(np.abs(r.sensor_offset) < 1.0 / 120), (name, r.sensor_offset)


def test_mode_one_is_where_the_peer_puts_it():
    _, results = per_run()
    for name in ("el_centro_1", "el_centro_2", "northridge_1"):
        # the 1 % on the earthquake trials (SRIM reads the rig at the amplitudes of each trial; so does
        # the linear fit, now that a pole beside the mode that barely lowers the misfit is not an extra mode)
        assert abs(results[name].frequency[0] / SRIM_FREQUENCY[name] - 1) < 0.01, (name, results[name].frequency)
        assert results[name].frequency_answered(0), results[name].warnings
    # sine_1: answered, within 2 % of the README's SRIM figure (21.61 Hz), and within the 1 % of the
    # pole SRIM holds over the README's model orders 4-30: 21.978 Hz at all 14 orders, where 21.61 Hz is found
    # at 4 (`python -m benchmarks.srim_comparison --rig stiff_1storey`, committed in benchmarks/results)
    assert results["sine_1"].frequency_answered(0)
    assert abs(results["sine_1"].frequency[0] / SRIM_FREQUENCY["sine_1"] - 1) < 0.02, results["sine_1"].frequency
    assert abs(results["sine_1"].frequency[0] / 21.978 - 1) < 0.01, results["sine_1"].frequency
    # sine_2's 2 Hz table forces the mode only at its harmonics (21.93 and 23.92 Hz): the fit, pulled between
    # them, reads 22.28 +- 0.017 Hz, above where the rig rings free at small amplitude (22.22 Hz), which a rig
    # whose joints slip as it shakes harder never does: its frequency is refused, with the reason in words
    sine_2 = results["sine_2"]
    assert not sine_2.frequency_answered(0)
    words = [w for w in sine_2.warnings if FORCED_LINE in w]
    assert len(words) == 1 and "only at its harmonics" in words[0] and "rings free" in words[0], sine_2.warnings
    # ... and the amplitude trend of mode 1's frequency is read without it, and says so (text and HTML)
    from momentid.estimation.trend import amplitude_trend

    trend = amplitude_trend(results.values())
    assert "without sine_2: not an answer" in trend.table()
    assert trend._repr_html_().count("NOT AN ANSWER (see the warnings)") >= 1


def test_at_60_hz_the_pulled_frequency_is_still_refused():
    """An IMU at 60 Hz (Sine 2 low-passed and decimated by 2, zero phase): the table's fundamental is read
    from its line (1.993 Hz; a bin of the line's window lobe gave 2.036 Hz, whose 11th harmonic lies 0.47 Hz
    off), so the 21.93 and 23.92 Hz lines still bracket the mode and the fit's 22.32 Hz, above where the rig
    rings free, is refused as at 120 Hz; its damping from the free ringing stays an answer within 2x."""
    import dataclasses

    import scipy.signal

    experiment, _ = per_run()
    run = experiment.run("sine_2")
    values = scipy.signal.decimate(run.values, 2, ftype="fir", axis=0, zero_phase=True)
    run = dataclasses.replace(run, time=run.time[::2][:values.shape[0]], values=values)
    r = mi.identify(dataclasses.replace(experiment, runs=(run,)))
    assert not r.frequency_answered(0) and any(FORCED_LINE in w and "(1.993 Hz)" in w for w in r.warnings), r.warnings
    lo, hi = SRIM_DAMPING
    assert r.damping_is_answer[0] and lo / 2 <= r.damping_ratio[0] <= 2 * hi, r.damping_ratio


def test_damping_is_right_or_refused_with_its_reason():
    _, results = per_run()
    lo, hi = SRIM_DAMPING
    answered = 0
    for name, r in results.items():
        if r.damping_is_answer[0]:
            answered += 1
            # within 2x of the peer's 0.13-0.17 %
            assert lo / 2 <= r.damping_ratio[0] <= 2 * hi, (name, r.damping[0])
            assert r.damping[0].source in vars(Source).values(), r.damping[0].source
        else:
            assert r.damping_refusal[0], name
        # the equivalent linear damping is the old answer, 3-15x the peer's: never called the damping
        assert r.damping_ratio_equivalent[0] > 2 * hi, (name, r.damping_ratio_equivalent)
    # the issue's three earthquake trials are answered (El Centro 1's lone 28-cycle decay pooled with its
    # forced windows: 0.198 +- 0.099 % alone, refused; with the windows' 0.129 +- 0.111 %, an answer)
    for name in ("el_centro_1", "el_centro_2", "northridge_1"):
        assert results[name].damping_is_answer[0], (name, results[name].damping[0].refusal)
    assert answered >= 4


# ----------------------------------------------------------------------------- windows without a lead-in

def _window(run, start: int, seconds: float = 20.0):
    return run.window(start, start + int(seconds * run.sample_rate))


def _agrees_or_is_refused(window, whole, where) -> None:
    """One mode's damping of a window against the whole trial's: both answers agree within two standard
    errors of their difference (a 95 % check), or the window's is refused with its reason."""
    if window.is_answer and whole.is_answer:
        gap = abs(window.damping_ratio - whole.damping_ratio)
        assert gap <= 2 * np.hypot(window.damping_ratio_std, whole.damping_ratio_std), (where, window, whole)
    else:
        assert window.is_answer or window.refusal, (where, window)


def _windows_agree_or_are_refused(experiment, results, names):
    """A 20 s window cut just after each trial's quiet lead-in (a record that starts shaking at once)
    identifies, says where its noise level came from, and its damping agrees with the whole trial's
    within their stated errors (two standard errors of the difference: a 95 % check), or is refused."""
    import dataclasses

    from momentid.estimation.noise import quiet_lead_in

    for name in names:
        run = experiment.run(name)
        start = quiet_lead_in(run) + int(0.5 * run.sample_rate)
        window = dataclasses.replace(experiment, runs=(_window(run, start),))
        r = mi.identify(window)
        assert r.noise[0], name                              # where the noise level came from, said
        for w, t in zip(r.damping, results[name].damping):
            _agrees_or_is_refused(w, t, name)


def test_windows_of_the_stiff_rig_agree_or_are_refused():
    experiment, results = per_run()
    _windows_agree_or_are_refused(experiment, results, list(results))


def test_windows_of_the_flexible_rig_agree_or_are_refused():
    from test_real_identify import SRIM, real_per_run

    experiment, results = real_per_run()
    _windows_agree_or_are_refused(experiment, dict(zip(SRIM, results)), list(SRIM))


def test_windows_cut_mid_shaking_agree_or_are_refused():
    """15 s windows that start mid-shaking take their noise level from their own scatter, which holds the
    rig's distortion (6-30x the sensor noise): a linear fit that explains them to it proves nothing, and a
    decay that falls less than 3x with no trend does not give the damping at small amplitude.  These
    windows answered 0.358 +- 0.029 % (El Centro 1 at 9 s, linear fit), 1.64 +- 0.10 % (Northridge 1 at
    18 s, linear fit) and 0.416 +- 0.039 % (El Centro 1 at 6 s, a 1.7x decay) where the trials read
    0.15-0.17 %; now each agrees within two standard errors of the difference, or is refused.  Sine 1 from
    12 s holds the strong sine and its stop: its forced windows read 2.70 +- 0.32 % (the damping at 2.4-3.4
    m/s^2), and its ring-down after the stop stood below the scatter of the sine's distortion until a
    floor's noise, like the table's, was capped at the table's quiet level."""
    import dataclasses

    experiment, results = per_run()
    for name, start in (("el_centro_1", 6.0), ("el_centro_1", 9.0), ("northridge_1", 18.0), ("sine_1", 12.0)):
        run = experiment.run(name)
        window = _window(run, int(start * run.sample_rate), seconds=15.0)
        r = mi.identify(dataclasses.replace(experiment, runs=(window,)))
        assert "own scatter" in r.noise[0], r.noise
        _agrees_or_is_refused(r.damping[0], results[name].damping[0], (name, start))


def test_windows_holding_a_lead_in_and_the_start_of_a_sine_agree_or_are_refused():
    """The flexible rig's Sine 1.0 from 0 s: its quiet lead-in (the noise level) and the first 10 s of the
    sine.  Modes 2 and 3 answered 0.36 and 0.22 % from forced windows without a trend of their own, where
    the trial reads 0.09 and 0.07 %, while mode 1 showed the rig changing with amplitude; that refusal held
    only for records whose noise came from their own scatter, and now holds with a lead-in too."""
    import dataclasses

    from test_real_identify import SRIM, real_per_run

    experiment, results = real_per_run()
    whole = dict(zip(SRIM, results))["sine_1p0"]
    run = experiment.run("sine_1p0")
    r = mi.identify(dataclasses.replace(experiment, runs=(_window(run, 0, seconds=20.0),)))
    assert "lead-in" in r.noise[0], r.noise
    for k, (w, t) in enumerate(zip(r.damping, whole.damping)):
        _agrees_or_is_refused(w, t, ("sine_1p0", k + 1))


def test_windows_whose_decays_stop_short_of_the_noise_agree_or_are_refused():
    """20 s windows of the flexible rig whose free decays the window's end or the table's forcing cut at
    2-23x the noise cut: Northridge from 50 s read 0.199 +- 0.026 % (mode 2) and 0.225 +- 0.007 % (mode 3)
    and Sine 1.0 from 30 s read 0.40 +- 0.05 % (mode 2), constant over their 3-5x falls, where the
    trials' decays, ringing down to the noise, read 0.142, 0.123 and 0.094 %.  Each now agrees within two
    standard errors of the difference, or is refused."""
    import dataclasses

    from test_real_identify import SRIM, real_per_run

    experiment, results = real_per_run()
    whole = dict(zip(SRIM, results))
    for name, start in (("northridge", 50.0), ("sine_1p0", 30.0)):
        run = experiment.run(name)
        r = mi.identify(dataclasses.replace(experiment, runs=(_window(run, int(start * run.sample_rate)),)))
        for k, (w, t) in enumerate(zip(r.damping, whole[name].damping)):
            _agrees_or_is_refused(w, t, (name, start, k + 1))
