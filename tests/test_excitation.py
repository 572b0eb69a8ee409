"""Table motions: harmonics, AT2 records, band-limited noise, chirps (momentid.lab.excitation)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import cumulative_simpson

from momentid.errors import ScenarioError
from momentid.lab.excitation import STANDARD_GRAVITY, GroundMotion, ground_motion, read_at2
from momentid.lab.scenario import BandLimitedNoise, Chirp, Harmonics, RecordedMotion

ELCENTRO = Path(__file__).resolve().parents[1] / "data" / "records" / "elcentro_1940_ns.at2"


@pytest.fixture(scope="module")
def elcentro_path() -> Path:
    assert ELCENTRO.is_file(), f"{ELCENTRO} is missing from the repository"
    return ELCENTRO


@pytest.fixture(scope="module")
def elcentro(elcentro_path) -> GroundMotion:
    """El Centro at scale 1 with the defaults (highpass 0.1 Hz, taper 1 s)."""
    return ground_motion(RecordedMotion(elcentro_path), 20.0)


@pytest.fixture(scope="module")
def noise() -> GroundMotion:
    return ground_motion(BandLimitedNoise(rms=0.5, band=(1.0, 20.0), seed=7), 20.0)


def write_at2(path: Path, header: str, values, per_line: int = 5) -> Path:
    rows = [values[i : i + per_line] for i in range(0, len(values), per_line)]
    body = "\n".join(" ".join(f"{v: .7E}" for v in row) for row in rows)
    path.write_text(f"TEST RECORD\nSYNTHETIC\nACCELERATION TIME SERIES IN UNITS OF G\n{header}\n{body}\n")
    return path


def synthetic_record(tmp_path: Path) -> Path:
    """A 12 s decaying two-tone record (g) with a deliberate baseline offset."""
    t = np.arange(601) * 0.02
    acc = 0.2 * np.exp(-0.3 * t) * (np.sin(2 * np.pi * 1.3 * t) + 0.5 * np.sin(2 * np.pi * 4.1 * t)) + 0.003
    return write_at2(tmp_path / "synthetic.at2", "NPTS=   601, DT= .0200 SEC", list(acc))


# ---------------------------------------------------------------------------
# Harmonics
# ---------------------------------------------------------------------------
HARM = Harmonics(amplitudes=(0.002, 0.0007), angular_frequencies=(2 * np.pi, 17.3), phases=(0.3, -1.1))


def test_harmonic_derivatives_match_finite_differences():
    gm = ground_motion(HARM, 5.0)
    t = np.linspace(0.05, 4.95, 97)
    h = 1e-4
    for lower, upper, peak in (
        (gm.displacement, gm.velocity, gm.peak_velocity),
        (gm.velocity, gm.acceleration, gm.peak_acceleration),
    ):
        fd = (lower(t + h) - lower(t - h)) / (2 * h)
        # Central difference: truncation h^2/6 |f'''| <= 1e-8/6 * sum A w^4 ~ 1.5e-7 of
        # the peak, round-off eps |f| / h ~ 1e-12; 1e-6 of the peak leaves margin.
        np.testing.assert_allclose(fd, upper(t), rtol=0, atol=1e-6 * peak)


def test_harmonic_values_shapes_and_peaks():
    gm = ground_motion(HARM, 5.0)
    A, w, phi = (np.array(x) for x in (HARM.amplitudes, HARM.angular_frequencies, HARM.phases))
    # Closed forms at t = 0 (the simulator's initial base state); round-off only.
    assert gm.displacement(0.0) == pytest.approx(np.sum(A * np.sin(phi)), rel=1e-14)
    assert gm.velocity(0.0) == pytest.approx(np.sum(A * w * np.cos(phi)), rel=1e-14)
    t = np.linspace(0, 3, 24).reshape(2, 3, 4)
    assert gm.acceleration(t).shape == (2, 3, 4)
    single = ground_motion(Harmonics((0.002,), (2 * np.pi,), (0.0,)), 5.0)
    # A single sine over five periods peaks at A w^k; Newton polishing is exact to round-off.
    for peak, k in ((single.peak_displacement, 0), (single.peak_velocity, 1), (single.peak_acceleration, 2)):
        assert peak == pytest.approx(0.002 * (2 * np.pi) ** k, rel=1e-12)
    # A dense sample can only come close to the exact peak from below (grid 2.5 us:
    # the miss is <= f'' dt^2 / 8, ~1e-12 of the peak).
    dense = np.abs(gm.acceleration(np.linspace(0, 5, 2_000_001))).max()
    assert dense <= gm.peak_acceleration * (1 + 1e-12)
    assert dense >= gm.peak_acceleration * (1 - 1e-9)


@pytest.mark.parametrize(
    "bad, key",
    [
        (Harmonics((0.002, 0.001), (1.0,), (0.0,)), "excitation.phases"),
        (Harmonics((-0.002,), (1.0,), (0.0,)), "excitation.amplitudes"),
        (Harmonics((0.002,), (float("nan"),), (0.0,)), "excitation.angular_frequencies"),
    ],
)
def test_harmonic_invalid(bad, key):
    with pytest.raises(ScenarioError, match=key):
        ground_motion(bad, 5.0)


def test_invalid_duration():
    with pytest.raises(ScenarioError, match="scenario.duration"):
        ground_motion(HARM, 0.0)


# ---------------------------------------------------------------------------
# AT2 parsing
# ---------------------------------------------------------------------------
def test_read_elcentro(elcentro_path):
    dt, acc = read_at2(elcentro_path)
    assert dt == 0.02
    assert acc.shape == (1560,)
    assert acc[:3].tolist() == [0.0, 6.3e-03, 3.64e-03]
    assert acc[-1] == 0.0
    assert np.abs(acc).max() == pytest.approx(0.31882, abs=1e-12)  # PGA of the file, in g


@pytest.mark.parametrize(
    "header, dt",
    [
        ("NPTS= 7, DT= .0200 SEC", 0.02),
        ("NPTS=  7   DT=   0.0050", 0.005),
        ("npts=7,dt=0.01", 0.01),
        ("7    0.0100    NPTS, DT", 0.01),
    ],
)
def test_read_at2_header_variants(tmp_path, header, dt):
    values = [0.0, 0.1, -0.2, 0.3, -0.05, 1e-3, 0.0]
    got_dt, acc = read_at2(write_at2(tmp_path / "r.at2", header, values, per_line=3))
    assert got_dt == dt
    np.testing.assert_array_equal(acc, values)  # "% .7E" round-trips these exactly


def test_read_at2_fortran_exponent(tmp_path):
    p = tmp_path / "d.at2"
    p.write_text("A\nB\nC\nNPTS= 4, DT= 0.01\n 1.0D-02 -2.0d-03 0.0 0.5\n")
    np.testing.assert_array_equal(read_at2(p)[1], [0.01, -0.002, 0.0, 0.5])


def _at2_error(path: Path) -> str:
    with pytest.raises(ScenarioError) as info:
        read_at2(path)
    msg = str(info.value)
    assert str(path) in msg
    return msg


def test_read_at2_bad_value_token(tmp_path):
    p = tmp_path / "bad.at2"
    p.write_text("A\nB\nC\nNPTS= 6, DT= 0.01\n0.1 0.2 0.3\n0.4 0.5x 0.6\n")
    msg = _at2_error(p)
    assert "line 6" in msg and "'0.5x'" in msg


def test_read_at2_bad_header_tokens(tmp_path):
    p = tmp_path / "npts.at2"
    p.write_text("A\nB\nC\nNPTS= 15x0, DT= 0.01\n0.1 0.2\n")
    msg = _at2_error(p)
    assert "line 4" in msg and "'15x0'" in msg
    p.write_text("A\nB\nC\nNPTS= 2, DT= -0.01\n0.1 0.2\n")
    msg = _at2_error(p)
    assert "line 4" in msg and "'-0.01'" in msg
    p.write_text("A\nB\nC\nNPTS and DT follow\n0.1 0.2\n")
    assert "line 4" in _at2_error(p)


def test_read_at2_npts_mismatch(tmp_path):
    p = write_at2(tmp_path / "short.at2", "NPTS= 9, DT= 0.01", [0.1] * 8)
    msg = _at2_error(p)
    assert "line 4" in msg and "NPTS = 9" in msg and "8 values" in msg


def test_read_at2_missing_header_units_and_file(tmp_path):
    p = tmp_path / "noheader.at2"
    p.write_text("0.1 0.2 0.3\n" * 20)
    assert "NPTS" in _at2_error(p)
    p = tmp_path / "cm.at2"
    p.write_text("A\nACCELERATION TIME SERIES IN UNITS OF CM/S/S\nNPTS= 4, DT= 0.01\n1 2 3 4\n")
    assert "line 2" in _at2_error(p)
    assert "not found" in _at2_error(tmp_path / "absent.at2")


# ---------------------------------------------------------------------------
# Recorded motions: processing and baseline correction
# ---------------------------------------------------------------------------
def assert_at_rest_outside(gm: GroundMotion):
    """z, z', z'' start at 0, return to 0 at the end and stay exactly 0 after."""
    T = gm.end
    for f, peak in ((gm.displacement, gm.peak_displacement), (gm.velocity, gm.peak_velocity)):
        assert f(0.0) == 0.0  # antiderivatives taken from t = 0: exact
        # End values come from a 2x2 solve and polynomial sums: round-off, ~1e-14 of the peak.
        assert abs(f(np.nextafter(T, 0.0))) <= 1e-11 * peak
    after = np.array([T, T + 1e-9, T + 3.0, 1e6])
    for f in (gm.displacement, gm.velocity, gm.acceleration):
        assert np.all(f(after) == 0.0)
        assert np.all(f(np.array([-1.0, -1e-9])) == 0.0)
    # The taper brings the acceleration itself to zero at both ends (round-off).
    assert abs(gm.acceleration(np.nextafter(T, 0.0))) <= 1e-12 * gm.peak_acceleration


