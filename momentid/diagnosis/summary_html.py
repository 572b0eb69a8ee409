"""The answer of a diagnosis in HTML: a notebook's ``Diagnosis._repr_html_`` and the report page's first
section (:mod:`momentid.report`), the same words in both: the verdict and the physics in one sentence,
then the report's own lines (:attr:`~momentid.diagnosis.result.Diagnosis.summary`) with its warnings
marked."""

from __future__ import annotations

import math
from typing import Any

from momentid.core import html
from momentid.diagnosis.verdict import Verdict
from momentid.mechanisms.place import location_words

__all__ = ["diagnosis_html", "diagnosis_headline", "mechanism_words"]


def mechanism_words(name: str) -> str:
    """A mechanism's name in words (``joint_friction`` -> ``joint friction``)."""
    return name.replace("_", " ")


def _places(named) -> str:
    """``joint friction at storey 1, storey 2 and storey 3; extra damper at storey 3``."""
    by_kind: dict[str, list[str]] = {}
    for n in named:
        by_kind.setdefault(mechanism_words(n.mechanism), []).append(location_words(n.location))
    out = []
    for kind, places in by_kind.items():
        said = places[0] if len(places) == 1 else ", ".join(places[:-1]) + " and " + places[-1]
        out.append(f"{kind} at {said}")
    return "; ".join(out)


def diagnosis_headline(diag: Any) -> str:
    """One sentence of a :class:`~momentid.diagnosis.result.Diagnosis` (which imports this module: typed
    ``Any``): the verdict, the physics and where, and the held-out check's numbers."""
    if diag.verdict is Verdict.NONE:
        head = "No missing physics: the linear model explains the recordings to the noise level"
    elif diag.verdict is Verdict.MECHANISM and diag.mechanisms:
        head = f"Missing physics: {_places(diag.mechanisms)}"
    elif diag.verdict is Verdict.ANOTHER_RIG_STATE:
        head = ("The held-out trial is of another rig state: its misfit is not evidence of missing physics "
                f"(largest at the {location_words(diag.location)})")
    else:
        head = f"Unexplained mismatch at {location_words(diag.location)}"
    if math.isfinite(diag.nrmse_before) and math.isfinite(diag.nrmse_after):
        head += (f"; held-out {diag.held_out}: NRMSE {100 * diag.nrmse_before:.2f} % (linear) -> "
                 f"{100 * diag.nrmse_after:.2f} %")
        if math.isfinite(diag.noise_nrmse):   # the data check runs no noise estimate
            head += f", sensor noise alone {100 * diag.noise_nrmse:.2f} %"
    return head + "."


def diagnosis_html(diag: Any) -> str:
    """The answer of a :class:`~momentid.diagnosis.result.Diagnosis` (module docstring)."""
    return html.summary(diagnosis_headline(diag), html.word_lines(diag.summary.splitlines()))
