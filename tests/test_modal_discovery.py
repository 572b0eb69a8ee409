"""The open search of the modal path (:mod:`momentid.diagnosis.modal.open_search`) on simulated
accelerometer-only rigs: 120 Hz, no added mass, like ``tests/test_real_diagnose.py``'s, but with a
cubic spring in storey 1 (a rig that stiffens with its drift), simulated by an independent
fixed-step RK4 of the shear building at 8 sub-steps per sample."""

from __future__ import annotations

import json

import numpy as np
import pytest

import momentid as mi
from momentid.core.series import RunData
from momentid.diagnosis.modal import check as mc
from momentid.diagnosis.modal.open_search import MIN_HELD_OUT_GAIN, discover_modal
from momentid.diagnosis.modal.path import diagnose_modal
from momentid.diagnosis.report import write_report

from test_real_diagnose import DURATION, FS, LEAD_IN, MASSES, SIGMA, STIFFNESS, lab

#: RK4 sub-steps per sample: the step is then 1/60 of mode 3's period (~16 Hz), its error ~1e-7.
SUBSTEPS = 8
#: Storey 1's cubic spring (N/m^3): mode 1 then moves by 1 % between the smallest and the largest
#: training run (3.98 -> 4.02 Hz in their modal fits), and the linear model misses the held-out run
#: by ~15 x noise; at 1e7 N/m^3 (8 %) the per-run modal fit itself breaks down.
K3 = 3.0e6
#: Velocity scale (m/s) of the smoothed friction: ~3 % of storey 1's RMS drift rate in the runs.
FRICTION_SCALE = 1e-3
#: Table RMS (m/s^2) of the runs; the last one is held out and lies inside the training range.
AMPLITUDES = (0.15, 0.5, 0.3, 0.25)
ZETA = (0.005, 0.004, 0.003)


def table(rms: float, seed: int) -> np.ndarray:
    """Band-limited (below 25 Hz) table acceleration (m/s^2) after a quiet lead-in."""
    rng = np.random.default_rng(seed)
    n = int(DURATION * FS)
    spectrum = np.fft.rfft(rng.standard_normal(n))
    spectrum[np.fft.rfftfreq(n, 1 / FS) > 25.0] = 0.0
    u = np.fft.irfft(spectrum, n)
    return np.concatenate([np.zeros(int(LEAD_IN * FS)), u * rms / np.std(u)])


def cubic_runs(k3: float, seed: int = 40, friction: float = 0.0) -> list[RunData]:
    """Every run of :data:`AMPLITUDES` at once: ``M q'' + C q' + K q + (k3 q1^3 + F tanh(q1' / v_s)) e1 =
    -M 1 z''`` (q relative to the table, z'' held linear between samples, F = ``friction`` N and v_s =
    :data:`FRICTION_SCALE`), floor sensors reading ``q'' + z''`` with white noise."""
    M = np.diag(MASSES)
    K = mi.shear_stiffness(STIFFNESS)
    w2, phi = np.linalg.eigh(np.linalg.solve(np.sqrt(M), np.linalg.solve(np.sqrt(M), K).T))
    phi = np.linalg.solve(np.sqrt(M), phi)
    C = M @ phi @ np.diag(2 * np.array(ZETA) * np.sqrt(w2)) @ phi.T @ M
    Minv = np.linalg.inv(M)
    u = np.array([table(rms, seed + i) for i, rms in enumerate(AMPLITUDES)]).T       # (n, runs)

    def absolute(q, qd):                      # floor accelerations q'' + z'' (runs, 3)
        f = q @ K + qd @ C
        f[:, 0] += k3 * q[:, 0] ** 3 + friction * np.tanh(qd[:, 0] / FRICTION_SCALE)
        return -f @ Minv

    h = 1 / (FS * SUBSTEPS)
    q, qd = np.zeros((len(AMPLITUDES), 3)), np.zeros((len(AMPLITUDES), 3))
    a = np.empty((u.shape[0], len(AMPLITUDES), 3))
    for j in range(u.shape[0]):
        a[j] = absolute(q, qd)
        u1 = u[min(j + 1, u.shape[0] - 1)]
        for s in range(SUBSTEPS):
            z0, zm, z1 = (u[j] + (u1 - u[j]) * (s + f) / SUBSTEPS for f in (0.0, 0.5, 1.0))
            k1v, k1a = qd, absolute(q, qd) - z0[:, None]
            k2v, k2a = qd + h / 2 * k1a, absolute(q + h / 2 * k1v, qd + h / 2 * k1a) - zm[:, None]
            k3v, k3a = qd + h / 2 * k2a, absolute(q + h / 2 * k2v, qd + h / 2 * k2a) - zm[:, None]
            k4v, k4a = qd + h * k3a, absolute(q + h * k3v, qd + h * k3a) - z1[:, None]
            q = q + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
            qd = qd + h / 6 * (k1a + 2 * k2a + 2 * k3a + k4a)
    rng = np.random.default_rng(seed + 100)
    out = []
    for r in range(len(AMPLITUDES)):
        values = np.column_stack([u[:, r], a[:, r]]) + SIGMA * rng.standard_normal((u.shape[0], 4))
        out.append(RunData(f"r{r + 1}", np.zeros(3), np.arange(u.shape[0]) / FS, ("zdd", "a1", "a2", "a3"), values))
    return out