def assert_antiderivatives_consistent(gm: GroundMotion, step: float):
    """z' is the integral of z'' and z that of z', checked by Simpson's rule."""
    t = np.arange(0.0, gm.end + step / 2, step)
    # At even points cumulative Simpson is the composite rule; step pairs never
    # straddle a knot (the grid step divides half the knot spacing).  It is exact
    # for the cubic z'' (round-off: 1e-9 of the peak); for the quartic z' it errs
    # by (h^4 / 180) int |z'^(4)| (measured <= 1.5e-8 of the peak: 1e-7).
    for upper, lower, peak, rel in (
        (gm.acceleration, gm.velocity, gm.peak_velocity, 1e-9),
        (gm.velocity, gm.displacement, gm.peak_displacement, 1e-7),
    ):
        integral = cumulative_simpson(upper(t), x=t, initial=0.0)[::2]
        np.testing.assert_allclose(integral, lower(t[::2]), rtol=0, atol=rel * peak)


def test_record_baseline_synthetic(tmp_path):
    gm = ground_motion(RecordedMotion(synthetic_record(tmp_path), scale=2.0, highpass=0.2, taper=0.5), 10.0)
    assert gm.end == pytest.approx(12.0, abs=1e-12)
    assert gm.duration == 10.0
    assert_at_rest_outside(gm)
    assert_antiderivatives_consistent(gm, 0.02 / 8)


