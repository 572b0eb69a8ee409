"""Blind diagnosis on cases the validation matrix does not hold: other places, magnitudes,
excitations (band-limited noise, three harmonics below the first mode) and noise levels.

    python -m benchmarks.diagnosis_variants [--workers N]

A check against tuning to the matrix of ``benchmarks/diagnosis.py``: the same rig, the same
verdict rules, cases chosen after the method was fixed.  Writes
``benchmarks/results/diagnosis_variants.json`` and ``.md``.
"""

from __future__ import annotations

from benchmarks.common import matrix_parser, run_cases, save
from benchmarks.diagnosis import case, table

NOISE = {"type": "noise", "rms": 0.3, "band": [0.5, 20.0]}
HARMONICS = {"type": "harmonics", "amplitudes": [0.002, 0.001, 0.0014],
             "angular_frequencies": [6.2832, 8.8858, 1.6239]}

CASES = [   # (mechanism, truth or fault, expected location, noise, excitation: None = El Centro)
    ("coulomb_friction", {"storey": 1, "force": 0.35}, {"storey": 1}, 0.015, NOISE),
    ("coulomb_friction", {"storey": 2, "force": 0.1}, {"storey": 2}, 0.01, None),
    ("coulomb_friction", {"storey": 2, "force": 0.3}, {"storey": 2}, 0.01, HARMONICS),
    ("cubic_stiffness", {"storey": 3, "k3": 2e7}, {"storey": 3}, 0.01, NOISE),
    ("extra_damper", {"storey": 2, "c": 2.5}, {"storey": 2}, 0.02, NOISE),
    ("extra_damper", {"storey": 1, "c": 1.0}, {"storey": 1}, 0.01, HARMONICS),
    ("p_delta", {"storey": 3, "factor": 2.0}, {"storey": 3}, 0.015, None),
    ("p_delta", {"storey": 2, "factor": 1.0}, {"storey": 2}, 0.02, NOISE),
    ("flexible_added_mass", {"floor": 2, "frequency": 8.0, "damping_ratio": 0.02}, {"floor": 2}, 0.01, NOISE),
    ("sensor_delay", {"q1": {"clock_offset": 0.004}}, {"channel": "q1"}, 0.01, None),
    ("sensor_delay", {"a1": {"clock_offset": 0.002}}, {"channel": "a1"}, 0.02, NOISE),
    ("sensor_gain", {"a3": {"gain": 0.95}}, {"channel": "a3"}, 0.01, NOISE),
    ("sensor_gain", {"zdd": {"gain": 1.03}}, {"channel": "zdd"}, 0.01, HARMONICS),
    ("sensor_bias", {"zdd": {"bias": 0.02}}, {"channel": "zdd"}, 0.01, None),
    ("none", {}, {}, 0.02, NOISE),
    ("none", {}, {}, 0.01, HARMONICS),
    ("none", {}, {}, 0.02, HARMONICS),
    ("unexplained", {"storey": 2, "fraction": 0.2, "time": 10.0}, {"storey": 2}, 0.01, NOISE),
]


def main(argv=None) -> int:
    args = matrix_parser("benchmarks.diagnosis_variants", __doc__).parse_args(argv)
    rows = run_cases(CASES, args.workers, case)
    lines = table(rows, spec=True)
    lines += ["", f"Right verdict and location: {sum(r['correct'] for r in rows)} of {len(rows)}."]
    save(args.out, "diagnosis_variants", rows, lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
