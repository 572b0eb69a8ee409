"""Campaigns: one base scenario, many variants, each simulated, identified and scored.

A sweep file (TOML) names a base scenario and a grid of values for dotted
scenario keys; every combination of the values (Cartesian product) is one
case::

    [sweep]
    base = "../scenarios/tall_noise.toml"  # relative to this file (default: the embedded default)
    estimator = "equation"                 # or "difference" (default "equation")

    [grid]
    scenario.seed = [0, 1, 2, 3]           # seeds every random choice: noise excitation, sensor noise
    structure.storey_stiffness = [3.0e5, 2.5e5]
    runs.1.added_mass = [[2.0, 0.0, 1.5, 0.0, 2.0, 0.0, 1.0, 0.0, 1.5, 1.0], 1.0]   # [[runs]] index from 0

Each case is the base scenario's parsed TOML with its values put in and is
validated by :func:`momentid.lab.scenario.parse_scenario` as strictly as a
scenario file: an unknown key or a bad value is a :class:`ScenarioError`
naming the sweep file, the key and the value before anything runs.

:func:`run_sweep` runs the cases on every local core (a process pool), or
on a Dask cluster when given the scheduler's address (``pip install
'momentid[cluster]'``; momentid must be installed on the workers).  Each
case gives one row: its values, the identified parameters, the analytic
ones and their relative errors, or the error that stopped it.
"""

from __future__ import annotations

import csv
import io
import itertools
import json
import math
import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from collections.abc import Callable

from momentid.io.exclusive import write_whole
from momentid.io.toml_reader import Table, load_toml
from momentid.errors import MomentidError, ScenarioError
from momentid.lab.scenario import Scenario, default_scenario_path, parse_scenario, set_key

__all__ = ["Case", "Sweep", "load_sweep", "parse_sweep", "run_case", "run_sweep", "write_table",
           "table_columns", "table_path", "table_text"]


@dataclass(frozen=True)
class Case:
    """One scenario variant: ``values`` maps each grid key to this case's value."""

    index: int
    values: dict
    scenario: Scenario


@dataclass(frozen=True)
class Sweep:
    """A validated sweep: every case's scenario is already parsed."""

    source: str
    base: str
    estimator: str
    keys: tuple[str, ...]
    cases: tuple[Case, ...]


def load_sweep(path: str | os.PathLike) -> Sweep:
    """Read and validate a sweep file (see the module docstring)."""
    path = Path(path)
    return parse_sweep(load_toml(path), source=path)


def _grid_items(node: Any, prefix: str, source: Path) -> list[tuple[str, list]]:
    """Flatten ``[grid]``: nested tables become dotted keys, arrays are the values."""
    if isinstance(node, list):
        if not node:
            raise ScenarioError(f"{source}: key 'grid.{prefix}' = []: expected a non-empty array of "
                                "values to sweep")
        twice = [v for i, v in enumerate(node) if v in node[:i]]
        if twice:   # the same case twice would count twice in any statistic over the table
            raise ScenarioError(f"{source}: key 'grid.{prefix}' = {node!r}: {twice[0]!r} is listed twice; "
                                "expected each value once")
        return [(prefix, node)]
    if not isinstance(node, dict) or not node:
        raise ScenarioError(f"{source}: key 'grid.{prefix}' = {node!r}: expected an array of values "
                            "to sweep (e.g. [0, 1, 2])")
    out = []
    for key, value in node.items():
        out += _grid_items(value, f"{prefix}.{key}" if prefix else key, source)
    return out


def _variant(base: dict, values: dict, base_path: Path, text: str) -> Scenario:
    import copy

    data = copy.deepcopy(base)
    for key, value in values.items():
        set_key(data, key, value)
    return parse_scenario(data, source=base_path, text=text)


