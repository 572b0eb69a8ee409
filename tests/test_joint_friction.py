"""Joint friction (Iwan sliders in MuJoCo) and the re-simulated twin of a real rig.

The sliders are held to the ideal Jenkins law (a spring whose elongation is clipped at its slip drift)
evaluated on MuJoCo's own drift history; the twin's linear part to the exact modal replay; the written
MJCF to the compiled spec; the output-error fit to a rig whose parameters it must recover.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from momentid.diagnosis.modal import check as mc
from momentid.twin import fit as twin_fit
from momentid.lab import resim
from momentid.lab.sensors import gain_and_delay
from momentid.mechanisms import joint_friction as jf

MASSES = np.array([0.16, 0.16, 0.142])      # kg: the shipped rig's stated floor masses
K3 = np.array([[1018.0, -535.0, 36.5], [-535.0, 1066.0, -556.0], [36.5, -556.0, 512.0]])   # N/m, identified
ZETA = np.array([0.004, 0.003, 0.002])
FS = 120.0                                  # Hz: the shipped rig's sample rate


def _table(duration: float, peak: float, seed: int = 0) -> np.ndarray:
    """Table acceleration (m/s^2): band-limited noise under a rising then falling envelope."""
    rng = np.random.default_rng(seed)
    n = int(duration * FS)
    x = np.convolve(rng.normal(size=n), np.hanning(9), "same")
    envelope = np.sin(np.pi * np.arange(n) / n) ** 2
    return peak * envelope * x / np.max(np.abs(x))


def test_slider_elements_carry_the_stiffness_and_the_power_law():
    k, delta = jf.slider_elements(50.0, 4e-3, -0.4)
    assert np.isclose(k.sum(), 50.0, rtol=1e-12)                    # the weights are a partition of unity
    assert np.isclose(delta[-1], 4e-3) and np.isclose(delta[-1] / delta[0], jf.SPAN)
    params = {"stiffness": 50.0, "slip_drift": 4e-3, "exponent": -0.4}
    x = np.array([1e-7, 4e-3, 1.0])
    f = jf.backbone(params, x)
    assert np.isclose(f[0], 50.0 * 1e-7, rtol=1e-9)                 # stuck: the full stiffness
    assert np.isclose(f[1], f[2]) and np.isclose(f[2], np.sum(k * delta))   # macro-slip: all sliders at strength
    # Micro-slip: the stiffness lost grows as x^(chi+1); between two drifts inside the elements' span the
    # discretised law follows it to the resolution of 6 geometric elements (~25 % per factor 4 of drift).
    def lost(x):
        return 1.0 - jf.backbone(params, x) / (50.0 * x)

    slope = np.log(lost(1.6e-3) / lost(0.4e-3)) / np.log(4.0)
    assert abs(slope - 0.6) < 0.15, slope


def _step_storey(model, zdd, substeps):
    """Step ``model`` under ``zdd`` (samples at FS); per step: storey-1 drift and its sliders' force (N)."""
    data = mujoco.MjData(model)
    data.act[0] = zdd[0]
    tendons = [i for i in range(model.ntendon) if model.tendon(i).name.startswith("jenkins1_")]
    q1 = model.jnt_qposadr[model.joint("q1").id]
    jerk = np.repeat(np.diff(zdd) * FS, substeps)
    drift, force = np.empty(jerk.size), np.empty(jerk.size)
    for i, u in enumerate(jerk):
        data.ctrl[0] = u
        mujoco.mj_step(model, data)
        drift[i] = data.qpos[q1]
        force[i] = float(np.sum(model.tendon_stiffness[tendons] * data.ten_length[tendons]))
    return drift, force


def test_mujoco_sliders_follow_the_ideal_jenkins_law():
    params = {"stiffness": 60.0, "slip_drift": 1.5e-3, "exponent": -0.4}
    rig1 = twin_fit.FittedRig(np.array([0.16]), np.array([[520.0]]), np.array([0.004]),
                          twin_fit.friction_records([1], [params]))
    substeps = 4
    model = resim.compile_models([rig1.rig()], 1.0 / FS / substeps)[0]
    drift, force = _step_storey(model, _table(8.0, 6.0), substeps)
    k, delta = jf.slider_elements(**params)
    z, ideal = np.zeros(k.size), np.empty(drift.size)
    previous = 0.0
    for i, x in enumerate(drift):                 # the rate-independent law on MuJoCo's own drift history
        z = np.clip(z + x - previous, -delta, delta)
        previous = x
        ideal[i] = np.sum(k * z)
    assert np.max(np.abs(drift)) > 3 * params["slip_drift"]          # the record reaches macro-slip
    error = np.sqrt(np.mean((force - ideal) ** 2) / np.mean(ideal ** 2))
    # Each slider is a small mass whose spring MuJoCo integrates explicitly, not a massless clip: a slipping
    # element lags the ideal one by about a step, an error proportional to the step (measured 12.8 % of
    # the force's RMS at 4 steps a sample and 3.7 x the slip drift, 6.7 % at 8 steps); a slider that did
    # not stick or slip (wrong friction, wrong sign) is off by 100 % or more.
    assert error < 0.2, error


