"""Write a twin's folder whole or not at all, and read it back.

:func:`write_twin` follows the one output rule (:mod:`momentid.io.outputs`): it builds every file in a
private folder inside ``DIR`` and renames each into place at the end, so ``DIR`` never holds a
half-built file and an error (or an interrupt) leaves it as it was.  Only the twin's files are written:
the user's other files in ``DIR`` are never touched, a file of a twin's name that ``momentid twin`` did
not write is refused (unless ``force``), and the plots of a previous twin that are not drawn again are
removed.  One writer per folder: ``DIR`` is held (:func:`momentid.io.exclusive.exclusive`) while the
twin is written, so a second writer of the same folder gets one line naming it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
import json
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from momentid.core.series import Experiment, json_safe
from momentid.errors import MomentidError, RecordingError
from momentid.io.outputs import OwnedFolder
from momentid.twin.parameters import ExtraMode, SensorModel, TwinParameters

if TYPE_CHECKING:
    from momentid.twin.build import Twin

__all__ = ["write_twin", "read_twin", "check_against", "file_names", "output_folder", "TWIN_XML", "TWIN_JSON",
           "TRANSFER_PNG", "TwinFolderError"]

TWIN_XML, TWIN_JSON, TRANSFER_PNG = "twin.xml", "twin.json", "transfer.png"


class TwinFolderError(MomentidError):
    """The twin's output folder cannot be used, or a twin folder cannot be read."""


def file_names(runs: Iterable[str], plots: bool = True) -> list[str]:
    """Every file a twin of trials ``runs`` may write (checked against the folder before the build)."""
    from momentid.twin.plots import replay_files

    return [TWIN_XML, TWIN_JSON] + ([TRANSFER_PNG, *replay_files(runs).values()] if plots else [])


def output_folder(out: str | os.PathLike, *, force: bool = False) -> OwnedFolder:
    """The twin's folder ``out`` under the one output rule (:mod:`momentid.io.outputs`)."""
    return OwnedFolder(out, "twin", force=force)


def _write_files(twin, experiment, folder: Path, plots: bool, extra=None) -> list:
    from momentid.core.processes import run_forked
    from momentid.twin import plots as plotting

    (folder / TWIN_XML).write_text(twin.xml)
    text = json.dumps(json_safe(twin.to_dict()), indent=2, allow_nan=False) + "\n"
    (folder / TWIN_JSON).write_text(text)
    names = [TWIN_XML, TWIN_JSON]
    if plots:           # each plot on its own: on the machine's cores, which inherit matplotlib loaded once
        plotting.pyplot()

        def plot(replay):
            if replay is None:
                return plotting.plot_transfer(twin, experiment, folder / TRANSFER_PNG).name
            return plotting.plot_replay(replay, folder / files[replay.run]).name

        files = plotting.replay_files([replay.run for replay in twin.replays])
        names += run_forked(plot, list(twin.replays) + [None])
    if extra is not None:
        names += extra(folder)
    return names


def write_twin(twin: Twin, experiment: Experiment, out: str | os.PathLike, *, plots: bool = True, force: bool = False,
               extra: Callable[[Path], list[str]] | None = None) -> list[str]:
    """Write ``twin.xml``, ``twin.json`` and the plots into the folder ``out``, each file whole.

    The folder follows the one output rule (:class:`momentid.io.outputs.OwnedFolder`): only the
    twin's files are written; every other file in ``out`` is left alone; a file of the same name that
    ``momentid twin`` did not write is refused, unless ``force``; the plots of a previous twin that
    this one does not draw again are removed.  Nothing in ``out`` changes until every file is built.

    Parameters
    ----------
    twin : Twin
        From :func:`momentid.twin.build.build_twin`.
    experiment : Experiment
        The recording it was built from (the plots' recorded spectra).
    out : str or Path
        The folder; created when missing.
    plots : bool
        Write the PNG plots too.
    force : bool
        Overwrite files of the twin's names that ``momentid twin`` did not write.
    extra : callable, optional
        ``extra(folder)`` writes more files into the folder being built (the report page of
        :mod:`momentid.report`, which this layer does not import) and returns their names.

    Returns
    -------
    list of str
        The file names written, in ``out``.

    Raises
    ------
    OutputRefusedError
        ``out`` is a file, cannot be written, or holds a file of the twin's names it did not write.
    OutputBusyError
        Another process is writing ``out`` (left as that process writes it).
    """
    return output_folder(out, force=force).write(lambda staging: _write_files(twin, experiment, staging, plots, extra))


def _sensors(d: dict) -> SensorModel:
    return SensorModel(np.asarray(d["gain"], float), np.asarray(d["clock_offset_s"], float),
                       np.asarray(d["bias_m_s2"], float))


