"""Recordings: experiments stored as MCAP files with protobuf sensor blocks.

A recording holds one experiment: a ``momentid.experiment`` metadata record
(structure, scenario), then per run one channel ``/runs/<name>/sensors`` whose
messages are :data:`SCHEMA_NAME` blocks of up to ``block_size`` samples, an
optional model attachment and a ``momentid.run`` metadata record that marks
the run complete.  The layout is documented in ``docs/recording-format.md``.

Crash safety: every run is flushed and fsynced before its completion record
is written, so a writer that dies keeps every completed run; the reader
recovers them from a truncated file (see :func:`read_recording`).  A
recording written where a file already stands is written beside it
(``<name>.partial``) and renamed into place once complete, so a writer that
fails keeps the previous file whole, and its completed runs in the partial
file.

This module writes (:class:`RecordingWriter`, :func:`write_experiment`);
:mod:`momentid.io.recording_reader` reads, and :mod:`momentid.io.recording_format`
holds the record names and the SensorBlock schema both share.  The readers
and the format's public names are re-exported here.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import warnings
from pathlib import Path

import numpy as np
from mcap.writer import CompressionType, Writer

from momentid.core.series import UNITS, Experiment, RunData, channel_unit, json_safe, run_name_problem
from momentid.core.structure import LabStatement, Structure
from momentid.errors import OutputBusyError, RecordingError, RecoveryWarning
from momentid.io.exclusive import busy_error, exclusive, open_locked, partial_path
from momentid.io.recording_format import (ABORTED_RECORD, EXPERIMENT_RECORD, FORMAT_VERSION, IMPORT_META_KEYS,
                                          SCHEMA_DATA, SCHEMA_NAME, SENSOR_BLOCK_PROTO, RUN_RECORD, SensorBlock,
                                          check_sample_times, encode_block, run_topic)
from momentid.io.recording_reader import read_recording, stream_recording

__all__ = [
    "RecordingWriter",
    "write_experiment",
    "read_recording",
    "stream_recording",
    "FORMAT_VERSION",
    "SCHEMA_NAME",
    "SENSOR_BLOCK_PROTO",
    "SCHEMA_DATA",
    "SensorBlock",
    "run_topic",
]


def _json(value, what: str, path) -> str:
    try:
        return json.dumps(value, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise RecordingError(f"{path}: {what} = {value!r} is not JSON-serializable ({e}); "
                             "expected str, numbers, lists and dicts") from None


class RecordingWriter:
    """Write an experiment run by run; a context manager.

    The header and the ``momentid.experiment`` record are written and
    flushed on construction; each :meth:`write_run` makes its run durable
    before marking it complete.  Leaving the ``with`` block by an exception
    records ``momentid.aborted`` and still finishes the file.

    A file already at ``path`` (a previous recording) stays until the new one
    is complete: the new one is written to ``<path>.partial`` beside it and
    renamed over it by :meth:`close`.  When writing fails, ``path`` keeps the
    previous file and the partial file the completed runs (a
    :class:`~momentid.errors.RecoveryWarning` says so; with none completed it is
    removed).

    Parameters
    ----------
    path : str or Path
        The ``.mcap`` file to create (replaced once complete).
    structure : Structure or None
        Nominal model of the rig; fixes the number of storeys ``d`` that
        every run's ``added_mass`` must match.
    scenario : dict
        JSON-serializable scenario summary (``Scenario.summary()``).
    scenario_text : str
        The scenario file's text.
    extra_metadata : dict of str to str, optional
        More keys for the ``momentid.experiment`` record (not read back).
    statement : LabStatement, optional
        What a real lab states short of a nominal model (stored as JSON).
    """

    def __init__(self, path, *, structure: Structure | None, scenario: dict,
                 scenario_text: str = "", extra_metadata: dict[str, str] | None = None,
                 statement: LabStatement | None = None):
        self.path = Path(path)
        self._storeys = (structure.storeys if structure is not None
                         else statement.storeys if statement is not None else None)
        self._runs: list[str] = []  # names of the runs started, in index order
        self._completed = 0
        self._closed = True
        meta = {
            "format_version": FORMAT_VERSION,
            "scenario": _json(scenario, "scenario", self.path),
            "scenario_text": scenario_text,
            "structure": _json(structure.to_dict() if structure is not None else None,
                               "structure", self.path),
            "statement": _json(_statement_dict(statement), "statement", self.path),
            "units": json.dumps(UNITS),
            "storeys": "" if self._storeys is None else str(self._storeys),
        }
        for key, value in (extra_metadata or {}).items():
            if key in meta or not isinstance(key, str) or not isinstance(value, str):
                raise RecordingError(
                    f"{self.path}: extra_metadata key {key!r} = {value!r}: expected a str key other "
                    f"than {', '.join(meta)} and a str value")
            meta[key] = value
        # A previous file stays whole until this one is complete: written beside it, renamed at close().
        previous = self.path.is_file() and not self.path.is_symlink() and self.path.stat().st_size > 0
        self._target = partial_path(self.path) if previous else self.path
        self._held = contextlib.ExitStack()
        try:   # locked before it is truncated: a second writer of the same file is refused, not mixed in
            if previous:
                self._held.enter_context(exclusive(self.path))
            self._file = open_locked(self._target)
        except OutputBusyError:
            self._held.close()
            raise busy_error(self.path) from None   # the user's path, not the partial file
        except OSError as e:
            self._held.close()
            if e.errno == errno.ELOOP:
                raise RecordingError(f"{self.path}: a symbolic link; expected a regular file path (a recording "
                                     "is never written through a link onto another file)") from None
            raise RecordingError(f"{self.path}: cannot create the recording ({e.strerror}); "
                                 "expected a writable file path") from None
        self._closed = False
        # Uncompressed chunks: float64 sensor data shrink ~10 % with zstd, which halves read speed.
        self._writer = Writer(self._file, compression=CompressionType.NONE, enable_data_crcs=True)
        try:
            self._writer.start(profile="", library="momentid.io.recording format " + FORMAT_VERSION)
            self._schema_id = self._writer.register_schema(SCHEMA_NAME, "protobuf", SCHEMA_DATA)
            self._writer.add_metadata(EXPERIMENT_RECORD, meta)
            self._sync()
        except OSError as e:
            self._abandon()
            self._kept_beside()
            raise self._disk_error(e, "the header") from None
        except BaseException:
            self._abandon()
            self._kept_beside()
            raise

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc is None:
            self.close()
            return False
        try:
            if not self._closed:
                error = f"{exc_type.__name__}: {exc}" if str(exc) else exc_type.__name__
                self._writer.add_metadata(ABORTED_RECORD, {"error": error,
                                                           "runs_written": str(self._completed)})
            self._finish()
        except (OSError, RecordingError):
            # The disk refused more bytes (it is full, say): the completed runs are already fsynced
            # and read back as a truncated file; the error that got us here is the one to report.
            self._abandon()
        self._held.close()
        self._kept_beside(said=str(self._target) in str(exc))
        return False

    def _kept_beside(self, said: bool = False) -> None:
        """After a failure beside a previous file: that file stays; the completed runs stay in the
        partial file (said in a note unless the error ``said`` it), or nothing does."""
        if self._target == self.path:
            return
        kept = self._runs[:self._completed]
        if not kept:
            with contextlib.suppress(OSError):
                self._target.unlink()
            return
        if not said:
            warnings.warn(f"{self.path}: not replaced, the file there is kept; the {len(kept)} completed run(s) "
                          f"of the new recording ({', '.join(kept)}) are in {self._target}", RecoveryWarning,
                          stacklevel=3)

    def _abandon(self) -> None:
        """Close the file without writing more (after a write failed)."""
        self._closed = True
        try:
            self._file.close()
        except OSError:
            pass  # the bytes it still held could not be written either; the recovery note says so
        finally:
            self._held.close()

    def _disk_error(self, exc: OSError, doing: str) -> RecordingError:
        """A one-line error for a failed write that says what the file still holds."""
        kept = self._runs[:self._completed]
        where = "on disk" if self._target == self.path else f"in {self._target}"
        runs = (f"the {len(kept)} completed run(s) ({', '.join(kept)}) are {where} and read back "
                "with a note" if kept else "no run was completed")
        previous = "" if self._target == self.path else "the file there is kept; "
        return RecordingError(f"{self.path}: cannot write {doing} ({exc.strerror or exc}); {previous}{runs}; "
                              "expected free space on the disk")

    def _sync(self) -> None:
        self._writer.flush()  # closes the open chunk
        self._file.flush()
        os.fsync(self._file.fileno())

    def write_run(self, run: RunData, *, model_xml: str | None = None, block_size: int = 1000) -> None:
        """Append one run and mark it complete once it is on disk.

        Parameters
        ----------
        run : RunData
            ``time`` shape (n,) s, finite and strictly increasing, n >= 1;
            ``values`` shape (n, c) in SI units; ``added_mass`` shape (d,) kg.
        model_xml : str, optional
            MuJoCo XML of the model that produced the run; stored as the
            attachment ``models/<name>.xml``.
        block_size : int
            Samples per SensorBlock message (1000 keeps messages ~100 kB
            for 10 channels).

        Raises
        ------
        RecordingError
            The writer is closed, the name is empty or already used, or the
            data would not read back (bad times, channel names, added mass), or
            the disk refused the bytes (full: the message names the runs kept).
        """
        try:
            self._write_run(run, model_xml, block_size)
        except OSError as e:  # a full disk, an I/O error
            raise self._disk_error(e, f"run {run.name!r}") from None

    def _write_run(self, run: RunData, model_xml: str | None, block_size: int) -> None:
        where = f"{self.path}: run {run.name!r}"
        if self._closed:
            raise RecordingError(f"{where}: the writer is closed; expected write_run before close()")
        if not run.name or run.name in self._runs:
            raise RecordingError(f"{where}: expected a non-empty run name not already used "
                                 f"(used: {', '.join(self._runs) or 'none'})")
        problem = run_name_problem(run.name)
        if problem:
            raise RecordingError(f"{where}: the run name has {problem}; expected a name of one printable line "
                                 "without '/', '\\', '..' or ','")
        if not isinstance(block_size, int) or block_size < 1:
            raise RecordingError(f"{where}: block_size = {block_size!r}; expected an int >= 1")
        channels = tuple(run.channels)
        for c in channels:
            if not c or "," in c or channels.count(c) > 1:
                raise RecordingError(f"{where}: channel name {c!r}; expected unique non-empty names "
                                     "without commas")
        t = np.ascontiguousarray(run.time, dtype="<f8")
        n = t.shape[0]
        if t.ndim != 1 or not 1 <= n < 2**32:
            raise RecordingError(f"{where}: time has shape {t.shape}; expected (n,) with 1 <= n < 2**32")
        check_sample_times(t, where)
        v = np.ascontiguousarray(run.values, dtype="<f8").reshape(n, len(channels))
        added = [float(x) for x in np.asarray(run.added_mass, dtype=float).ravel()]
        if not np.all(np.isfinite(added)) or (self._storeys is not None and len(added) != self._storeys):
            raise RecordingError(f"{where}: added_mass = {added!r}; expected {self._storeys or 'd'} "
                                 "finite masses (kg), one per floor")
        added_json = json.dumps(added)
        index = str(len(self._runs))
        channel_meta = {
            "run": run.name, "index": index, "channels": ",".join(channels),
            "units": ",".join(channel_unit(c) for c in channels), "added_mass": added_json,
        }
        imported = {k: run.meta[k] for k in IMPORT_META_KEYS if k in run.meta}
        if imported:
            channel_meta["import"] = _json(json_safe(imported), "run.meta", where)
        ch_id = self._writer.register_channel(run_topic(run.name), "protobuf", self._schema_id, channel_meta)
        self._runs.append(run.name)  # its topic is taken even if this run fails
        stamps = np.maximum(np.round(t * 1e9), 0)  # log_time: first sample's time in ns
        for k, i in enumerate(range(0, n, block_size)):
            j = min(i + block_size, n)
            data = encode_block(run.name, i, channels, t[i:j], v[i:j])
            self._writer.add_message(ch_id, int(stamps[i]), data, int(stamps[i]), sequence=k)
        self._writer.flush()
        if model_xml is not None:
            self._writer.add_attachment(int(stamps[0]), int(stamps[0]), f"models/{run.name}.xml",
                                        "application/xml", model_xml.encode("utf-8"))
        self._sync()
        self._writer.add_metadata(RUN_RECORD, {
            "name": run.name, "index": index, "added_mass": added_json, "n_samples": str(n),
            "channels": ",".join(channels), "sample_rate": repr(float(run.sample_rate)),
            "complete": "true",
        })
        self._sync()
        self._completed += 1

    def close(self) -> None:
        """Write the summary and footer, close the file and (beside a previous file) put it in place
        of that file (idempotent)."""
        if self._closed:
            return
        self._finish()
        if self._target != self.path:
            try:
                os.replace(self._target, self.path)
            except OSError as e:
                raise RecordingError(f"{self.path}: cannot put the new recording in place ({e.strerror or e}); "
                                     f"the file there is kept and the new one, complete, is {self._target}; "
                                     f"expected a folder this user can rename files in") from None
            finally:
                self._held.close()

    def _finish(self) -> None:
        """Write the summary and footer, make them durable and close the file where it is written."""
        if self._closed:
            return
        try:
            self._writer.finish()
            self._file.flush()
            os.fsync(self._file.fileno())
        except OSError as e:
            self._abandon()
            raise self._disk_error(e, "the summary and footer") from None
        self._closed = True
        self._file.close()


def write_experiment(path: str | os.PathLike, experiment: Experiment, *,
                     model_xml: dict[str, str] | None = None) -> Path:
    """Write all runs of ``experiment`` to a new recording.

    Parameters
    ----------
    path : str or Path
        The ``.mcap`` file to create (overwritten).
    experiment : Experiment
        Runs (with an imported run's ``meta`` keys :data:`IMPORT_META_KEYS`),
        structure, statement, scenario summary and text; ``complete`` and
        ``notes`` are not stored.
    model_xml : dict of str to str, optional
        MuJoCo XML per run name; a run not in it keeps ``run.meta["model_xml"]``
        when present, so reading and rewriting a recording keeps its models.

    Returns
    -------
    Path
        ``path``.
    """
    models = dict(model_xml or {})
    names = {r.name for r in experiment.runs}
    unknown = sorted(set(models) - names)
    if unknown:
        raise RecordingError(f"{path}: model_xml names run {unknown[0]!r}; expected one of "
                             f"{', '.join(sorted(names))}")
    with RecordingWriter(path, structure=experiment.structure, scenario=experiment.scenario,
                         scenario_text=experiment.scenario_text, statement=experiment.statement) as writer:
        for run in experiment.runs:
            writer.write_run(run, model_xml=models.get(run.name, run.meta.get("model_xml")))
    return Path(path)



def _statement_dict(statement: LabStatement | None) -> dict | None:
    if statement is None:
        return None
    return {"storeys": statement.storeys,
            "masses": None if statement.masses is None else list(statement.masses),
            "storey_heights": None if statement.storey_heights is None else list(statement.storey_heights),
            "noise": [[group, value] for group, value in statement.noise]}

