"""Sensor files of one run -> one run on one time base: clocks, shaking axis, sign, gravity.

Each sensor (an IMU on the table or on a floor) writes its own file with its
own clock, three axes in its own frame and gravity included.  For one run
:func:`align_sensors`

1. checks the sensors share a sample interval and that no two files hold
   the same data (the same export named twice);
2. per sensor, finds the gravity axis (largest mean) and the shaking axis:
   of the other two, the one with the most motion in :data:`ALIGN_BAND`,
   below the first mode of a bench-top model, where every floor follows the
   table (torsion and rocking live at the higher modes);
3. aligns every floor to the table: on the shared device clock when the
   clocks overlap and the data agree with them to :data:`CLOCK_AGREEMENT`
   samples, otherwise from the data (the lag of the largest band-limited
   cross-correlation with the table) and says so, with the shift; it refuses
   when neither clock nor data can align a sensor;
4. takes the sign of each floor from that correlation (below the first
   mode a floor moves with the table; the table sensor's own axis is the
   reference direction), keeps the span every sensor covers and removes
   each series' mean over it: gravity leaking into a tilted axis plus the
   sensor's static offset (a record that starts and ends at rest has zero
   mean acceleration).

What was done per sensor is a :class:`SensorReport`.
"""

from __future__ import annotations


import enum
from dataclasses import asdict, dataclass, field, replace

import numpy as np
from scipy import signal

from momentid.core.series import TABLE_MOTION
from momentid.errors import SensorDataError
from momentid.io.formats import SensorRecord

__all__ = ["Alignment", "SensorReport", "AlignedRun", "align_sensors", "ALIGN_BAND", "CLOCK_AGREEMENT",
           "MIN_ALIGN_CORRELATION", "STILL_RMS", "STILL_FRACTION", "MIN_ALIGN_PERIODS", "min_align_samples"]

#: Band (Hz) used to pick the shaking axis, estimate clock offsets and signs:
#: above the slow drift of an IMU's offset, below the first mode of a
#: bench-top shear model (3.7 Hz for the shipped flexible model), where each
#: floor moves in phase with the table (within 0.3 samples at 120 Hz there).
ALIGN_BAND = (0.3, 2.0)
#: Order of the Butterworth band-pass (applied forward and backward: zero phase).
FILTER_ORDER = 4
#: Largest difference (samples) between the clock's and the data's offset of
#: a sensor for the clock to be trusted: the floors' own phase lag in
#: :data:`ALIGN_BAND` is a fraction of a sample, a wrong clock is off by more.
CLOCK_AGREEMENT = 1.0
#: Smallest |correlation| with the table, in :data:`ALIGN_BAND` at the chosen
#: lag, for the data to align or sign a sensor: 0.96 on the shipped
#: unsynchronised trial, 0.99 on the synchronised ones; 0.8 leaves room for a
#: noisier rig while refusing a sensor that does not follow the table.
MIN_ALIGN_CORRELATION = 0.8
#: Smallest band-limited RMS (m/s^2) of the table's shaking axis for a run to
#: count as shaken: an idle Xsens DOT shows ~0.002 m/s^2 in ALIGN_BAND, the
#: gentlest shipped trial 0.12.
STILL_RMS = 0.01
#: Smallest band-limited RMS of a floor's shaking axis as a fraction of the
#: table's: below the first mode a floor moves at least as much as the table
#: (1.0-2.8 times on the shipped data), a loose or dead sensor far less.
STILL_FRACTION = 0.2
#: Clock drift (samples of lag gained over the shaking a sensor shares with the table) above which
#: it is resampled onto the table's clock with a note.  The floors' own phase in ALIGN_BAND moves
#: the lag as the motion's content changes: the shipped synchronised trials read 0.05-0.6 samples;
#: a clock 300 ppm fast reads 1.4 over their 60 s of shaking (15 deg of phase at the 17 Hz mode).
DRIFT_LIMIT = 1.0
#: Window (s) in which the lag is read to find the drift: a few of the slowest cycles of ALIGN_BAND.
DRIFT_WINDOW = 10.0
#: Largest clock drift (relative rate difference) read from the data or accepted from a device's
#: stamps: 1 % (10000 ppm), twice the 5000 ppm a cheap crystal oscillator can be off; a larger
#: difference is another sample rate, refused.
MAX_DRIFT = 0.01
#: Readings of a drift at most (the first and those of what is left after resampling).
DRIFT_PASSES = 4
#: How many standard errors of the lag's slope a drift must exceed (with more than three windows):
#: the floors' own phase wanders with the motion's content, a clock drifts steadily.
DRIFT_SIGNIFICANCE = 3.0
#: Largest relative difference between two sensors' sample intervals.
STEP_TOLERANCE = 1e-3
#: Fewest periods of the lowest frequency of :data:`ALIGN_BAND` a sensor's record must span: the
#: shaking axis, sign and clock offset are read from the motion in that band, and fewer than two of
#: its slowest cycles (6.7 s) cannot tell motion from drift; the zero-phase band-pass also needs its
#: edge transients (a few periods of the band edges) to die out inside the record.
MIN_ALIGN_PERIODS = 2.0