def parse_sweep(data: dict, *, source: str | os.PathLike = "<string>") -> Sweep:
    """Validate an already-parsed sweep file and build every case's scenario."""
    from momentid.estimation.identification import ESTIMATORS

    source = Path(source)
    top = Table(data, source)
    head = top.table("sweep", {})
    base_name = head.string("base", "")
    estimator = head.string("estimator", "equation", choices=tuple(ESTIMATORS))
    head.finish()
    grid_table = top.table("grid", None)
    top.finish()
    grid = None if grid_table is None else grid_table.data
    if grid is None:
        raise ScenarioError(f"{source}: missing table [grid]: expected the values to sweep, "
                            "e.g. scenario.seed = [0, 1, 2]")
    items = _grid_items(grid, "", source)

    base_path = Path(os.path.normpath(source.parent / base_name)) if base_name else default_scenario_path()
    if base_name and not base_path.is_file():
        raise ScenarioError(f"{source}: key 'sweep.base' = {base_name!r}: no such file {base_path}")
    base = load_toml(base_path)
    text = base_path.read_text(encoding="utf-8")

    # Each key and value on its own first, so an error names exactly one of them.
    for key, values in items:
        for value in values:
            try:
                _variant(base, {key: value}, base_path, text)
            except ScenarioError as e:
                raise ScenarioError(f"{source}: grid key '{key}' = {value!r}: {e}") from None
    keys = tuple(k for k, _ in items)
    cases = []
    for index, combo in enumerate(itertools.product(*(v for _, v in items))):
        values = dict(zip(keys, combo))
        try:
            scenario = _variant(base, values, base_path, text)
        except ScenarioError as e:
            what = ", ".join(f"{k} = {v!r}" for k, v in values.items())
            raise ScenarioError(f"{source}: case {index} ({what}): {e}") from None
        cases.append(Case(index, values, scenario))
    return Sweep(source=str(source), base=str(base_path), estimator=estimator, keys=keys,
                 cases=tuple(cases))


# ----------------------------------------------------------------------------- running

#: MuJoCo's control callback is process-global, so a worker process with
#: several threads (a Dask worker, say) simulates one case at a time.
_SIMULATION_LOCK = threading.Lock()


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def run_case(index: int, values: dict, scenario: Scenario, estimator: str) -> dict:
    """Simulate, identify and compare one case; its row of the result table.

    A module-level function of picklable arguments, so any process pool or
    cluster can run it.  Errors momentid raises on purpose (a diverging
    simulation, unidentifiable data) become the row's ``error``.
    """
    from momentid.estimation.comparison import compare
    from momentid.estimation.identification import identify
    from momentid.lab.simulation import simulate

    row: dict = {"case": index, "values": values, "status": "ok", "error": None}
    t0 = time.perf_counter()
    try:
        with _SIMULATION_LOCK:
            experiment = simulate(scenario, workers=1)
        result = identify(experiment, estimator=estimator)
        comparison = compare(result, scenario.structure)
    except MomentidError as e:
        row.update(status="error", error=f"{type(e).__name__}: {e}", seconds=time.perf_counter() - t0)
        return row
    row.update(
        seconds=time.perf_counter() - t0,
        max_rel_error=_finite(comparison.max_rel_error),
        condition=_finite(result.condition),
        residual_rms=_finite(result.residual_rms),
        n_equations=int(result.n_equations), n_unknowns=int(result.n_unknowns),
        identified={e.name: _finite(e.identified) for e in comparison.entries},
        analytic={e.name: _finite(e.analytic) for e in comparison.entries},
        rel_error={e.name: _finite(e.rel_error) for e in comparison.entries},
    )
    return row


def _local(payloads: list[tuple], workers: int, done: Callable[[dict], None]) -> list[dict]:
    from concurrent.futures import as_completed

    from momentid.core.processes import forked_pool

    with forked_pool(workers) as pool:   # workers that die with the sweep
        futures = [pool.submit(run_case, *p) for p in payloads]
        for future in as_completed(futures):
            done(future.result())
        return [f.result() for f in futures]


def _serial(payloads: list[tuple], done: Callable[[dict], None]) -> list[dict]:
    rows = []
    for p in payloads:
        rows.append(run_case(*p))
        done(rows[-1])
    return rows


