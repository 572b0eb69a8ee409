"""Universal File Format (UFF) datasets, as modal-analysis tools exchange modes and frequency responses.

ASCII datasets, each between two ``    -1`` lines, written to the published layout (the SDRL
descriptions of datasets 15, 55, 58 and 164):

- :func:`units` (dataset 164): SI units (metre, newton, kelvin);
- :func:`nodes` (dataset 15): node coordinates (m);
- :func:`mode` (dataset 55, normal mode): one mode's shape at the nodes, its frequency and viscous
  damping ratio;
- :func:`function` (dataset 58): a function of frequency at a response node over a reference node
  (a frequency response function, a coherence), evenly spaced, real or complex, double precision.

ID lines hold at most 80 characters (longer ones are cut) and are never blank (``NONE``); a value
written is what a Fortran ``E13.5``/``E20.12`` read gives back.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from momentid.errors import RecordingError

__all__ = ["units", "nodes", "mode", "function", "FRF", "COHERENCE", "X"]

#: Dataset 58 function types.
FRF, COHERENCE = 4, 6
#: Direction code of +X translation (the shaking axis).
X = 1
#: Dataset 58 specific data types: frequency (abscissa), acceleration (numerator, denominator), general.
_FREQUENCY, _ACCELERATION, _GENERAL = 18, 12, 1
_LINE = "{:>6}\n"


def _delimited(body: str, number: int) -> str:
    return _LINE.format(-1) + f"{number:>6}\n" + body + _LINE.format(-1)


def _id(text: str) -> str:
    """One ID line: printable ASCII, at most 80 characters, ``NONE`` when empty."""
    clean = "".join(c if 32 <= ord(c) < 127 else "?" for c in str(text)).rstrip()[:80]
    return f"{clean or 'NONE':<80}\n"


def _e13(x: float) -> str:
    return f"{x:13.5E}"


def _finite(values, what: str) -> np.ndarray:
    values = np.asarray(values)
    if not np.all(np.isfinite(values)):
        raise RecordingError(f"UFF: {what} holds a value that is not finite: a UFF file carries numbers only")
    return values


def units() -> str:
    """Dataset 164: SI units (code 1, metre-newton-kelvin, absolute temperatures)."""
    body = f"{1:>10}{'SI - mks (m/newton)':<20}{1:>10}\n"
    body += "".join(f"{v:25.16E}".replace("E", "D") for v in (1.0, 1.0, 1.0)) + "\n"
    body += f"{273.15:25.16E}".replace("E", "D") + "\n"
    return _delimited(body, 164)


def nodes(numbers: Sequence[int], coordinates: ArrayLike) -> str:
    """Dataset 15: nodes ``numbers`` at ``coordinates`` (n, 3) in m (global coordinate system 0)."""
    xyz = _finite(coordinates, "node coordinates").reshape(len(numbers), 3)
    body = "".join(f"{n:>10}{0:>10}{0:>10}{0:>10}" + "".join(_e13(c) for c in row) + "\n"
                   for n, row in zip(numbers, xyz))
    return _delimited(body, 15)


def mode(number: int, frequency: float, damping_ratio: float, node_numbers: Sequence[int], shape: ArrayLike,
         ids: Sequence[str], modal_mass: float = 0.0, load_case: int = 1) -> str:
    """Dataset 55 of a normal mode: its shape along +X at ``node_numbers`` (3 values per node: X, Y, Z).

    Parameters
    ----------
    number : int
        Mode number (1 = lowest).
    frequency : float
        Hz.
    damping_ratio : float
        Modal viscous damping ratio (1).
    node_numbers : sequence of int
    shape : array_like, shape (n,)
        The shape's X component at each node (real).
    ids : sequence of str
        Up to five ID lines (the rest ``NONE``).
    modal_mass : float
        Modal mass of the shape as scaled (kg; 0: not given).
    load_case : int
        Load case number (one per set of modes: a run of its own, say).

    Returns
    -------
    str
    """
    shape = _finite(shape, f"mode {number}'s shape").astype(float)
    _finite([frequency, damping_ratio, modal_mass], f"mode {number}'s frequency, damping or modal mass")
    lines = [_id(t) for t in list(ids)[:5]] + [_id("")] * (5 - min(len(ids), 5))
    # model type 1 (structural), analysis type 2 (normal mode), data characteristic 2 (3 DOF translation),
    # specific data type 8 (displacement: a shape), data type 2 (real), 3 values per node
    body = "".join(lines) + "".join(f"{v:>10}" for v in (1, 2, 2, 8, 2, 3)) + "\n"
    body += "".join(f"{v:>10}" for v in (2, 4, load_case, number)) + "\n"
    body += "".join(_e13(v) for v in (frequency, modal_mass, damping_ratio, 0.0)) + "\n"
    for n, x in zip(node_numbers, shape):
        body += f"{n:>10}\n" + _e13(x) + _e13(0.0) + _e13(0.0) + "\n"
    return _delimited(body, 55)


def function(kind: int, number: int, frequency_step: float, values: ArrayLike, *, response_node: int,
             reference_node: int, ids: Sequence[str], ordinate: str) -> str:
    """Dataset 58 of a function of frequency from 0 in steps of ``frequency_step`` (Hz): ``values``
    (real or complex, double precision) at ``response_node`` (+X) over ``reference_node`` (+X).

    Parameters
    ----------
    kind : int
        :data:`FRF` (acceleration over acceleration) or :data:`COHERENCE` (1).
    number : int
        Function identification number.
    frequency_step : float
        Hz.
    values : array_like, shape (nf,)
    response_node, reference_node : int
    ids : sequence of str
        Up to five ID lines.
    ordinate : str
        The ordinate's axis label (20 characters at most).

    Returns
    -------
    str
    """
    values = _finite(values, f"function {number}")
    is_complex = np.iscomplexobj(values)
    lines = [_id(t) for t in list(ids)[:5]] + [_id("")] * (5 - min(len(ids), 5))
    body = "".join(lines)
    body += (f"{kind:>5}{number:>10}{1:>5}{0:>10} {'NONE':<10}{response_node:>10}{X:>4} "
             f"{'NONE':<10}{reference_node:>10}{X:>4}\n")
    body += (f"{6 if is_complex else 4:>10}{values.size:>10}{1:>10}"
             + _e13(0.0) + _e13(frequency_step) + _e13(0.0) + "\n")
    numerator = _ACCELERATION if kind == FRF else _GENERAL
    denominator = _ACCELERATION if kind == FRF else 0
    body += f"{_FREQUENCY:>10}{0:>5}{0:>5}{0:>5} {'Frequency':<20} {'Hz':<20}\n"
    body += f"{numerator:>10}{0:>5}{0:>5}{0:>5} {ordinate[:20]:<20} {'NONE':<20}\n"
    body += f"{denominator:>10}{0:>5}{0:>5}{0:>5} {'NONE':<20} {'NONE':<20}\n"
    body += f"{0:>10}{0:>5}{0:>5}{0:>5} {'NONE':<20} {'NONE':<20}\n"
    flat = np.column_stack([values.real, values.imag]).ravel() if is_complex else values.astype(float)
    for k in range(0, flat.size, 4):
        body += "".join(f"{v:20.12E}" for v in flat[k:k + 4]) + "\n"
    return _delimited(body, 58)