class Alignment(enum.Enum):
    """How a sensor was put on the table's time base."""

    REFERENCE = "reference"   # the table sensor itself
    CLOCK = "clock"           # the shared device clock, confirmed by the data
    DATA = "data"             # the data's cross-correlation with the table


@dataclass(frozen=True)
class SensorReport:
    """What the import did with one sensor's file.

    Attributes
    ----------
    channel : str
        The channel it became (``"zdd"``, ``"a1"``, ...).
    file : str
        The file read.
    axis : str
        The sensor axis along the shaking direction.
    sign : int
        +1, or -1 for a sensor mounted reversed (relative to the table's).
    gravity_axis : str
        The axis carrying gravity; ``gravity`` its mean (m/s^2).
    gravity : float
    offset : float
        Mean of the shaking axis (m/s^2, sensor sign) removed: tilt and bias.
    start : float
        Time (s) of the sensor's first sample on the table's time base.
    alignment : Alignment
    clock_error : float
        Data-minus-clock offset (s) when the clocks overlap; nan otherwise.
    correlation : float
        Correlation with the table in :data:`ALIGN_BAND` at the chosen lag
        (1 for the table).
    missing : int
        Samples missing (``nan``) in the kept span.
    notes : tuple of str
        Anything unusual, one sentence each.
    """

    channel: str
    file: str
    axis: str
    sign: int
    gravity_axis: str
    gravity: float
    offset: float
    start: float
    alignment: Alignment
    clock_error: float
    correlation: float
    missing: int
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        """The report as a JSON-ready dict (``alignment`` by its value); :meth:`from_dict` reads it back."""
        out = asdict(self)
        out["alignment"] = self.alignment.value
        out["notes"] = list(self.notes)
        return out

    @classmethod
    def from_dict(cls, data: dict) -> SensorReport:
        """The report of a :meth:`to_dict` dict (a ``clock_error`` of None is nan)."""
        fields = dict(data, alignment=Alignment(data["alignment"]), notes=tuple(data.get("notes", ())))
        fields["clock_error"] = float("nan") if fields["clock_error"] is None else fields["clock_error"]
        return cls(**fields)

    def line(self) -> str:
        """One line for the import report."""
        sign = "+" if self.sign > 0 else "-"
        how = {Alignment.REFERENCE: "the reference (time and direction)",
               Alignment.CLOCK: (f"shared clock, confirmed by the data to {self.clock_error * 1e3:+.1f} ms "
                                 f"(r = {self.correlation:+.2f})" if self.correlation >= MIN_ALIGN_CORRELATION
                                 else "shared clock, which the data cannot confirm"),
               Alignment.DATA: f"aligned from the data (r = {self.correlation:+.2f})"}[self.alignment]
        text = (f"{self.channel:>3}: axis {sign}{self.axis}, gravity {self.gravity:+.2f} m/s^2 on "
                f"{self.gravity_axis}, offset {self.offset:+.3f} m/s^2 removed, starts at "
                f"{self.start:+.4f} s, {how}")
        return "; ".join([text, *self.notes])