def test_record_baseline_without_highpass_or_taper(tmp_path):
    gm = ground_motion(RecordedMotion(synthetic_record(tmp_path), highpass=0.0, taper=0.0), 5.0)
    T = gm.end
    for f, peak in ((gm.displacement, gm.peak_displacement), (gm.velocity, gm.peak_velocity)):
        assert abs(f(np.nextafter(T, 0.0))) <= 1e-11 * peak  # round-off, as above


def test_elcentro_table_motion(elcentro, elcentro_path):
    assert_at_rest_outside(elcentro)
    assert_antiderivatives_consistent(elcentro, 0.02 / 8)
    dt, raw = read_at2(elcentro_path)
    raw = raw * STANDARD_GRAVITY
    t = np.arange(raw.size) * dt
    diff = np.abs(elcentro.acceleration(t) - raw)
    pga = np.abs(raw).max()
    # The 1 s taper cuts the record's first motions (0.15 g at 0.46 s): 4.7 % of the peak.
    assert diff.max() <= 0.06 * pga
    # Past the 2 s baseline ramp only the 0.1 Hz high-pass acts: measured 0.4 %.
    assert diff[t >= 2.0].max() <= 0.01 * pga
    # The applied peak stays within 1 % of the record's (measured 3.139 vs 3.127 m/s^2).
    assert elcentro.peak_acceleration == pytest.approx(pga, rel=0.01)
    # Stroke and speed a large table provides (measured 0.214 m, 0.353 m/s).
    assert 0.1 < elcentro.peak_displacement < 0.3
    assert 0.25 < elcentro.peak_velocity < 0.45


