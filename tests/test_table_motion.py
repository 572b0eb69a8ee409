"""The table sensor's other motions: read from an Xsens DOT export (rates in rad/s, dropped with a note
when they cannot be read), and the twin driven by them through gains it fits."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.signal

from momentid.core.series import TABLE_MOTION
from momentid.errors import IdentificationError
from momentid.io.formats.xsens_dot import read_xsens_dot
from momentid.twin import fit as twin_fit

PREAMBLE = ("sep=,\nDeviceTag:,Xsens DOT\nFirmwareVersion:,3.0.0\nAppVersion:,2023.6.0\n"
            "StartTime: ,2025-03-06_12:21:16_000 PST\n\u00a9 Movella Technologies B. V. 2005-2025\n\n")
HEADER = "PacketCounter,SampleTimeFine,Euler_X,Euler_Y,Euler_Z,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z"
STEP_US, N_ROWS = 8333, 60


def _export(path, gyro_cell=lambda k, j, v: f"{v:.6f}"):
    """A DOT export of ``N_ROWS`` rows: X motion, gravity on Z, angular rates ``(k, 2k, -k) / 10`` deg/s
    written by ``gyro_cell(row, axis, value)``."""
    rows = []
    for k in range(N_ROWS):
        rates = [k / 10, 2 * k / 10, -k / 10]
        cells = ",".join(gyro_cell(k, j, v) for j, v in enumerate(rates))
        rows.append(f"{k},{1000 + k * STEP_US},0,0,0,{0.1 * np.sin(k / 3):.6f},0.01,9.81,{cells}")
    path.write_text(PREAMBLE + HEADER + "\n" + "\n".join(rows) + "\n")
    return path


def test_angular_rates_are_read_in_radians_per_second(tmp_path):
    record = read_xsens_dot(_export(tmp_path / "t.csv"))
    k = np.arange(N_ROWS)
    # the file writes deg/s to 6 decimals: the same rates in rad/s to the rounding (5e-7 deg/s)
    assert np.allclose(record.rates, np.column_stack([k, 2 * k, -k]) / 10 * np.pi / 180, rtol=0, atol=1e-8)


def test_a_long_gap_in_the_rates_drops_them_and_keeps_the_accelerations(tmp_path):
    # 8 empty Gyr_Y cells in a row (more than the 5 a reader interpolates): no rates, a note, the
    # accelerations read as ever
    def cell(k, j, v):
        return "" if j == 1 and 20 <= k < 28 else f"{v:.6f}"

    record = read_xsens_dot(_export(tmp_path / "t.csv", cell))
    assert record.rates is None and record.acc.shape == (N_ROWS, 3)
    assert any("angular rates not read" in note for note in record.notes)


def test_a_short_gap_in_the_rates_is_interpolated_with_a_note(tmp_path):
    def cell(k, j, v):
        return "" if j == 2 and k == 30 else f"{v:.6f}"

    record = read_xsens_dot(_export(tmp_path / "t.csv", cell))
    # Gyr_Z is a straight line in the row: interpolation gives it back to the written rounding
    assert record.rates[30, 2] == pytest.approx(-3.0 * np.pi / 180, abs=1e-8)
    assert any("Gyr_Z" in note for note in record.notes)


def _trial(seed: int, n: int = 2400, dt: float = 1 / 120) -> twin_fit.Trial:
    """A trial of a 1-storey rig: band-limited table shaking after a 1 s quiet lead-in, two table motions
    (the floors are filled in by the caller)."""
    rng = np.random.default_rng(seed)
    b, a = scipy.signal.butter(2, [0.5 / 60, 30 / 60], "band")
    lead = 120
    def shaking():
        return np.concatenate([np.zeros(lead), scipy.signal.lfilter(b, a, rng.standard_normal(n - lead))])

    zdd = shaking()
    motion = np.column_stack([shaking() for _ in range(2)])
    return twin_fit.Trial(f"t{seed}", zdd, np.zeros((n, 1)), dt, lead, n, 1.0, 0.2 * motion, TABLE_MOTION[:2])


def test_the_twin_fits_the_gains_of_the_table_motions_that_drive_it():
    truth = twin_fit.FittedRig(np.array([0.2]), np.array([[3000.0]]), np.array([0.01]), table_motion=TABLE_MOTION[:2],
                               table_gains=np.array([-0.5, 0.3]))
    trials = []
    for seed in (1, 2):
        tr = _trial(seed)
        a = twin_fit.predict(truth, tr)
        active = a[tr.start:]
        trials.append(replace(tr, a=a, norm=float(np.sqrt(np.sum((active - active.mean(axis=0)) ** 2)))))
    start = replace(truth, stiffness=np.array([[2900.0]]), table_gains=np.zeros(2))
    fit = twin_fit.fit_twin(trials, start)
    # noise-free data of the same model: the gains come back to the optimiser's tolerance (1e-6 relative
    # cost); 1e-3 is far below the 0.3-0.5 they are and far above round-off
    assert np.allclose(fit.model.table_gains, truth.table_gains, atol=1e-3)
    assert max(fit.nrmse.values()) < 1e-3
    # held (fit_motion=False, as the physics candidates are fitted), the gains stay as started, to the bit
    held = twin_fit.fit_twin(trials, replace(start, table_gains=np.array([-0.4, 0.2])), fit_motion=False)
    assert held.model.table_gains.tolist() == [-0.4, 0.2]
    # without the motions the same fit cannot explain the floors
    alone = twin_fit.fit_twin(trials, replace(start, table_motion=(), table_gains=np.zeros(0)))
    assert min(alone.nrmse.values()) > 0.1


def test_a_trial_without_the_motions_is_refused_by_a_twin_driven_by_them():
    model = twin_fit.FittedRig(np.array([0.2]), np.array([[3000.0]]), np.array([0.01]), table_motion=("table_wy",))
    tr = _trial(3)
    with pytest.raises(IdentificationError, match="table_wy"):
        model.drive(tr)
    with pytest.raises(ValueError, match="one gain per motion"):
        replace(model, table_gains=np.zeros(2))


def test_motions_that_do_not_drive_the_rig_drive_no_candidate():
    # three trials of a linear rig whose two table motions are unrelated noise: the twin driven by them
    # fits their gains to the training trials and predicts the inner held-out trial no better (not within
    # MOTION_RATIO): no candidate is driven by them
    from momentid.diagnosis.twin import folds

    truth = twin_fit.FittedRig(np.array([0.2]), np.array([[3000.0]]), np.array([0.01]))
    rng = np.random.default_rng(5)
    trials = {}
    for seed, scale in ((11, 0.5), (12, 1.0), (13, 2.0)):
        tr = _trial(seed)
        tr = replace(tr, zdd=scale * tr.zdd)
        a = twin_fit.predict(truth, tr)
        a = a + rng.normal(0.0, 0.01 * np.std(a), a.shape)          # 1 % sensor noise
        active = a[tr.start:]
        trials[tr.name] = replace(tr, a=a, norm=float(np.sqrt(np.sum((active - active.mean(axis=0)) ** 2))))
    start = replace(truth, stiffness=np.array([[2950.0]]))
    best, inner, table = folds.select(trials, list(trials), max_nfev=10, augmented_nfev=3, start=start)
    assert table["table_motion"]["ratio_to_linear"] > folds.MOTION_RATIO, table
    assert not best.motion and not any(n.endswith("+table_motion") for n in table), table


@pytest.mark.parametrize("linear", [True, False])
def test_one_drive_per_model_simulates_as_each_alone(linear):
    # resim.simulate with a table drive per model (the Jacobian's nudged motions in one rollout) reads
    # what each model reads under its own drive alone: the same arithmetic, to round-off
    from momentid.lab import resim

    model = twin_fit.FittedRig(np.array([0.2]), np.array([[3000.0]]), np.array([0.01]))
    tr = _trial(4, n=600)
    dt, substeps = tr.dt, resim.substeps_for(tr.dt)
    compiled = resim.compile_models([model.rig()] * 2, dt / substeps)
    drives = np.stack([tr.zdd, tr.zdd + tr.motion[:, 0]])
    together = resim.simulate(compiled, drives, dt, substeps, linear=linear)
    for k in range(2):
        alone = resim.simulate(compiled[:1], drives[k], dt, substeps, linear=linear)[0]
        assert np.allclose(together[k], alone, rtol=0, atol=1e-12 * np.max(np.abs(alone)))
    assert not np.allclose(together[0], together[1])


def test_a_motion_column_of_zeros_is_no_motion():
    # an export that writes its angular rates as zeros (the bad-input suite's synthetic DOT files do): the
    # twin is not offered a motion that never moves (its gain would be undetermined)
    from momentid.diagnosis.twin import folds

    tr = _trial(6)
    zero = replace(tr, motion=np.column_stack([tr.motion[:, 0], np.zeros(len(tr.zdd))]))
    assert folds.table_motion([tr, tr]) == TABLE_MOTION[:2]
    assert folds.table_motion([tr, zero]) == TABLE_MOTION[:1]


def test_a_run_file_may_carry_the_table_motions(tmp_path):
    # the CSV run format takes the table's other motions as optional columns (SI units), as the IMU import
    # writes them; an unknown column is still refused
    from momentid.errors import SensorDataError
    from momentid.io.formats.csv_run import read_csv_run

    rows = "\n".join(f"{k / 100:.2f},{np.sin(k / 5):.6f},{np.sin(k / 5 + 0.1):.6f},{0.01 * np.cos(k / 5):.6f}"
                     for k in range(50))
    path = tmp_path / "r1.csv"
    path.write_text("t,zdd,a1,table_wy\n" + rows + "\n")
    _, channels, values = read_csv_run(path, 1)
    assert channels == ("zdd", "a1", "table_wy") and values.shape == (50, 3)
    path.write_text("t,zdd,a1,table_spin\n" + rows + "\n")
    with pytest.raises(SensorDataError, match="table_spin"):
        read_csv_run(path, 1)