@dataclass(frozen=True)
class AlignedRun:
    """Sensors of one run on one time base.

    Attributes
    ----------
    time : ndarray, shape (n,)
        s, from 0 at the sensors' sample interval.
    values : ndarray, shape (n, c)
        Shaking-direction accelerations (m/s^2), sign-corrected, mean removed.
    reports : tuple of SensorReport, length c
    notes : tuple of str
        Run-level notes (span trimmed to the common part, ...).
    stamp_delays : dict
        Per floor channel whose stamps overlap the table's and whose data align it (|r| >=
        :data:`MIN_ALIGN_CORRELATION`) away from a periodic ambiguity: how many samples (sub-sample) its
        data lag the position its stamps give (:func:`momentid.io.delays.common_delays` reads them
        across runs).
    motion : dict
        The table sensor's other motions on the same samples (:data:`TABLE_MOTION` names, mean removed): its
        acceleration across the shaking axis and along gravity (m/s^2), and, when its export has them, its
        angular rates about the shaking, the cross and the gravity axis (rad/s).
    """

    time: np.ndarray
    values: np.ndarray
    reports: tuple[SensorReport, ...]
    notes: tuple[str, ...]
    stamp_delays: dict = field(default_factory=dict)
    motion: dict = field(default_factory=dict)


def _filled(x: np.ndarray) -> np.ndarray:
    """``x`` with nan samples linearly interpolated (for filtering only)."""
    bad = np.isnan(x)
    if not bad.any():
        return x
    good = np.flatnonzero(~bad)
    if good.size < 2:
        return np.zeros_like(x)
    out = x.copy()
    out[bad] = np.interp(np.flatnonzero(bad), good, x[good])
    return out


def _band(x: np.ndarray, step: float) -> np.ndarray:
    """``x`` (n,) or (n, k), mean removed, band-passed to :data:`ALIGN_BAND` with zero phase."""
    nyquist = 0.5 / step
    if not ALIGN_BAND[1] < nyquist:
        raise SensorDataError(f"sample rate {1 / step:.4g} Hz: expected above {2 * ALIGN_BAND[1]:g} Hz to "
                              f"align and sign sensors in the {ALIGN_BAND[0]:g}-{ALIGN_BAND[1]:g} Hz band")
    sos = signal.butter(FILTER_ORDER, ALIGN_BAND, btype="band", fs=1 / step, output="sos")
    x = np.apply_along_axis(_filled, 0, x)
    return signal.sosfiltfilt(sos, x - np.mean(x, axis=0), axis=0)


def _lag(table: np.ndarray, floor: np.ndarray, near: float | None = None,
         reach: float = CLOCK_AGREEMENT + 1) -> tuple[float, float]:
    """Lag L (samples, sub-sample) with ``floor[i + L] ~ table[i]`` and the correlation there.

    With ``near`` (a lag the shared clock gives), only lags within ``reach`` samples (default
    :data:`CLOCK_AGREEMENT` + 1) of it are candidates and each is normalised by the two records' energy over the samples
    they share at that lag: a record that stops early (a table sensor that died halfway) is then judged on
    what it recorded, not against a lag where a periodic motion matches more samples.
    """
    xc = signal.correlate(floor, table, mode="full", method="fft")
    lags = signal.correlation_lags(floor.size, table.size, mode="full")
    if near is None:
        norm = np.full(xc.shape, np.sqrt(np.sum(table ** 2) * np.sum(floor ** 2)))
        candidate = norm > 0
    else:
        lo = np.clip(-lags, 0, table.size)             # the table samples shared at each lag: lo..hi
        hi = np.clip(floor.size - lags, lo, table.size)
        energy_t = np.concatenate([[0.0], np.cumsum(table ** 2)])
        energy_f = np.concatenate([[0.0], np.cumsum(floor ** 2)])
        norm = np.sqrt((energy_t[hi] - energy_t[lo]) * (energy_f[hi + lags] - energy_f[lo + lags]))
        candidate = (np.abs(lags - near) <= reach) & (hi - lo >= 3) & (norm > 0)
    if not candidate.any():
        return float(lags[0] if near is None else near), 0.0
    r = np.where(candidate, xc / np.where(candidate, norm, 1.0), 0.0)
    i = int(np.argmax(np.abs(r)))
    if near is not None and not (0 < i < r.size - 1 and candidate[i - 1] and candidate[i + 1]):
        return float(lags[i]), 0.0  # the best lag near the clock's is at the window's edge: no peak there
    frac = 0.0
    if 0 < i < r.size - 1 and candidate[i - 1] and candidate[i + 1]:  # parabola through the peak and its neighbours
        y0, y1, y2 = np.abs(r[i - 1:i + 2])
        curvature = y0 - 2 * y1 + y2
        frac = 0.5 * (y0 - y2) / curvature if curvature < 0 else 0.0
    return lags[i] + frac, float(r[i])