def test_elcentro_scales_linearly_and_peaks_are_exact(elcentro, elcentro_path):
    small = ground_motion(RecordedMotion(elcentro_path, scale=0.05), 20.0)
    t = np.linspace(-1.0, 35.0, 5001)
    # Every processing step is linear in the scale: equal up to the round-off of
    # the recursive filter and the spline integrals (measured 2e-13 of the peak).
    np.testing.assert_allclose(small.displacement(t), 0.05 * elcentro.displacement(t),
                               rtol=0, atol=1e-12 * elcentro.peak_displacement)
    assert small.peak_displacement == pytest.approx(0.05 * elcentro.peak_displacement, rel=1e-10)
    dense = np.linspace(0.0, elcentro.end, 400_001)
    for f, peak in ((elcentro.displacement, elcentro.peak_displacement),
                    (elcentro.velocity, elcentro.peak_velocity),
                    (elcentro.acceleration, elcentro.peak_acceleration)):
        sampled = np.abs(f(dense)).max()
        # Exact peaks (breakpoints and roots) bound any sample from above; a
        # 78 us grid misses the peak by at most f'' dt^2 / 8, ~1e-6 of it.
        assert sampled <= peak * (1 + 1e-12)
        assert sampled >= peak * (1 - 1e-5)


def test_record_invalid_parameters(tmp_path):
    path = synthetic_record(tmp_path)
    for bad, key in (
        (RecordedMotion(path, highpass=30.0), "excitation.highpass"),  # Nyquist is 25 Hz
        (RecordedMotion(path, taper=6.5), "excitation.taper"),  # record is 12 s long
        (RecordedMotion(path, scale=-1.0), "excitation.scale"),
    ):
        with pytest.raises(ScenarioError, match=key) as info:
            ground_motion(bad, 10.0)
        assert str(path) in str(info.value)
    with pytest.raises(ScenarioError, match="not found"):
        ground_motion(RecordedMotion(tmp_path / "nope.at2"), 10.0)


# ---------------------------------------------------------------------------
# Band-limited noise
# ---------------------------------------------------------------------------
def test_noise_rms_and_band(noise):
    assert noise.end == 20.0
    t = np.arange(0.0, 20.0, 1e-3)
    acc = noise.acceleration(t)
    steady = (t >= 2.0) & (t <= 18.0)
    # The full-period stationary signal has RMS 0.5 exactly; the 16 s window of a
    # random multisine scatters by ~1.5 % (1 sigma) and the baseline ramps are
    # outside it: 5 % is > 3 sigma.  (Measured 0.8 % for this seed.)
    assert np.sqrt(np.mean(acc[steady] ** 2)) == pytest.approx(0.5, rel=0.05)
    power = np.abs(np.fft.rfft(acc)) ** 2
    f = np.fft.rfftfreq(t.size, 1e-3)
    in_band = power[(f >= 1.0) & (f <= 20.0)].sum() / power.sum()
    # Only the 1 s tapers and the baseline ramps leak out of the band: 0.04 %.
    assert in_band > 0.995


def test_noise_at_rest_and_consistent(noise):
    assert_at_rest_outside(noise)
    assert_antiderivatives_consistent(noise, 20.0 / 8000 / 4)  # knot spacing 1/400 s


