"""The pieces of the modal identification: response, Jacobian, subspace estimate, storey-mode choice,
and the answers it refuses (issue 18 points 2 and 3)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import momentid as mi
from momentid.cli import main
from momentid.core.series import Experiment, RunData
from momentid.core.structure import LabStatement
from momentid.estimation.linear import discretize, frequency_response, outputs, output_matrix, simulate_linear
from momentid.estimation.modal import linear_start, modal_spectra, refine, with_fixed_sensors
from momentid.estimation.modal_checks import check
from momentid.estimation.modal_model import Hold, Likelihood, ModalModel, mode_response
from momentid.estimation.modal_select import f_test, select_modes, storey_modes
from momentid.estimation.scaled import identify_modal
from momentid.estimation.subspace import stable_poles
from momentid.io.recording import write_experiment

MASSES = (0.160, 0.160, 0.142)
FS = 120.0
SIGMA = 0.01
LEAD_IN = 5.0


def rig(zeta, dt: float):
    """The 3-storey shear building (modal damping ``zeta``) discretised at ``dt`` (s), first-order hold."""
    M, K = np.diag(MASSES), mi.shear_stiffness([450.0, 500.0, 520.0])
    w2, phi = np.linalg.eigh(np.linalg.solve(np.sqrt(M), np.linalg.solve(np.sqrt(M), K).T))
    phi = np.linalg.solve(np.sqrt(M), phi)
    C = M @ phi @ np.diag(2 * np.asarray(zeta) * np.sqrt(w2)) @ phi.T @ M
    return discretize(M, C, K, dt)


def shear_run(seed: int, *, zeta=(0.005, 0.004, 0.003), duration=40.0, name="shake") -> RunData:
    """A 3-storey shear building (modes near 4, 11, 16 Hz) under band-limited table noise at 120 Hz,
    exact first-order-hold simulation, a quiet lead-in and white noise on every channel."""
    rng = np.random.default_rng(seed)
    n = int(duration * FS)
    spectrum = np.fft.rfft(rng.standard_normal(n))
    spectrum[np.fft.rfftfreq(n, 1 / FS) > 30.0] = 0.0
    u = np.fft.irfft(spectrum, n)
    u = np.concatenate([np.zeros(int(LEAD_IN * FS)), 0.5 * u / np.std(u), np.zeros(int(3 * FS))])
    model = rig(zeta, 1 / FS)
    a = outputs(model, simulate_linear(model, u))["a"]
    values = np.column_stack([u, a]) + SIGMA * rng.standard_normal((u.size, 4))
    return RunData(name, np.zeros(3), np.arange(u.size) / FS, ("zdd", "a1", "a2", "a3"), values)


def late_run(seed: int, offsets, *, duration=20.0, zeta=(0.005, 0.004, 0.003)) -> RunData:
    """The rig of :func:`shear_run` simulated 10x finer, floor j read ``offsets[j]`` fine steps (tenths
    of a sample) after the table, the record cut while the floors still ring (no rest at its end)."""
    rng = np.random.default_rng(seed)
    n, up = int(duration * FS), 10
    spectrum = np.fft.rfft(rng.standard_normal(n))
    spectrum[np.fft.rfftfreq(n, 1 / FS) > 30.0] = 0.0
    u = np.fft.irfft(spectrum * up, n * up)            # the same band-limited motion on the finer grid
    u = np.concatenate([np.zeros(int(LEAD_IN * FS * up)), 0.5 * u / np.std(u)])
    model = rig(zeta, 1 / (FS * up))
    a = outputs(model, simulate_linear(model, u))["a"]
    k = np.arange(2 * up, u.size - up, up)
    values = np.column_stack([u[k]] + [a[k - o, j] for j, o in enumerate(offsets)])
    values = values + SIGMA * rng.standard_normal(values.shape)
    return RunData("shake", np.zeros(3), np.arange(k.size) / FS, ("zdd", "a1", "a2", "a3"), values)


def true_frequencies() -> np.ndarray:
    """The rig's undamped natural frequencies (Hz)."""
    M, K = np.diag(MASSES), mi.shear_stiffness([450.0, 500.0, 520.0])
    return np.sqrt(np.linalg.eigvalsh(np.linalg.solve(np.sqrt(M), np.linalg.solve(np.sqrt(M), K).T))) / (2 * np.pi)