def read_twin(folder: str | os.PathLike) -> TwinParameters:
    """The parameters of a twin folder written by :func:`write_twin` (from its ``twin.json``).

    Raises
    ------
    TwinFolderError
        No ``twin.json``, or not one a twin wrote.
    """
    path = Path(folder) / TWIN_JSON
    try:
        data = json.loads(path.read_text())
        sensors = {run: _sensors(s) for run, s in data["sensors"]["runs"].items()}
        d = int(data["storeys"])
        params = TwinParameters(
            masses=np.asarray(data["masses_kg"], float), K=np.asarray(data["K_N_m"], float),
            C=np.asarray(data["C_N_s_m"], float), storey_heights=np.asarray(data["storey_heights_m"], float),
            sensors=sensors, nominal=_sensors(data["sensors"]["nominal"]),
            extra_modes=tuple(ExtraMode(float(e["frequency_hz"]), float(e["damping_ratio"]),
                                        np.asarray(e["residues"], float)) for e in data["extra_modes"]),
            mass_normalised=bool(data["mass_normalised"]), added_mass_damping=float(data["added_mass_damping_1_s"]),
            source=str(data["identification"]), runs=tuple(data["calibrated_on"]), notes=tuple(data["notes"]))
    except FileNotFoundError:
        raise TwinFolderError(f"{folder}: no {TWIN_JSON}: expected a folder written by `momentid twin`") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise TwinFolderError(f"{path}: not a twin written by `momentid twin` ({type(exc).__name__}: {exc})") from None
    if params.K.shape != (d, d) or params.C.shape != (d, d) or params.masses.shape != (d,):
        raise TwinFolderError(f"{path}: K, C and masses have shapes {params.K.shape}, {params.C.shape}, "
                              f"{params.masses.shape}: expected ({d}, {d}) and ({d},)")
    _check_values(params, path)
    return params


def _check_values(params: TwinParameters, path: Path) -> None:
    """Refuse a twin.json whose values no rig has (NaN, a gain of 1e308, a K that is not positive
    definite), naming the key and value, before anything is computed from them."""
    from momentid.estimation.modal_model import GAIN_RANGE

    def refuse(key, value, expected):
        raise TwinFolderError(f"{path}: key '{key}' = {value}: expected {expected} (a twin written by "
                              f"`momentid twin` has them; was the file edited?)")

    arrays = {"masses_kg": params.masses, "K_N_m": params.K, "C_N_s_m": params.C,
              "storey_heights_m": params.storey_heights, "added_mass_damping_1_s": params.added_mass_damping}
    for run, sensors in [("nominal", params.nominal), *params.sensors.items()]:
        arrays.update({f"sensors.{run}.gain": sensors.gain, f"sensors.{run}.clock_offset_s": sensors.clock_offset,
                       f"sensors.{run}.bias_m_s2": sensors.bias})
    for key, value in arrays.items():
        if not np.all(np.isfinite(value)):
            refuse(key, np.asarray(value).tolist(), "finite numbers")
    if np.any(params.masses <= 0):
        refuse("masses_kg", params.masses.tolist(), "positive floor masses")
    if np.any(params.storey_heights <= 0):
        refuse("storey_heights_m", params.storey_heights.tolist(), "positive storey heights")
    for key, M in (("K_N_m", params.K), ("C_N_s_m", params.C)):
        if not np.allclose(M, M.T, rtol=1e-9, atol=0.0):
            refuse(key, M.tolist(), "a symmetric matrix")
    if np.linalg.eigvalsh(params.K).min() <= 0:
        refuse("K_N_m", params.K.tolist(), "a positive definite stiffness matrix")
    if np.linalg.eigvalsh(params.C).min() < -1e-9 * np.abs(params.C).max():   # rounding of a PSD matrix
        refuse("C_N_s_m", params.C.tolist(), "a positive semi-definite damping matrix")
    for run, sensors in [("nominal", params.nominal), *params.sensors.items()]:
        gain = np.asarray(sensors.gain, float)
        if np.any((gain < GAIN_RANGE[0]) | (gain > GAIN_RANGE[1])):
            refuse(f"sensors.{run}.gain", gain.tolist(), f"sensor gains of {GAIN_RANGE[0]:g}-{GAIN_RANGE[1]:g} "
                                                         "x the table's (an accelerometer's calibration)")
        if np.any(np.abs(sensors.clock_offset) > 1.0):
            refuse(f"sensors.{run}.clock_offset_s", np.asarray(sensors.clock_offset).tolist(),
                   "clock offsets within 1 s (the import aligns clocks to a few samples)")


def check_against(params: TwinParameters, experiment: Experiment) -> None:
    """Refuse a twin of another rig or recording than ``experiment``: another storey count, trials it
    was calibrated on that the recording does not hold (the twin of another recording: a simulated
    scenario's twin over a real rig), or other stated floor masses.

    Raises
    ------
    RecordingError
    """
    where = f"the twin (calibrated on {', '.join(params.runs)})"
    if params.storeys != experiment.storeys:
        raise RecordingError(f"the twin has {params.storeys} storeys but {experiment.source} records "
                             f"{experiment.storeys}: it is the twin of another rig")
    names = {run.name for run in experiment.runs}
    missing = [r for r in params.runs if r not in names]
    if missing:
        raise RecordingError(f"{where}: {experiment.source} has no trial named {missing[0]!r} (its trials: "
                             f"{', '.join(sorted(names))}): expected the twin of this recording; it is the "
                             "twin of another recording")
    stated = experiment.statement.masses if experiment.statement is not None else None
    if stated is None and experiment.structure is not None:
        stated = experiment.structure.masses
    if not params.mass_normalised and stated is not None and not np.allclose(params.masses, stated, rtol=1e-6):
        raise RecordingError(f"{where}: floor masses {params.masses.tolist()} kg but {experiment.source} states "
                             f"{np.asarray(stated, float).tolist()} kg: expected the twin of this recording")