def _dask(payloads: list[tuple], address: str, done: Callable[[dict], None]) -> list[dict]:
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise MomentidError(f"--address {address}: running on a cluster needs Dask "
                            "(pip install 'momentid[cluster]')") from None
    try:
        client = Client(address, timeout="10s")
    except (OSError, TimeoutError) as e:
        raise MomentidError(f"--address {address}: cannot reach a Dask scheduler there ({e}); "
                            "expected the address of a running scheduler, e.g. tcp://host:8786") from None
    with client:
        futures = client.map(run_case, *zip(*payloads), pure=False)
        for future in as_completed(futures):
            done(future.result())
        return client.gather(futures)


def run_sweep(sweep: Sweep, *, workers: int | None = None, address: str | None = None,
              on_case: Callable[[dict], None] | None = None) -> list[dict]:
    """Run every case; the rows in case order (see :func:`run_case`).

    Parameters
    ----------
    workers : int, optional
        Local worker processes (default: one per available core); ``1``
        runs in this process.  Ignored with ``address``.
    address : str, optional
        A Dask scheduler (``tcp://host:8786``, or any address
        ``distributed.Client`` accepts): the cases run on its workers, which
        need momentid installed.
    on_case : callable, optional
        Called with each row as it completes (in completion order).
    """
    from momentid.lab.simulation import available_cores

    payloads = [(c.index, c.values, c.scenario, sweep.estimator) for c in sweep.cases]
    done = on_case or (lambda row: None)
    if address is not None:
        return _dask(payloads, address, done)
    workers = workers if workers is not None else available_cores()
    if not isinstance(workers, int) or workers < 1:
        raise MomentidError(f"workers = {workers!r}: expected an int >= 1")
    workers = min(workers, len(payloads))
    if workers == 1:
        return _serial(payloads, done)
    return _local(payloads, workers, done)


# ----------------------------------------------------------------------------- output

def table_columns(rows: list[dict]) -> list[str]:
    """CSV columns: case, the grid keys, status, scores, then per parameter
    ``id:``, ``an:`` and ``err:`` columns (identified, analytic, relative error)."""
    cols = ["case"]
    seen = set(cols)

    def add(name):
        if name not in seen:
            seen.add(name)
            cols.append(name)

    for row in rows:
        for k in row["values"]:
            add(k)
    for name in ("status", "max_rel_error", "condition", "residual_rms", "n_equations",
                 "n_unknowns", "seconds", "error"):
        add(name)
    for row in rows:
        for p in row.get("identified", {}):
            for prefix in ("id:", "an:", "err:"):
                add(prefix + p)
    return cols


def _flat(row: dict) -> dict:
    out = {"case": row["case"]}
    for k, v in row["values"].items():
        out[k] = json.dumps(v) if isinstance(v, (list, dict)) else v
    for name in ("status", "max_rel_error", "condition", "residual_rms", "n_equations",
                 "n_unknowns", "seconds", "error"):
        out[name] = row.get(name)
    for prefix, key in (("id:", "identified"), ("an:", "analytic"), ("err:", "rel_error")):
        for p, v in row.get(key, {}).items():
            out[prefix + p] = v
    return out


def table_path(path: str | os.PathLike) -> Path:
    """``path`` as a result table's name (``.csv`` or ``.json``), checked before a sweep starts."""
    path = Path(path)
    if path.suffix not in (".csv", ".json"):
        raise MomentidError(f"output {path}: expected a .csv or .json file name")
    return path


def table_text(rows: list[dict], path: str | os.PathLike) -> str:
    """The rows as CSV (``.csv``, one flat row per case) or JSON (``.json``), by ``path``'s suffix."""
    if table_path(path).suffix == ".json":
        return json.dumps(rows, indent=2, allow_nan=False) + "\n"
    out = io.StringIO(newline="")
    writer = csv.DictWriter(out, fieldnames=table_columns(rows))
    writer.writeheader()
    for row in rows:
        writer.writerow(_flat(row))
    return out.getvalue()


def write_table(rows: list[dict], path: str | os.PathLike) -> Path:
    """Write the rows as CSV (``.csv``, one flat row per case) or JSON (``.json``), whole or not at
    all and locked against a second writer (:func:`momentid.io.exclusive.write_whole`)."""
    return write_whole(table_path(path), table_text(rows, path).encode("utf-8"))