def lab(*runs) -> Experiment:
    return Experiment(runs=tuple(runs), statement=LabStatement(storeys=3, masses=MASSES), source="sim")


def jacobian_error(lik: Likelihood, theta: np.ndarray) -> np.ndarray:
    """Per parameter, the analytic Jacobian's relative distance from central differences."""
    J = lik.jacobian(theta)
    fd = np.empty_like(J)
    for i in range(theta.size):
        step = 1e-6 * max(abs(theta[i]), 1e-3 if i >= lik.model.n_modal + 3 else 1.0)
        e = np.zeros_like(theta)
        e[i] = step
        fd[:, i] = (lik.residual(theta + e) - lik.residual(theta - e)) / (2 * step)
    return np.linalg.norm(J - fd, axis=0) / np.linalg.norm(fd, axis=0)


def test_first_order_hold_response_is_the_exact_discretisation():
    w, z, h = 2 * np.pi * np.array([3.7, 16.7, 40.0]), np.array([0.005, 0.003, 0.02]), 1 / FS
    bins = 2 * np.pi * np.linspace(0.5, 55.0, 300)
    H, _ = mode_response(Hold.FIRST_ORDER, bins, h, w, z)
    oscillators = discretize(np.eye(3), np.diag(2 * z * w), np.diag(w ** 2), h)
    G, _ = frequency_response(oscillators, output_matrix(oscillators, ["a"]), np.exp(1j * bins * h))
    # Two computations of the same rational function: round-off only (observed 7e-12).
    assert np.max(np.abs((1 - G) - H)) < 1e-9


@pytest.mark.parametrize("hold", list(Hold))
def test_mode_response_derivatives(hold):
    w, z, h = 2 * np.pi * np.array([3.7, 16.7]), np.array([0.005, 0.003]), 1 / FS
    bins = 2 * np.pi * np.linspace(0.5, 55.0, 300)
    _, dH = mode_response(hold, bins, h, w, z)
    e = 1e-7
    numeric = [(mode_response(hold, bins, h, w * np.exp(e), z)[0]
                - mode_response(hold, bins, h, w * np.exp(-e), z)[0]) / (2 * e),
               (mode_response(hold, bins, h, w, z + e)[0] - mode_response(hold, bins, h, w, z - e)[0]) / (2 * e)]
    for analytic, fd in zip(dH, numeric):
        # Central differences of step 1e-7 on a peak of height ~1/(2 zeta): ~1e-8 relative round-off.
        assert np.max(np.abs(analytic - fd)) < 1e-6 * np.max(np.abs(analytic))


def test_jacobian_matches_finite_differences_at_the_optimum():
    run = shear_run(1)
    model = ModalModel(3, 1)
    sp = modal_spectra([run], 3, 25.0)
    # At the optimum, where Kaufman's Jacobian is exact up to a term proportional to the (noise-sized)
    # residual.
    start = linear_start(model, sp, 2 * np.pi * true_frequencies(), np.array([0.005, 0.004, 0.003]))
    theta = refine(model, sp, [("start", start)], sample_rates=[FS], f_max=25.0, hold=Hold.FIRST_ORDER).theta
    error = jacobian_error(Likelihood(model, sp, hold=Hold.FIRST_ORDER), theta)
    # Kaufman's approximation drops a term of the size of the residual relative to the model's
    # sensitivity: a few percent at most here (observed below 2e-2); a wrong derivative is O(1).
    assert np.all(error < 0.05), error


def test_jacobian_with_clock_offsets_and_a_complex_mode():
    """The offsets' and the transient's derivatives where the floors ring at the record's end."""
    run = late_run(1, (6, -4, 9))
    model = ModalModel(3, 1, quadrature=(0,))
    sp = modal_spectra([run], 3, 25.0)
    start = linear_start(model, sp, 2 * np.pi * true_frequencies(), np.array([0.005, 0.004, 0.003]))
    theta = refine(model, sp, [("start", start)], sample_rates=[FS], f_max=25.0).theta
    error = jacobian_error(Likelihood(model, sp), theta)
    # As above: Kaufman's dropped term is residual-sized (observed below 3e-2); a wrong derivative is O(1).
    assert np.all(error < 0.05), error