def test_linear_twin_is_the_modal_replay():
    zdd = _table(20.0, 2.0, seed=1)
    twin = twin_fit.FittedRig(MASSES, K3, ZETA)
    substeps = 16
    a = resim.simulate(resim.compile_models([twin.rig()], 1.0 / FS / substeps), zdd, 1.0 / FS, substeps)[0]
    omega, zeta, residues = twin_fit.twin_modes(twin)
    exact = mc.replay(omega, zeta, residues, np.ones(3), np.zeros(3), zdd, 1.0 / FS)
    # implicitfast is second order here: 10 % over 20 s of light damping at 4 steps a sample (the modes'
    # phase drifts; a fitted twin absorbs it in K), 2.3 % at 8, 0.6 % at 16; a wrong tendon (K or C)
    # would be off by tens of %.
    assert mc.nrmse(exact, a) < 0.015, mc.nrmse(exact, a)


def test_the_written_twin_loads_in_stock_mujoco_and_simulates_the_same():
    params = {"stiffness": 40.0, "slip_drift": 5e-3, "exponent": -0.3}
    twin = twin_fit.FittedRig(MASSES, K3, ZETA, twin_fit.friction_records([1, 2], [params, params]))
    substeps = resim.TIMESTEP_PER_SAMPLE
    spec = resim.build_spec(twin.rig(), 1.0 / FS / substeps)
    compiled = spec.compile()
    loaded = mujoco.MjModel.from_xml_string(spec.to_xml())
    zdd = _table(6.0, 4.0, seed=2)
    a, b = (resim.simulate([m], zdd, 1.0 / FS, substeps)[0] for m in (compiled, loaded))
    # The same model through MJCF text, whose numbers are printed to 6 digits (the step, the sliders'
    # masses): 1e-4 of the response apart (measured 2e-4 over 6 s); a lost slider or tendon is tens of %.
    assert mc.nrmse(a, b) < 1e-3, mc.nrmse(a, b)
    assert loaded.nv == 4 + 2 * jf.SLIDERS


def test_fit_twin_recovers_a_linear_rig():
    truth = twin_fit.FittedRig(MASSES, K3, ZETA, gain=np.array([1.0, 1.01, 0.99]), offset=np.array([0.0, 0.0, 2e-3]))
    zdd = _table(12.0, 2.0, seed=3)
    clean = twin_fit.predict(truth, twin_fit.Trial("t", zdd, np.zeros((zdd.size, 3)), 1.0 / FS, 0, zdd.size, 1.0))
    tr = twin_fit.Trial("t", zdd, clean, 1.0 / FS, 0, zdd.size, float(np.sqrt(np.sum((clean - clean.mean(0)) ** 2))))
    start = twin_fit.FittedRig(MASSES, K3 * 1.01, ZETA * 1.3)
    fit = twin_fit.fit_twin([tr], start)
    # Noise-free data of the model's own form: the fit lands on the truth to the optimiser's tolerance.
    assert fit.nrmse["t"] < 1e-3, fit.nrmse
    assert np.allclose(fit.model.stiffness, K3, rtol=2e-3, atol=0.5)
    assert np.allclose(fit.model.offset, truth.offset, atol=5e-5)


def test_sensor_columns_of_the_fit_are_the_residual_derivatives():
    model = twin_fit.FittedRig(MASSES, K3, ZETA, gain=np.array([1.0, 1.02, 0.97]), offset=np.array([0.0, 1e-3, -2e-3]))
    zdd = _table(4.0, 1.0, seed=5)
    a = resim.simulate(resim.compile_models([model.rig()], 0.5 / FS), zdd, 1.0 / FS)[0]
    tr = twin_fit.Trial("t", zdd, gain_and_delay(a, np.ones(3), np.zeros(3), 1.0 / FS), 1.0 / FS, 40, zdd.size, 3.0)
    J = twin_fit.sensor_jacobian(model, a, tr)

    def residual(gain, offset):
        read = gain_and_delay(a, gain, offset, tr.dt)
        return ((tr.a[tr.start:] - read[tr.start:]) / tr.norm).ravel()

    base = residual(model.gain, model.offset)
    for j in range(3):
        h = 1e-6                      # central differences: their error (h^2 x third derivative) is ~1e-12
        g = np.log(model.gain)
        gp, gm = g.copy(), g.copy()
        gp[j] += h
        gm[j] -= h
        fd = (residual(np.exp(gp), model.offset) - residual(np.exp(gm), model.offset)) / (2 * h)
        # exact against central differences: agreement to 1e-6 of the column's size (round-off of the FFTs)
        assert np.allclose(J[:, j], fd, atol=1e-6 * np.max(np.abs(fd))), j
        h = 1e-7                      # s: a tenth of a microsecond, 1e-5 of a sample
        op, om = model.offset.copy(), model.offset.copy()
        op[j] += h
        om[j] -= h
        fd = (residual(model.gain, op) - residual(model.gain, om)) / (2 * h)
        assert np.allclose(J[:, 3 + j], fd, atol=1e-5 * np.max(np.abs(fd))), j
    assert base.size == J.shape[0]


@pytest.mark.parametrize("rate, steps", [(60.0, 4), (100.0, 3), (120.0, 2), (200.0, 2), (240.0, 1), (1000.0, 1)])
def test_the_twin_fit_steps_within_the_sliders_tested_step_at_any_rate(rate, steps):
    # the fewest steps per sample that keep the step within MAX_TIMESTEP (1/240 s)
    assert resim.substeps_for(1.0 / rate) == steps
    assert 1.0 / rate / steps <= jf.MAX_TIMESTEP * (1 + 1e-12)