def test_cubic_storey_found_on_mode_1(tmp_path):
    # the modal path itself (`diagnose` runs three or more trials with stated masses on the twin)
    diag = diagnose_modal(lab(*cubic_runs(K3)))
    assert diag.nrmse_before > 5 * diag.noise_nrmse, diag.summary     # the linear model misses it clearly
    found = diag.discovered
    assert found is not None, diag.summary
    assert found.location["mode"] == 1, found.description
    # Its first nonlinear term is a stiffness that grows with the motion: a positive coefficient of a
    # term odd in eta (cubic, quadratic, a gap or stop) is stiffening.
    first = [t for t in found.terms if t["term"] not in ("x", "v")][0]
    stiffening = ("x3", "x_abs_x", "dead_zone", "gap_pos", "gap_neg")
    assert first["term"] in stiffening and first["coefficient"] > 0, found.terms
    assert found.beats_linear, diag.summary
    assert found.nrmse_after <= (1 - MIN_HELD_OUT_GAIN) * found.nrmse_before
    assert "it beats the linear model" in diag.summary and diag.mechanism != "none"
    write_report(diag, tmp_path)
    report = json.loads((tmp_path / "report.json").read_text())
    for key in ("location", "description", "terms", "nrmse_before", "nrmse_after", "beats_linear"):
        assert key in report["discovered"]
    assert (tmp_path / "discovered.png").exists()


@pytest.mark.slow
def test_friction_storey_found_on_mode_1():
    # 0.02 N of friction in storey 1: ~2 % of its spring force at a 2 mm drift, a damping that falls
    # with the amplitude; the linear model misses the held-out run by ~18 x noise.
    diag = diagnose_modal(lab(*cubic_runs(0.0, friction=0.02)))
    found = diag.discovered
    assert found is not None, diag.summary
    assert found.location["mode"] == 1, found.description
    first = [t for t in found.terms if t["term"] not in ("x", "v")][0]
    assert first["term"] == "sign_v" and first["coefficient"] > 0, found.terms      # friction, dissipative
    assert found.beats_linear, diag.summary


def test_linear_rig_nothing_found():
    runs = cubic_runs(0.0)
    experiment = lab(*runs)
    train = [r.name for r in runs[:-1]]
    linear = mc.fit_runs(experiment, train)          # one joint fit: the rig is linear, its modes shared
    held = runs[-1]
    dt, start = 1 / held.sample_rate, mc.active_start(held)
    model = mc.replay(linear.omega, linear.zeta, linear.residues, linear.gain.mean(axis=0), linear.offset.mean(axis=0),
                      held["zdd"], dt)
    before = mc.nrmse(held.group("a", 3)[start:], model[start:])
    # Run even though diagnose would not (the linear model is within noise): no term earns its place.
    found = discover_modal(experiment, linear, train, held.name, {"sensor": "a1"}, before)
    assert found is None, found.to_dict()
