"""Compare ways to supply the velocity and displacement that equation (3) needs.

    python -m benchmarks.reconstruction

On the lab rig (paper structure, El Centro, reference + one added-mass run), noise-free and with 1 %
sensor noise: the equation-form least-squares estimate (the starting point of the EIV fit) and the
error of the reconstructed floor velocity, for

* ``diff``: central differences of the raw displacement (no filter);
* ``lowpass+spline``: the same zero-phase low-pass on every channel, velocity as the derivative of the
  cubic spline through the filtered displacement (momentid's choice with displacement transducers);
* ``integrate``: accelerometers only, relative acceleration integrated twice in the frequency domain
  with a 0.1 Hz high-pass (the classic baseline-corrected integration);
* ``weak form``: accelerometers only, the equation tested against sliding bumps (momentid's choice).

Writes ``benchmarks/results/reconstruction.md``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

import momentid as mi
from momentid.estimation.reconstruct import Prefilter, prepare_run, suggest_band, weak_form
from momentid.lab.scenario import Instrument, Sensors
from momentid.lab.sensors import measure

ROOT = Path(__file__).resolve().parents[1]


def _integrate(x, fs, low=0.1):
    n = x.shape[0]
    nfft = 2 * n
    X = np.fft.rfft(x - x.mean(axis=0), n=nfft, axis=0)
    w = 2 * np.pi * np.fft.rfftfreq(nfft, 1 / fs)
    keep = w > 2 * np.pi * low
    out = np.zeros_like(X)
    out[keep] = X[keep] / (1j * w[keep, None])
    return np.fft.irfft(out, n=nfft, axis=0)[:n]


def _equation_estimate(signals, runs, structure):
    """Plain LS of eq. (3) on given per-run (a, v, q); max relative error over M, C, K, mu."""
    rows, rhs = [], []
    d = structure.storeys
    for s, run in zip(signals, runs):
        dm = run.added_mass
        for j in range(d):
            cols = [s["a"][:, j:j + 1], s["v"], s["q"], (dm[j] * s["v"][:, j])[:, None]]
            A = np.zeros((s["a"].shape[0], d + 2 * d * d + 1))
            A[:, j] = cols[0][:, 0]
            A[:, d + j * d:d + (j + 1) * d] = s["v"]
            A[:, d + d * d + j * d:d + d * d + (j + 1) * d] = s["q"]
            A[:, -1] = cols[3][:, 0]
            rows.append(A)
            rhs.append(-dm[j] * s["a"][:, j])
    A, b = np.vstack(rows), np.concatenate(rhs)
    theta, *_ = np.linalg.lstsq(A / np.linalg.norm(A, axis=0), b, rcond=None)
    theta /= np.linalg.norm(A, axis=0)
    M = theta[:d]
    return float(np.max(np.abs(M / np.asarray(structure.masses) - 1)))


def main() -> int:
    sc = mi.load_scenario(ROOT / "scenarios" / "lab_noisy.toml")
    sc = dataclasses.replace(sc, sensors=Sensors())
    truth = mi.simulate(sc)
    d = sc.structure.storeys
    lines = ["| method | sensors | noise | velocity error (RMS / RMS) | max mass error of plain LS |",
             "|---|---|---|---|---|"]
    for noise in (0.0, 0.01):
        inst = Instrument(relative_noise=noise) if noise else Instrument()
        sens = Sensors(groups=("zdd", "z", "a", "q"), set="accel+disp", accelerometer=inst, displacement=inst)
        runs = [measure(r, sens, seed=3, run_index=i) if noise else r for i, r in enumerate(truth.runs)]
        fs = runs[0].sample_rate
        band = Prefilter(high=suggest_band(truth.runs[0], d))
        for method in ("diff", "lowpass+spline", "integrate", "weak form"):
            sigs, verr = [], []
            for run, true in zip(runs, truth.runs):
                a, q, zdd = run.group("a", d), run.group("q", d), run["zdd"]
                v_true = true.group("v", d)
                if method == "diff":
                    s = {"a": a, "q": q, "v": np.gradient(q, 1 / fs, axis=0)}
                elif method == "lowpass+spline":
                    s = prepare_run(dataclasses.replace(run, channels=run.channels, values=run.values), d, band)
                    v_true = prepare_run(true, d, band)["v"]
                elif method == "integrate":
                    v = _integrate(a - zdd[:, None], fs)
                    s = {"a": a, "v": v, "q": _integrate(v, fs)}
                else:
                    s = weak_form(run.time, a, zdd, band.high)
                    v_true = weak_form(true.time, true.group("a", d), true["zdd"], band.high)["v"]
                sigs.append(s)
                verr.append(np.sqrt(np.mean((s["v"] - v_true) ** 2)) / np.sqrt(np.mean(v_true ** 2)))
            err = _equation_estimate(sigs, runs, sc.structure)
            kind = "accel+disp" if method in ("diff", "lowpass+spline") else "accel"
            lines.append(f"| {method} | {kind} | {100 * noise:g} % | {np.mean(verr):.2e} | {err:.2e} |")
            print(lines[-1], flush=True)
    out = ROOT / "benchmarks" / "results"
    out.mkdir(parents=True, exist_ok=True)
    (out / "reconstruction.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