def test_late_floor_sensors_in_a_record_that_ends_ringing_fit_to_the_noise():
    """Floor j reads the free decays tau_j late: exp(-lambda tau_j) per mode, not the forced part's
    exp(-i w tau_j) per bin (which misfit by 2-2.3x the noise and bent the damping by up to 12 %)."""
    for seed in (1, 2):
        r = identify_modal(lab(late_run(seed, (6, -4, 9))))
        # White noise fitted by its own level: residual RMS 1 within the 20 s record's scatter (observed
        # 0.97-1.01, the same as with no offsets).
        assert 0.9 < r.residual_rms < 1.1, r.residual_rms
        # 20 s of a lightly damped rig: within 5 % of the truth (observed within 0.6 %).
        assert np.allclose(r.damping_ratio, [0.005, 0.004, 0.003], rtol=0.05), r.damping_ratio


def test_fixing_an_undetermined_gain_keeps_what_the_data_determine():
    """A gain the data leave open trades with its floor's residues (a record of mostly free decay
    determines only ``g_j R_ij``): fixed at 1, the residues carry it, so the refit starts where the data
    put the shapes (fixed at 1 alone, a window of the flexible rig's ``sine_1p5`` refitted into modes at
    8-13 Hz with 49 % damping, its clock offsets at the bound)."""
    model = ModalModel(3, 2)
    R = np.arange(1.0, 10.0).reshape(3, 3)
    theta = model.pack([20.0, 60.0, 100.0], [0.01] * 3, R, gains=[[0.5, 1.2, 2.0], [0.8, 1.1, 1.5]],
                       offsets=[[0.001, -0.002, 0.003], [0.0, 0.001, 0.002]])
    fixed = np.zeros(model.p, bool)
    for r in range(2):
        s = model.sensor_slice(r)
        fixed[s.start] = fixed[s.start + 2] = True      # floors 1 and 3's gains, every run
        fixed[s.stop - 1] = r == 0                      # floor 3's offset in run 0
    fixed[model.sensor_slice(1).start + 1] = True       # floor 2's gain in run 1 only
    out = with_fixed_sensors(model, theta, fixed)
    g0, tau0 = model.sensors(out, 0)
    g1, _ = model.sensors(out, 1)
    assert np.allclose(g0, [1.0, 1.2, 1.0]) and np.allclose(g1, [1.0, 1.0, 1.0])
    assert np.allclose(tau0, [0.001, -0.002, 0.0])
    # floors 1 and 3: the runs' geometric mean gain moved into the residues; floor 2 (its gain
    # determined in run 0) keeps its residues
    assert np.allclose(model.residues(out), R * np.array([np.sqrt(0.5 * 0.8), 1.0, np.sqrt(2.0 * 1.5)]))


def test_subspace_finds_the_modes_stable_over_orders():
    run = shear_run(2)
    poles = stable_poles(run["zdd"], run.group("a", 3), 1 / FS, 3, 50.0)
    stable = [p for p in poles if p.damping_stable]
    f = np.array([p.frequency for p in stable])
    assert f.size == 3
    # 40 s of noisy data: within 0.3 % of the rig's frequencies.
    assert np.allclose(f, true_frequencies(), rtol=3e-3), (f, true_frequencies())
    z = np.array([p.damping_ratio for p in stable])
    # Damping within 30 %: the subspace estimate is a second opinion, not the answer.
    assert np.allclose(z, [0.005, 0.004, 0.003], rtol=0.3), z