def min_align_samples(step: float) -> int:
    """Fewest samples (at interval ``step``, s) a sensor record needs to be aligned: :data:`MIN_ALIGN_PERIODS`
    periods of the lowest frequency of :data:`ALIGN_BAND`."""
    return int(np.ceil(MIN_ALIGN_PERIODS / ALIGN_BAND[0] / step))


def _check_length(records: list[SensorRecord], step: float) -> None:
    need = min_align_samples(step)
    for rec in records:
        if rec.acc.shape[0] < need:
            raise SensorDataError(
                f"{rec.path}: {rec.acc.shape[0]} samples ({rec.acc.shape[0] * step:.3g} s); expected at least "
                f"{need} ({need * step:.3g} s, {MIN_ALIGN_PERIODS:g} periods of {ALIGN_BAND[0]:g} Hz): the "
                f"shaking axis, sign and clock of each sensor are read from its motion at "
                f"{ALIGN_BAND[0]:g}-{ALIGN_BAND[1]:g} Hz, which a shorter record cannot tell from drift")


def _check_distinct(records: list[SensorRecord]) -> None:
    for i, a in enumerate(records):
        for b in records[i + 1:]:
            if a.acc.shape == b.acc.shape and np.array_equal(a.acc, b.acc, equal_nan=True):
                raise SensorDataError(f"{b.path}: the same accelerations as {a.path}; expected one file "
                                      f"per sensor (the same export named twice?)")


def _axes(rec: SensorRecord, step: float) -> tuple[int, int, np.ndarray]:
    """(gravity axis, shaking axis, band-limited shaking signal) of one sensor."""
    if np.all(np.isnan(rec.acc)):
        raise SensorDataError(f"{rec.path}: every sample is missing (nan); expected accelerations")
    means = np.nanmean(rec.acc, axis=0)
    g = int(np.argmax(np.abs(means)))
    others = [k for k in range(rec.acc.shape[1]) if k != g]
    band = _band(rec.acc[:, others], step)
    rms = np.sqrt(np.mean(band ** 2, axis=0))
    j = int(np.argmax(rms))
    return g, others[j], band[:, j]


