"""The calibrated MuJoCo twin of a real rig (``momentid twin``).

Build it from a recording, or piece by piece::

    from momentid.twin import build_twin, write_twin, from_identification, twin_spec, replay_run
    twin = build_twin(experiment)                       # identify, build the MJCF, replay every trial
    write_twin(twin, experiment, "twin/")               # twin.xml, twin.json, plots, atomically

    params = twin.parameters                            # or from_identification(result, experiment)
    spec = twin_spec(params, step, sensors=params.sensors_of("run"))   # edit (add a mechanism) ...
    model = momentid.lab.rig.compile_model(spec)                       # ... then compile
    replay = replay_run(params, experiment.run("run"), model=model)    # NRMSE of the edited twin

Modules: :mod:`~momentid.twin.parameters` (what the twin is made of, K and C as tendons),
:mod:`~momentid.twin.spec` (the MJCF), :mod:`~momentid.twin.replay` (drive, sensor model, NRMSE),
:mod:`~momentid.twin.build` (identification, refusals, the :class:`Twin`),
:mod:`~momentid.twin.files` (the folder), :mod:`~momentid.twin.plots`, :mod:`~momentid.report.twin_overlay` (its layer
in the rerun viewer).
"""

from momentid.twin.build import Twin, build_twin, check_recording, refusals
from momentid.twin.files import read_twin, write_twin
from momentid.twin.parameters import ExtraMode, SensorModel, Tendon, TwinParameters, from_identification, tendon_layout
from momentid.twin.replay import Replay, replay_run, transfer
from momentid.twin.spec import Timing, model_matrices, timing, twin_spec

__all__ = ["Twin", "build_twin", "check_recording", "refusals", "read_twin", "write_twin", "ExtraMode",
           "SensorModel", "Tendon", "TwinParameters", "from_identification", "tendon_layout", "Replay",
           "replay_run", "transfer", "Timing", "model_matrices", "timing", "twin_spec"]
