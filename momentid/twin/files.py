"""Write a twin's folder whole or not at all, and read it back.

:func:`write_twin` builds every file in a temporary folder beside ``DIR`` and renames it into place at
the end, so ``DIR`` never holds a half-built file: an error (or an interrupt) leaves ``DIR`` as it was.
A ``DIR`` that exists must be empty or a previous twin (it holds ``twin.json``): it is replaced whole;
a folder with other files is refused rather than emptied.  One writer per folder: ``DIR`` is held
(:func:`momentid.io.exclusive.exclusive`) while the twin is written, so a second writer of the same
folder gets one line naming it and the first finishes intact.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from momentid.core.series import json_safe
from momentid.errors import MomentidError, RecordingError
from momentid.io.exclusive import exclusive
from momentid.twin.parameters import ExtraMode, SensorModel, TwinParameters

__all__ = ["write_twin", "read_twin", "check_against", "TWIN_XML", "TWIN_JSON", "TRANSFER_PNG", "TwinFolderError"]

TWIN_XML, TWIN_JSON, TRANSFER_PNG = "twin.xml", "twin.json", "transfer.png"


class TwinFolderError(MomentidError):
    """The twin's output folder cannot be used, or a twin folder cannot be read."""


def _check_out(out: Path) -> None:
    if out.exists() and not out.is_dir():
        raise TwinFolderError(f"-o {out}: a file of that name exists; expected a folder (or a new path)")
    if out.is_dir() and any(out.iterdir()) and not (out / TWIN_JSON).exists():
        raise TwinFolderError(f"-o {out}: the folder holds files and no {TWIN_JSON}: expected a new or empty "
                              f"folder, or a previous twin's (which is replaced whole)")


def _write_files(twin, experiment, folder: Path, plots: bool, extra=None) -> list:
    from momentid.diagnosis.workers import run_forked
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
            return plotting.plot_replay(replay, folder / plotting.replay_file(replay.run)).name

        names += run_forked(plot, list(twin.replays) + [None])
    if extra is not None:
        names += extra(folder)
    return names


def write_twin(twin, experiment, out, *, plots: bool = True, extra=None) -> list:
    """Write ``twin.xml``, ``twin.json`` and the plots into the folder ``out``, atomically.

    Parameters
    ----------
    twin : Twin
        From :func:`momentid.twin.build.build_twin`.
    experiment : Experiment
        The recording it was built from (the plots' recorded spectra).
    out : str or Path
        The folder; created, or replaced when it holds a previous twin.
    plots : bool
        Write the PNG plots too.
    extra : callable, optional
        ``extra(folder)`` writes more files into the folder being built (the report page of
        :mod:`momentid.report`, which this layer does not import) and returns their names.

    Returns
    -------
    list of str
        The file names written, in ``out``.

    Raises
    ------
    TwinFolderError
        ``out`` is a file, or a folder holding other files.
    OutputBusyError
        Another process is writing ``out`` (left as that process writes it).
    """
    out = Path(out)
    _check_out(out)
    with exclusive(out):    # one writer per folder (a new one is made here, and removed on failure)
        return _replace(twin, experiment, out, plots, extra)


def _replace(twin, experiment, out: Path, plots: bool, extra=None) -> list:
    """Build the folder beside ``out`` and rename it into place (see :func:`write_twin`)."""
    parent = out.absolute().parent
    parent.mkdir(parents=True, exist_ok=True)
    building = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=parent))
    old = None
    try:
        names = _write_files(twin, experiment, building, plots, extra)
        os.chmod(building, 0o755)                    # mkdtemp makes it private; a result folder is not
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=parent))
            os.replace(out, old / out.name)
        os.replace(building, out)
    except BaseException:
        shutil.rmtree(building, ignore_errors=True)
        if old is not None and not out.exists() and (old / out.name).exists():
            os.replace(old / out.name, out)          # put the previous twin back
        raise
    finally:
        if old is not None:
            with contextlib.suppress(OSError):
                shutil.rmtree(old)
    return names


def _sensors(d: dict) -> SensorModel:
    return SensorModel(np.asarray(d["gain"], float), np.asarray(d["clock_offset_s"], float),
                       np.asarray(d["bias_m_s2"], float))


def read_twin(folder) -> TwinParameters:
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
    return params


def check_against(params: TwinParameters, experiment) -> None:
    """Refuse a twin of another rig than ``experiment``'s (storey count).

    Raises
    ------
    RecordingError
    """
    if params.storeys != experiment.storeys:
        raise RecordingError(f"the twin has {params.storeys} storeys but {experiment.source} records "
                             f"{experiment.storeys}: it is the twin of another rig")