def align_sensors(records: list[SensorRecord], channels: tuple[str, ...],
                  delays: dict | None = None) -> AlignedRun:
    """Put one run's sensor files on the table's time base along the shaking direction.

    Parameters
    ----------
    records : list of SensorRecord, length c
        The table sensor first, then floor 1 .. d.
    channels : tuple of str, length c
        Their channel names (``("zdd", "a1", ..., "ad")``).
    delays : dict, optional
        Per floor channel, ``(samples, note)``: the delay of its data behind its stamps that the
        other runs of the experiment agree on (:func:`~momentid.io.delays.common_delays`), applied to its stamps before
        the data confirm them, with the note.

    Returns
    -------
    AlignedRun

    Raises
    ------
    SensorDataError
        A one-line reason: different sample intervals, a record too short to
        read its axes (:func:`min_align_samples`), a duplicated file, a
        sensor that does not move, clocks that do not overlap and data that
        cannot align a sensor, no common span.
    """
    step = records[0].step
    records = [records[0], *(_on_table_rate(rec, records[0]) for rec in records[1:])]
    _check_distinct(records)
    _check_length(records, step)
    axes = [_axes(rec, step) for rec in records]
    table_rms = float(np.sqrt(np.mean(axes[0][2] ** 2)))
    if table_rms < STILL_RMS:
        raise SensorDataError(f"{records[0].path}: the table does not move ({table_rms:.3g} m/s^2 RMS in "
                              f"{ALIGN_BAND[0]:g}-{ALIGN_BAND[1]:g} Hz on its most active axis); expected "
                              f"at least {STILL_RMS:g} m/s^2")
    links = [_Link(start=0, alignment=Alignment.REFERENCE, correlation=1.0, clock_error=float("nan"))]
    for rec, ch, (_, _, band) in zip(records[1:], channels[1:], axes[1:]):
        rms = float(np.sqrt(np.mean(band ** 2)))
        if rms < STILL_FRACTION * table_rms:
            raise SensorDataError(f"{rec.path}: sensor {ch} does not move ({rms:.3g} m/s^2 RMS in "
                                  f"{ALIGN_BAND[0]:g}-{ALIGN_BAND[1]:g} Hz, the table {table_rms:.3g}); "
                                  f"expected a sensor fixed to the floor, moving with the table")
        links.append(_offset(records[0], rec, ch, axes[0][2], band, step, (delays or {}).get(ch)))
    records, links = _correct_drift(records, axes, links, step)
    aligned = _assemble(records, channels, axes, links, step)
    found = {ch: link.stamp_delay for ch, link in zip(channels, links) if np.isfinite(link.stamp_delay)}
    return replace(aligned, stamp_delays=found)


def _on_table_rate(rec: SensorRecord, table: SensorRecord) -> SensorRecord:
    """``rec`` on the table's sample interval: as it is when its stamps give the same interval (to
    :data:`STEP_TOLERANCE`), resampled by its stamps (linear interpolation, with a note naming the
    ppm) when they give one up to :data:`MAX_DRIFT` off (a device sampling at its own rate, as its
    stamps say), refused beyond."""
    rate = rec.step / table.step - 1
    if abs(rate) <= STEP_TOLERANCE:
        return rec
    if abs(rate) > MAX_DRIFT:
        raise SensorDataError(f"{rec.path}: sample interval {rec.step:.6g} s differs from {table.step:.6g} s of "
                              f"{table.path} by {rate * 1e6:+.0f} ppm; expected sensors at one rate (a clock "
                              f"drift of up to {MAX_DRIFT * 1e6:.0f} ppm is resampled)")
    grid = rec.time[0] + np.arange(int(np.floor((rec.time[-1] - rec.time[0]) / table.step)) + 1) * table.step
    acc = np.column_stack([np.interp(grid, rec.time, _filled(rec.acc[:, j])) for j in range(rec.acc.shape[1])])
    for j in range(rec.acc.shape[1]):   # a sample missing in the file stays missing
        gone = np.isnan(rec.acc[:, j])
        if gone.any():
            near = np.searchsorted(rec.time, grid).clip(1, rec.time.size - 1)
            acc[gone[near] | gone[near - 1], j] = np.nan
    note = (f"its stamps give a sample interval of {rec.step * 1e6:.1f} us against the table's "
            f"{table.step * 1e6:.1f} us ({rate * 1e6:+.0f} ppm): resampled onto the table's clock by its stamps")
    return replace(rec, time=grid, step=table.step, acc=acc, notes=rec.notes + (note,), rates=None)


