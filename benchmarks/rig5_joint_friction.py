"""A simulated 5-storey rig read by accelerometers only, with joint friction: ``momentid diagnose``'s time.

    python -m benchmarks.rig5_joint_friction [--out benchmarks/results]

The rig: five floors of 6 kg on storeys of 1800 N/m (modes 1.2-10.3 Hz), Rayleigh damping, a bolted joint
with friction (:mod:`momentid.mechanisms.joint_friction`, Iwan) in storey 2, table accelerometer and one
accelerometer per floor with 1 % noise, no added mass.  Four trials of El Centro at four amplitudes (the
friction shows as an amplitude dependence), 30 s each at 200 Hz, each simulated by the lab as its own
scenario and gathered into one experiment that states the floor masses (a real lab weighs them): the
diagnosis takes the twin path (``momentid.diagnosis.twin``), the path of a real accelerometer-only rig.
Reports the verdict, the diagnosis's wall time (target: within 60 s), its replays
(:func:`momentid.core.counters.counting`) and the time in raw ``mujoco.rollout`` s of one trial through the
linear rig, measured in the same process right after.  Writes ``rig5_joint_friction.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from benchmarks.common import HIDDEN_RIG, RESULTS, machine, measured_diagnosis, save

STOREYS = 5
MASSES = [6.0] * STOREYS                 # kg
STIFFNESS = [1800.0] * STOREYS           # N/m
FRICTION = {"type": "joint_friction", "storey": 2, "stiffness": 500.0, "slip_drift": 0.002, "exponent": 0.0}
SCALES = (0.02, 0.04, 0.03, 0.06)        # El Centro scale of each trial; the third lies inside the others
DURATION, SAMPLE_RATE, NOISE = 30.0, 200.0, 0.01


def scenario(scale: float, index: int, friction: bool = True):
    """One trial's scenario: the rig under El Centro at ``scale``, its own noise seed."""
    from momentid.lab.scenario import parse_scenario

    data = {
        "scenario": {"name": f"rig5_trial{index + 1}", "duration": DURATION, "sample_rate": SAMPLE_RATE,
                     "seed": 100 + index},
        "structure": {"masses": MASSES, "storey_stiffness": STIFFNESS, "storey_height": 0.3,
                      "damping": {"rayleigh_mu": 0.05, "rayleigh_kappa": 0.0005}},
        "excitation": {"type": "record", "file": str((HIDDEN_RIG.parent / "../../data/records/elcentro_1940_ns.at2")
                                                     .resolve()), "scale": scale},
        "runs": [{"name": f"trial{index + 1}", "added_mass": [0.0] * STOREYS}],
        "sensors": {"set": "accel", "accelerometer": {"relative_noise": NOISE}},
    }
    if friction:
        data["truth"] = {"mechanisms": [dict(FRICTION)]}
    return parse_scenario(data, source=HIDDEN_RIG)


def experiment(friction: bool = True):
    """The four trials gathered into one experiment that states the floor masses (no nominal model)."""
    from dataclasses import replace

    import momentid as mi
    from momentid.core.series import Experiment
    from momentid.core.structure import LabStatement

    runs = [mi.simulate(scenario(s, i, friction)).runs[0] for i, s in enumerate(SCALES)]
    runs = [replace(r, name=f"trial{i + 1}") for i, r in enumerate(runs)]
    return Experiment(runs=tuple(runs), statement=LabStatement(storeys=STOREYS, masses=tuple(MASSES)),
                      source="rig5_joint_friction")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.rig5_joint_friction", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    load = os.getloadavg()
    d, costs = measured_diagnosis(experiment(), structure=scenario(SCALES[0], 0, friction=False).structure)
    row = {"verdict": d.mechanism, "location": d.location, "named": [m.to_dict() for m in d.mechanisms],
           "nrmse_before": d.nrmse_before, "nrmse_after": d.nrmse_after, **costs,
           "load_average": [round(x, 1) for x in load], "machine": machine()}
    lines = ["| rig | verdict | held-out NRMSE before -> after | time (wall / CPU) | x raw rollout (wall / CPU) "
             "| replays | load average |", "|---|---|---|---|---|---|---|",
             f"| 5 storeys, accelerometers only, joint friction in storey 2, 4 trials x {DURATION:g} s at "
             f"{SAMPLE_RATE:g} Hz | {d.mechanism} {json.dumps(d.location)} | {100 * d.nrmse_before:.2f} % -> "
             f"{100 * d.nrmse_after:.2f} % | {costs['seconds']:.0f} s / {costs['cpu_seconds']:.0f} s | "
             f"{costs['ratio']:.0f}x / {costs['cpu_ratio']:.0f}x | {costs['replays']} | {load[0]:.1f} |"]
    save(args.out, "rig5_joint_friction", row, lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
