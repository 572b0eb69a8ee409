"""AT2 records (PEER accelerograms) fed to a scenario's ``type = "record"`` excitation."""

from __future__ import annotations

from pathlib import Path

import momentid as mi

from ._core import Case, Group, Outcome
from .scenario import write

_HEADER = "PEER STRONG MOTION DATABASE RECORD\nTEST RECORD\nACCELERATION TIME SERIES IN UNITS OF G\n"
#: 8 values at 0.02 s: a well-formed record's body.
_VALUES = "0.0 0.001 0.002 -0.001\n0.003 -0.002 0.001 0.0\n"
GOOD = _HEADER + "NPTS=    8, DT= .0200 SEC\n" + _VALUES


def _scenario_with_record(text: str | bytes):
    """A scenario whose excitation is the record ``r.at2`` holding ``text``."""
    def act(folder: Path):
        at2 = folder / "r.at2"
        if isinstance(text, bytes):
            at2.write_bytes(text)
        else:
            at2.write_text(text, encoding="latin-1")
        path = write(folder, 'type = "harmonic"\namplitude = 0.002\nangular_frequency = 6.2832',
                     'type = "record"\nfile = "r.at2"\nscale = 1.0\nhighpass = 0.0\ntaper = 0.0')
        return mi.simulate(mi.load_scenario(path))
    return act


#: (id, file text, what the message must name).
_BAD = [
    ("no-npts-line", _HEADER + _VALUES, ("r.at2", "NPTS")),
    ("units-cm-s2", GOOD.replace("UNITS OF G", "UNITS OF CM/S2"), ("r.at2", "line 3", "CM/S2")),
    ("npts-zero", GOOD.replace("NPTS=    8", "NPTS=    0"), ("r.at2", "line 4", "'0'")),
    ("npts-word", GOOD.replace("NPTS=    8", "NPTS= many"), ("r.at2", "line 4")),
    ("npts-too-few", _HEADER + "NPTS=    2, DT= .0200 SEC\n0.0 0.001\n", ("r.at2", "line 4", "NPTS = 2")),
    ("dt-zero", GOOD.replace("DT= .0200", "DT= 0.0"), ("r.at2", "line 4", "DT")),
    ("dt-negative", GOOD.replace("DT= .0200", "DT= -.0200"), ("r.at2", "line 4")),
    ("npts-more-than-values", GOOD.replace("NPTS=    8", "NPTS=    9"), ("r.at2", "NPTS = 9", "8 values")),
    ("npts-fewer-than-values", GOOD.replace("NPTS=    8", "NPTS=    7"), ("r.at2", "NPTS = 7", "8 values")),
    ("value-word", GOOD.replace("0.003", "abc"), ("r.at2", "line 6", "'abc'")),
    ("value-nan", GOOD.replace("0.003", "nan"), ("r.at2", "line 6", "'nan'")),
    ("value-inf", GOOD.replace("0.003", "-inf"), ("r.at2", "line 6", "'-inf'")),
    ("empty-file", "", ("r.at2", "NPTS")),
    ("binary-garbage", bytes(range(256)) * 4, ("r.at2",)),
]

CASES = [Case(Group.AT2, id_, Outcome.ERROR, _scenario_with_record(text), names) for id_, text, names in _BAD] + [
    Case(Group.AT2, "value-1e308", Outcome.ERROR, _scenario_with_record(GOOD.replace("0.003", "1e308")),
         ("r.at2", "1e308")),
]