def _correct_drift(records: list, axes: list, links: list, step: float) -> tuple[list, list]:
    """Each floor sensor whose clock drifts from the table's by more than :data:`DRIFT_LIMIT` samples
    over the span they share, resampled onto the table's clock, with a note naming the drift.

    The drift is read again on the resampled record, up to :data:`DRIFT_PASSES` times, until what is
    left is under a tenth of a sample over the span: a lag read in windows of a drifting record
    comes out a few tens of percent short at thousands of ppm (the window's correlation averages a
    lag that moves within it), and each pass takes most of what is left."""
    records, links = list(records), list(links)
    table_band = axes[0][2]
    for k in range(1, len(records)):
        rec, link, band = records[k], links[k], axes[k][2]
        drift = _drift(table_band, band, link.start, step)
        if drift is None or abs(drift[0] * drift[1]) <= DRIFT_LIMIT:
            continue
        rate, span, centre = drift
        for _ in range(DRIFT_PASSES - 1):
            fixed = _dedrift(rec, rate, link.start, centre)
            left = _drift(table_band, _band(fixed.acc[:, [axes[k][1]]], step)[:, 0], link.start, step)
            if left is None or abs(left[0] * span) <= 0.1:
                break
            rate += left[0]
        records[k] = _dedrift(rec, rate, link.start, centre)
        note = (f"its clock drifts from the table's by {rate * 1e6:+.0f} ppm ({rate * span:+.1f} samples over "
                f"the {span * step:.0f} s of shaking, read from the lag in {DRIFT_WINDOW:g} s windows): "
                f"resampled onto the table's clock")
        links[k] = replace(link, notes=link.notes + (note,))
    return records, links


@dataclass(frozen=True)
class _Link:
    """How one sensor joins the table: its first sample's index on the table's grid, how that was
    found, the band-limited correlation with the table there (its sign is the sensor's), the clock's
    error (s; nan without an overlapping clock) and notes."""

    start: int
    alignment: Alignment
    correlation: float
    clock_error: float
    notes: tuple[str, ...] = ()
    stamp_delay: float = float("nan")   # samples the data lag the stamps (nan: not read)

    @property
    def sign(self) -> int:
        return 1 if self.correlation > 0 else -1


def _offset(table: SensorRecord, rec: SensorRecord, ch: str, table_band: np.ndarray, band: np.ndarray,
            step: float, delay: tuple | None = None) -> _Link:
    """How ``rec`` joins the table: the shared clock if the data agree, else the data.

    With ``delay = (samples, note)`` (the experiment's delay of this sensor's data behind its stamps)
    the stamps are shifted by it first.  A sign is only ever taken from data that confirm it: where
    they cannot, the sensor keeps the sign of its file and the note says so.  Data that put the sensor
    a whole or half period of a repeating table motion away from its stamps cannot tell the two
    apart: the stamps are kept."""
    lag, corr = _lag(table_band, band)
    data_start = int(round(-lag))
    overlap = min(table.time[-1], rec.time[-1]) - max(table.time[0], rec.time[0])
    reliable = abs(corr) >= MIN_ALIGN_CORRELATION
    if overlap > 0:  # a shared clock: trust it if the data agree
        stamps = (rec.time[0] - table.time[0]) / step
        shift, shifted = (0.0, ()) if delay is None else (delay[0], (delay[1],))
        clock_start = int(round(stamps + shift))
        near_lag, near_corr = _lag(table_band, band, near=-clock_start)
        if abs(near_corr) >= MIN_ALIGN_CORRELATION:  # the data confirm the clock where both recorded
            lag, corr, reliable = near_lag, near_corr, True
        error = (-lag - clock_start) * step
        periodic = reliable and _repeats(table_band, -lag - clock_start, step)
        found = -lag - stamps if reliable and not periodic else float("nan")
        if abs(-lag - clock_start) <= CLOCK_AGREEMENT or not reliable or periodic:
            notes = shifted
            if periodic:
                notes += (f"its data fit as well {-lag - clock_start:+.1f} samples from its stamps (r = {corr:+.2f}): "
                          f"the table's motion repeats there, so the data cannot decide: its stamps are kept and "
                          f"its clock and sign unchecked",)
            elif not reliable:
                notes += (f"the data cannot confirm the clock (r = {corr:+.2f} with the table): its clock is "
                          f"unchecked and its sign kept as the file's, unchecked",)
            sign = corr if reliable and not periodic else abs(corr)   # a sign the data do not confirm is kept
            return _Link(clock_start, Alignment.CLOCK, sign, error, notes, found)
        note = (f"its clock disagrees with the data by {error:+.4f} s ({-lag - clock_start:+.1f} samples): "
                f"aligned from the data")
        return _Link(data_start, Alignment.DATA, corr, error, shifted + (note,), found)
    if not reliable:
        raise SensorDataError(f"{rec.path}: sensor {ch}'s clock does not overlap the table's and its data "
                              f"correlate weakly with the table (r = {corr:+.2f}, expected |r| >= "
                              f"{MIN_ALIGN_CORRELATION}); cannot align it")
    note = f"its clock does not overlap the table's: offset {data_start * step:+.4f} s estimated"
    return _Link(data_start, Alignment.DATA, corr, float("nan"), (note,))