def test_noise_is_deterministic(noise):
    t = np.linspace(0.0, 20.0, 4001)
    again = ground_motion(BandLimitedNoise(rms=0.5, band=(1.0, 20.0), seed=7), 20.0)
    assert np.array_equal(again.acceleration(t), noise.acceleration(t))
    assert np.array_equal(again.pieces[2].c, noise.pieces[2].c)
    other = ground_motion(BandLimitedNoise(rms=0.5, band=(1.0, 20.0), seed=8), 20.0)
    assert not np.allclose(other.acceleration(t), noise.acceleration(t))


@pytest.mark.parametrize(
    "bad, key",
    [
        (BandLimitedNoise(rms=0.5, band=(5.0, 1.0), seed=0), "excitation.band"),
        (BandLimitedNoise(rms=0.5, band=(1.01, 1.02), seed=0), "excitation.band"),  # < 1/duration
        (BandLimitedNoise(rms=-1.0, band=(1.0, 5.0), seed=0), "excitation.rms"),
        (BandLimitedNoise(rms=0.5, band=(1.0, 5.0), seed=-3), "excitation.seed"),
        (BandLimitedNoise(rms=0.5, band=(1.0, 5.0), seed=0, taper=11.0), "excitation.taper"),
    ],
)
def test_noise_invalid(bad, key):
    with pytest.raises(ScenarioError, match=key):
        ground_motion(bad, 20.0)


# ---------------------------------------------------------------------------
# Chirp
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("sweep", ["linear", "log"])
def test_chirp_sweeps_its_band(sweep):
    motion = ground_motion(Chirp(amplitude=0.2, f_start=0.5, f_end=10.0, sweep=sweep), 20.0)
    assert motion.end == 20.0
    assert_at_rest_outside(motion)
    t = np.arange(0.0, 20.0, 1e-3)
    acc = motion.acceleration(t)
    steady = (t >= 3.0) & (t <= 17.0)
    # A sine's peak is its amplitude; the 2 s baseline ramps lie outside the window and add a
    # correction of order 1e-3 m/s^2 at most, so 2 % of the amplitude bounds it.
    assert np.max(np.abs(acc[steady])) == pytest.approx(0.2, rel=0.02)
    # The instantaneous frequency, from the zero crossings of the first and last steady seconds,
    # follows the sweep law (a crossing count over 1 s resolves 0.5 Hz, hence the tolerance).
    def frequency(t0):
        window = acc[(t >= t0) & (t < t0 + 1.0)]
        return 0.5 * np.count_nonzero(np.diff(np.sign(window)))
    law = (lambda x: 0.5 + 9.5 * x / 20.0) if sweep == "linear" else (lambda x: 0.5 * 20.0 ** (x / 20.0))
    for t0 in (4.0, 15.0):
        assert frequency(t0) == pytest.approx(law(t0 + 0.5), abs=0.6)


@pytest.mark.parametrize("bad, key", [(Chirp(amplitude=-1.0, f_start=1.0, f_end=5.0), "excitation.amplitude"),
                                      (Chirp(amplitude=0.2, f_start=0.0, f_end=5.0), "excitation.f_start"),
                                      (Chirp(amplitude=0.2, f_start=1.0, f_end=5.0, sweep="cubic"),
                                       "excitation.sweep")])
def test_chirp_invalid(bad, key):
    with pytest.raises(ScenarioError, match=key):
        ground_motion(bad, 20.0)


def test_chirp_from_scenario_text():
    from momentid.lab.scenario import parse_scenario
    data = {"scenario": {"name": "c", "duration": 5.0, "sample_rate": 200.0},
            "structure": {"masses": [10.0, 10.0], "storey_stiffness": [2000.0, 2000.0],
                          "damping": {"damping_ratios": [0.02, 0.02], "modes": [1, 2]}},
            "excitation": {"type": "chirp", "amplitude": 0.3, "f_start": 1.0, "f_end": 8.0, "sweep": "log"},
            "runs": [{"added_mass": [0.0, 0.0]}]}
    assert parse_scenario(data).excitation == Chirp(amplitude=0.3, f_start=1.0, f_end=8.0, sweep="log")