def test_storey_modes_are_the_orthogonal_ones_with_most_effective_mass():
    m = np.array(MASSES)
    M, K = np.diag(m), mi.shear_stiffness([450.0, 500.0, 520.0])
    w2, phi = np.linalg.eigh(np.linalg.solve(np.sqrt(M), np.linalg.solve(np.sqrt(M), K).T))
    phi = np.linalg.solve(np.sqrt(M), phi)
    gamma = phi.T @ m
    R = gamma[:, None] * phi.T                        # storey modes' residues (3 x 3)
    f = np.sqrt(w2) / (2 * np.pi)
    # An appendage beside mode 1: the same floor shape, 2 % of its effective mass.
    R_all = np.vstack([R, 0.02 * R[0]])
    f_all = np.append(f, 1.01 * f[0])
    assert storey_modes(R_all, f_all, 3, m) == (0, 1, 2)
    # One storey: the larger participation is the storey's, whichever is lower in frequency.
    assert storey_modes(np.array([[0.03], [0.97]]), np.array([9.9, 10.0]), 1) == (1,)


def test_f_test_of_nested_costs():
    F, p = f_test(1200.0, 1000.0, 5, 1000)
    assert F == pytest.approx(40.0) and p < 1e-6
    assert f_test(1001.0, 1000.0, 5, 1000)[1] > 0.1


def test_no_extra_mode_on_a_shear_building():
    selection = select_modes([shear_run(3)], 3, masses=MASSES)
    assert selection.model.n == 3 and selection.extra == ()


def test_an_equivalent_linear_damping_far_from_the_subspace_estimate_is_warned_about():
    run = shear_run(4)
    r = identify_modal(lab(run))
    assert r.damping_is_answer.all() and not any("NOT AN ANSWER" in w for w in r.warnings)
    selection = select_modes([run], 3, masses=MASSES)
    doubted = dataclasses.replace(selection, independent=selection.independent * np.array([1.0, 3.0, 1.0]))
    values = {"frequency": np.sort(selection.model.omega(selection.fit.theta)) / (2 * np.pi),
              "damping_ratio": selection.model.zeta(selection.fit.theta)[list(selection.storey)],
              "orthogonality": 0.0}
    std = {"frequency": np.zeros(3), "damping_ratio": np.zeros(3)}
    gain, offset = selection.model.sensors(selection.fit.theta, 0)
    warnings, _, answer = check(doubted, values, std, [run], gain[None], offset[None], MASSES)
    # the linear fit's damping is the equivalent linear one: warned about, while the damping answer
    # (at small amplitude, momentid.estimation.damping) is judged on its own evidence
    assert list(answer) == [True, True, True]
    assert any("mode 2" in w and "equivalent linear" in w and "subspace" in w for w in warnings), warnings


def test_a_sensor_reading_a_third_of_the_table_is_refused():
    run = shear_run(5)
    values = run.values.copy()
    values[:, 2] *= 0.3                      # a2 turned 70 degrees off the shaking axis
    with pytest.raises(mi.IdentificationError, match=r"refused: floor sensor\(s\) a2 .*at the bound"):
        identify_modal(lab(dataclasses.replace(run, values=values)))


def test_a_sensor_off_the_clock_by_three_samples_is_refused():
    run = shear_run(6)
    values = run.values.copy()
    values[:, 3] = np.roll(values[:, 3], 3)  # a3 three samples late
    with pytest.raises(mi.IdentificationError, match=r"clock offset of floor sensor\(s\) a3 .*bound of 1.5 samples"):
        identify_modal(lab(dataclasses.replace(run, values=values)))


def test_cli_prints_every_warning_once(tmp_path, capsys):
    """A floor sensor 8 % hot: one suspect-gain warning, on stderr, once (it used to come twice)."""
    runs = []
    for k in range(2):
        run = shear_run(10 + k, name=f"run{k}")
        values = run.values.copy()
        values[:, 1] *= 1.08
        runs.append(dataclasses.replace(run, values=values))
    path = write_experiment(tmp_path / "hot.mcap", lab(*runs))
    for argv in (["identify", str(path)], ["identify", str(path), "--per-run"]):
        assert main(argv) == 0
        out, err = capsys.readouterr()
        text = out + err
        assert "WARNING" not in out
        warned = [line for line in err.splitlines() if line.startswith("WARNING")]
        assert sum("a1 read 1.0" in w for w in warned) == 2, warned       # one per run
        for w in warned:
            assert text.count(w.split(": ", 1)[1]) == 1, w