def _repeats(table_band: np.ndarray, shift: float, step: float) -> bool:
    """Whether the table's band-limited motion shifted by ``shift`` samples matches itself (|r| >=
    :data:`MIN_ALIGN_CORRELATION`) although the shift exceeds a quarter period of the band's top
    frequency: a repeating motion (a sine), whose lag the data give only up to its period."""
    s = int(round(abs(shift)))
    if s < 0.25 / (ALIGN_BAND[1] * step) or s >= table_band.size // 2:
        return False
    a, b = table_band[:-s], table_band[s:]
    r = float(np.dot(a, b) / np.sqrt(np.dot(a, a) * np.dot(b, b)))
    return abs(r) >= MIN_ALIGN_CORRELATION


def _drift(table_band: np.ndarray, band: np.ndarray, start: int, step: float) -> tuple[float, int, float] | None:
    """The sensor's clock drift against the table's (samples of lag gained per sample), the span
    (samples) it was read over and that span's centre (an index of the table's grid).

    The lag is read in windows of :data:`DRIFT_WINDOW` s of the span both recorded, from the middle
    window outwards, each near the lag its inner neighbour predicts (within what a drift of
    :data:`MAX_DRIFT` adds over a window): a drift of thousands of ppm moves the lag by several
    samples from one window to the next, more than a search around the record's mean lag reaches,
    yet never by a half period of a repeating table motion.  Only windows where the data confirm the
    lag (|r| >= :data:`MIN_ALIGN_CORRELATION`: not a quiet lead-in or tail) count; the drift is the
    slope of a line through their lags, and None is returned with fewer than three such windows or
    a slope within three of its standard errors of zero (the floors' own phase moving with the
    motion's content, not a clock)."""
    lo, hi = max(0, start), min(table_band.size, start + band.size)
    width = max(int(DRIFT_WINDOW / step), min_align_samples(step))
    starts = list(range(lo, hi - width + 1, width))
    if len(starts) < 3:
        return None
    middle = len(starts) // 2
    reach = CLOCK_AGREEMENT + 1 + MAX_DRIFT * width
    read: dict[int, float] = {}

    def window(i: int, near: float) -> float | None:
        a = starts[i]
        lag, corr = _lag(table_band[a:a + width], band[a - start:a - start + width], near=near, reach=reach)
        if abs(corr) < MIN_ALIGN_CORRELATION:
            return None
        read[i] = lag
        return lag

    for side in (range(middle, len(starts)), range(middle - 1, -1, -1)):
        known: list[tuple[int, float]] = [(middle, read[middle])] if middle in read else []
        for i in side:
            if i in read:
                continue
            if len(known) >= 2:   # the line through the two nearest confirmed windows
                (i1, l1), (i2, l2) = known[-2], known[-1]
                near = l2 + (l2 - l1) / (i2 - i1) * (i - i2)
            else:
                near = known[-1][1] if known else 0.0
            lag = window(i, near)
            if lag is not None:
                known.append((i, lag))
    if len(read) < 3:
        return None
    index = sorted(read)
    centres = np.array([starts[i] + 0.5 * width for i in index])
    lags = np.array([read[i] for i in index])
    coef, cov = np.polyfit(centres, lags, 1, cov=True) if len(lags) > 3 else (np.polyfit(centres, lags, 1), None)
    if cov is not None and abs(coef[0]) < DRIFT_SIGNIFICANCE * np.sqrt(max(cov[0, 0], 0.0)):
        return None
    return float(coef[0]), int(centres[-1] - centres[0] + width), float(np.mean(centres))


def _dedrift(rec: SensorRecord, rate: float, start: int, centre: float) -> SensorRecord:
    """``rec`` resampled so that its lag to the table no longer grows by ``rate`` per sample; the lag
    at ``centre`` (the table grid's index where the drift was read) is kept: the offset stays as read."""
    centre = centre - start
    k = np.arange(rec.acc.shape[0], dtype=float)
    source = k + rate * (k - centre)
    acc = np.column_stack([np.interp(source, k, rec.acc[:, j], left=np.nan, right=np.nan)
                           for j in range(rec.acc.shape[1])])
    return replace(rec, acc=acc, rates=None)


def _assemble(records: list[SensorRecord], channels: tuple[str, ...], axes: list, links: list[_Link],
              step: float) -> AlignedRun:
    """Cut every sensor to the common span, orient it and remove its mean; report what was done."""
    starts = [link.start for link in links]
    lo = max(starts)
    hi = min(s + rec.acc.shape[0] for s, rec in zip(starts, records))
    if hi - lo < 3:
        raise SensorDataError(f"{records[0].path}: the sensors share {max(hi - lo, 0)} samples once aligned; "
                              f"expected recordings that overlap in time")
    notes = []
    cut = {ch: (lo - s, s + r.acc.shape[0] - hi) for ch, s, r in zip(channels, starts, records)}
    if any(a or b for a, b in cut.values()):
        dropped = ", ".join(f"{ch} {a}+{b}" for ch, (a, b) in cut.items() if a or b)
        notes.append(f"sensors cover different spans: kept the {hi - lo} samples every sensor covers "
                     f"(dropped at start+end: {dropped})")
    values = np.empty((hi - lo, len(records)))
    reports = []
    for k, (rec, ch, (g, j, _), link) in enumerate(zip(records, channels, axes, links)):
        start, sign = link.start, link.sign
        series = rec.acc[lo - start:hi - start, j]
        offset = float(np.nanmean(series))
        values[:, k] = sign * (series - offset)
        missing = int(np.isnan(series).sum())
        extra = list(rec.notes) + list(link.notes)
        if sign < 0:
            extra.append("mounted reversed: sign flipped")
        if missing:
            first = int(np.flatnonzero(np.isnan(series))[0])
            extra.append(f"{missing} samples missing (nan) from t = {first * step:.3f} s: kept as nan")
        reports.append(SensorReport(
            channel=ch, file=str(rec.path), axis=rec.axes[j], sign=sign, gravity_axis=rec.axes[g],
            gravity=float(np.nanmean(rec.acc[:, g])), offset=offset, start=(start - lo) * step,
            alignment=link.alignment, clock_error=link.clock_error, correlation=abs(link.correlation),
            missing=missing,
            notes=tuple(extra)))
    time = np.arange(hi - lo) * step
    motion = _table_motion(records[0], axes[0], slice(lo - starts[0], hi - starts[0]))
    return AlignedRun(time=time, values=values, reports=tuple(reports), notes=tuple(notes), motion=motion)


def _table_motion(table: SensorRecord, axes: tuple, span: slice) -> dict:
    """The table sensor's :data:`TABLE_MOTION` over ``span`` of its samples, each less its mean: the
    accelerations across the shaking axis and along gravity, then (when read) the angular rates about the
    shaking, cross and gravity axes (the sensor's own signs: the twin fits a gain to each)."""
    g, j, _ = axes
    cross = next(k for k in range(table.acc.shape[1]) if k not in (g, j))
    columns = [table.acc[span, cross], table.acc[span, g]]
    if table.rates is not None:
        columns += [table.rates[span, j], table.rates[span, cross], table.rates[span, g]]
    return {name: x - np.nanmean(x) for name, x in zip(TABLE_MOTION, columns)}
