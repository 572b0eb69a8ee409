"""What a discovered force is, physically: its class and the numbers an engineer reads off it.

The open search (:mod:`~momentid.diagnosis.added_mass.open_search`) returns a force as a sum of library terms
(:data:`momentid.mechanisms.data_driven.TERMS`) at a place.  :func:`physics` reads the terms
beyond the linear spring and dashpot as one class of physics:

* ``stop``: one-sided stops (``max(x - delta, 0)``, ``min(x + delta, 0)``), or a two-sided gap at a
  floor against the table (stops on both sides); its side (``+``, ``-``, ``both``), gap(s) (m) and
  contact stiffness (N/m);
* ``gap``: a two-sided gap (dead zone) across a storey: a brace that engages beyond its slack;
* ``hysteresis``: a Bouc-Wen hysteretic state;
* ``stiffness change``: a stiffness switch ``x H(t - t0)`` at ``t0``;
* ``polynomial``, ``damping``, ``friction``: the smooth terms;
* ``mixed``: several classes at once (the description lists them);
* ``linear``: no term beyond the linear spring and dashpot.

:func:`describe` says it in an engineer's words: a stop by its floor, side, gap (mm) and contact
stiffness; a gap by its storey, slack (mm) and the stiffness beyond it; every other term by its
size against the linear force at the place, with a WARNING when a term that corrects the linear
force is larger than that force at the peak (:data:`LOUD`).
"""

from __future__ import annotations


import numpy as np

from momentid.core.structure import Structure
from momentid.mechanisms.bouc_wen import bouc_wen_state
from momentid.mechanisms.data_driven import HYSTERETIC_BETA
from momentid.mechanisms.place import Place, Target

__all__ = ["physics", "describe", "linear_stiffness", "LINEAR_TERMS", "LOUD"]

#: A correction term whose force at the peak exceeds this multiple of the linear force at the place
#: gets a WARNING: it does not read as a correction of the linear model (a cubic term of -683 % of the
#: storey's stiffness at the peak describes nothing physical).
LOUD = 1.0
#: Cycles of the hysteretic law's loop computed for its area (the first ones settle from z = 0),
#: and samples per cycle.
_LOOP_CYCLES, _LOOP_SAMPLES = 3, 2000

#: The terms of every discovered force (the linear spring and dashpot at its place).
LINEAR_TERMS = ("x", "v")

_SMOOTH = {"x3": "polynomial", "x_abs_x": "polynomial", "v_abs_v": "damping", "sign_v": "friction"}


def _stop(terms: dict, two_sided_gap: bool) -> dict:
    """A stop's side, gaps (m) and contact stiffness (N/m) from its terms."""
    out: dict = {"class": "stop"}
    if two_sided_gap:
        t = terms["dead_zone"]
        return {**out, "side": "both", "gap_pos": t["dead_zone_delta"], "gap_neg": t["dead_zone_delta"],
                "stiffness": t["coefficient"]}
    pos, neg = terms.get("gap_pos"), terms.get("gap_neg")
    out["side"] = "both" if pos and neg else ("+" if pos else "-")
    if pos:
        out["gap_pos"] = pos["gap_pos_delta"]
    if neg:
        out["gap_neg"] = neg["gap_neg_delta"]
    out["stiffness"] = max(t["coefficient"] for t in (pos, neg) if t)
    return out


def physics(place: Place, terms: list[dict]) -> dict:
    """The class of physics a discovered force's terms say (see the module docstring).

    Parameters
    ----------
    place : Place
        The force's place: a storey, or a floor against the table.
    terms : list of dict
        The force's terms (``term``, ``coefficient`` and the term's shape parameters).

    Returns
    -------
    dict
        ``class`` and its numbers in SI units: ``side``, ``gap_pos``, ``gap_neg``, ``stiffness`` (a
        stop); ``gap``, ``stiffness`` (a gap); ``yield_drift``, ``exponent`` (hysteresis); ``time``
        (a stiffness change); ``terms`` (every other class).
    """
    nonlinear = {t["term"]: t for t in terms if t["term"] not in LINEAR_TERMS}
    names = set(nonlinear)
    if not names:
        return {"class": "linear"}
    if names <= {"gap_pos", "gap_neg"}:
        return _stop(nonlinear, False)
    if names == {"dead_zone"}:
        if place.target is Target.FLOOR_TABLE:
            return _stop(nonlinear, True)
        t = nonlinear["dead_zone"]
        return {"class": "gap", "gap": t["dead_zone_delta"], "stiffness": t["coefficient"]}
    if names == {"hysteretic"}:
        t = nonlinear["hysteretic"]
        return {"class": "hysteresis", "yield_drift": t["hysteretic_yield"], "exponent": t["hysteretic_exponent"]}
    if names == {"switch"}:
        return {"class": "stiffness change", "time": nonlinear["switch"]["switch_time"]}
    classes = {_SMOOTH.get(n, "other") for n in names}
    if len(classes) == 1 and "other" not in classes:
        return {"class": classes.pop(), "terms": sorted(names)}
    return {"class": "mixed", "terms": sorted(names)}


def _loop_area(coefficient: float, yield_drift: float, exponent: float, amplitude: float) -> float:
    """Energy (J) one cycle of amplitude ``amplitude`` (m) dissipates in the hysteretic term."""
    theta = np.linspace(0, 2 * np.pi * _LOOP_CYCLES, _LOOP_CYCLES * _LOOP_SAMPLES + 1)
    x = amplitude * np.sin(theta)
    rate = amplitude * np.cos(theta)
    z = bouc_wen_state(rate, float(theta[1] - theta[0]), yield_drift, exponent, HYSTERETIC_BETA)[:, 0]
    last = slice((_LOOP_CYCLES - 1) * _LOOP_SAMPLES, None)
    return float(coefficient * np.sum(0.5 * (z[last][1:] + z[last][:-1]) * np.diff(x[last])))


def linear_stiffness(place: Place, structure: Structure) -> float:
    """The model's linear stiffness (N/m) at a place: a storey's own, or for a floor against the
    table the storeys below it in series."""
    k = np.asarray(structure.storey_stiffness, float)
    lower, upper = place.nodes
    if place.target is Target.STOREY:
        return float(k[upper - 1])
    return float(1.0 / np.sum(1.0 / k[lower:upper]))


def _peak_force(t: dict, peak: float, peak_velocity: float) -> float:
    """|force| (N) of one term at the peak displacement or velocity."""
    c, term = abs(t["coefficient"]), t["term"]
    size = {"x3": peak ** 3, "x_abs_x": peak ** 2, "v_abs_v": peak_velocity ** 2, "sign_v": 1.0,
            "switch": peak, "hysteretic": t.get("hysteretic_yield", 0.0),
            "dead_zone": max(peak - t.get("dead_zone_delta", 0.0), 0.0),
            "gap_pos": max(peak - t.get("gap_pos_delta", 0.0), 0.0),
            "gap_neg": max(peak - t.get("gap_neg_delta", 0.0), 0.0)}
    return c * size.get(term, 0.0)


def _against_table(place: Place) -> bool:
    """A place whose stretch is a floor's displacement against the table (storey 1 is floor 1's)."""
    return place.nodes[0] == 0


def _where(place: Place) -> str:
    if place.target is Target.STOREY:
        return place.words + (" (floor 1 against the table)" if place.index == 1 else "")
    return f"floor {place.index} (against the table)"


def _stop_words(place: Place, ph: dict, k_lin: float) -> str:
    sides = {"+": "on the + side", "-": "on the - side", "both": "on both sides"}[ph["side"]]
    gaps = " and ".join(f"{sign}{1e3 * ph[key]:.1f} mm" for key, sign in (("gap_pos", "+"), ("gap_neg", "-"))
                        if key in ph)
    table = _against_table(place)
    what = f"floor {place.nodes[1]}" if table else f"{place.words}'s drift"
    return (f"{what} meets a stop {sides}: gap {gaps} from its rest position (relative to "
            f"{'the table' if table else 'the floor below'}), contact stiffness "
            f"{ph['stiffness']:.3g} N/m ({ph['stiffness'] / k_lin:.2g} x the frame's {k_lin:.3g} N/m there)")


def _term_words(t: dict, k_lin: float, peak: float, short: str) -> str:
    c, term = t["coefficient"], t["term"]
    trend = "stiffening" if c > 0 else "softening"
    if term == "gap_pos":
        return f"{trend} beyond {short} = +{1e3 * t['gap_pos_delta']:.1f} mm (a stop on the + side, {abs(c):.3g} N/m)"
    if term == "gap_neg":
        return f"{trend} beyond {short} = -{1e3 * t['gap_neg_delta']:.1f} mm (a stop on the - side, {abs(c):.3g} N/m)"
    if term == "dead_zone":
        return f"{trend} beyond |{short}| = {1e3 * t['dead_zone_delta']:.1f} mm (a two-sided gap, {abs(c):.3g} N/m)"
    if term in ("x3", "x_abs_x"):
        extra = c * peak ** (2 if term == "x3" else 1)
        return (f"{trend} with amplitude, {t['meaning'].split(' (')[0]} x {c:.3g} {t['unit']} "
                f"({100 * extra / k_lin:+.0f} % of its stiffness at the peak {1e3 * peak:.1f} mm)")
    if term == "v_abs_v":
        return f"quadratic damping {c:.3g} {t['unit']}"
    if term == "sign_v":
        return f"a friction-like force of {c:.3g} N"
    if term == "hysteretic":
        area = _loop_area(c, t["hysteretic_yield"], t["hysteretic_exponent"], peak)
        if area < 0:      # a passive hysteresis dissipates: its loops enclose a positive area
            return (f"a hysteretic-shaped term whose loops have negative area ({1e3 * area:.3g} mJ at the peak "
                    f"{1e3 * peak:.1f} mm): it puts energy in, which no passive joint or material does; a stand-in "
                    f"for something the library and the search lack, not a physical hysteresis")
        return (f"hysteretic: softening with amplitude (yield near |{short}| = {1e3 * t['hysteretic_yield']:.2f} mm),"
                f" loops of area {1e3 * area:.3g} mJ at the peak {1e3 * peak:.1f} mm")
    change = -c / k_lin
    return (f"{'loses' if change > 0 else 'gains'} {100 * abs(change):.0f} % of its stiffness from "
            f"t = {t['switch_time']:.1f} s")


def describe(place: Place, terms: list[dict], structure: Structure, peak: float,
             peak_velocity: float = 0.0) -> str:
    """The discovered force in words (see the module docstring).

    Parameters
    ----------
    place : Place
        The force's place: a storey, or a floor against the table.
    terms : list of dict
        The force's terms, :data:`LINEAR_TERMS` first.
    structure : Structure
        The linear model the force is added to (the linear stiffness at the place).
    peak, peak_velocity : float
        Peak ``|x|`` (m) and ``|v|`` (m/s) at the place on the training runs.
    """
    coef = {t["term"]: t for t in terms}
    k_lin = linear_stiffness(place, structure) + coef["x"]["coefficient"]
    if k_lin <= 0:   # the fitted spring undoes the model's: compare with the model's alone
        k_lin = linear_stiffness(place, structure)
    head = f"Discovered at {_where(place)}: "
    ph = physics(place, terms)
    nonlinear = [t for t in terms if t["term"] not in LINEAR_TERMS]
    if not nonlinear:
        return head + (f"a linear spring {coef['x']['coefficient']:.3g} N/m and dashpot "
                       f"{coef['v']['coefficient']:.3g} N s/m missing from the model.")
    if ph["class"] == "stop":
        words = [_stop_words(place, ph, k_lin)]
    elif ph["class"] == "gap":
        words = [f"{place.words} engages a brace beyond a gap of +/-{1e3 * ph['gap']:.1f} mm of drift, stiffness "
                 f"{ph['stiffness']:.3g} N/m beyond it ({ph['stiffness'] / k_lin:.2g} x the storey's {k_lin:.3g} N/m)"]
    else:
        short = "x" if place.target is Target.STOREY else f"q{place.index}"
        words = [_term_words(t, k_lin, peak, short) for t in nonlinear]
        if ph["class"] == "mixed":
            words.append("several kinds of physics at once: no single class reads from it")
    linear_force = abs(k_lin) * peak
    for t in nonlinear:
        force = _peak_force(t, peak, peak_velocity)
        if t["term"] not in ("gap_pos", "gap_neg", "dead_zone") and force > LOUD * linear_force:
            words.append(f"WARNING: its {t['meaning'].split(' (')[0]} term reaches {force:.3g} N at the peak, "
                         f"{force / linear_force:.1f} x the linear force there ({linear_force:.3g} N): not a "
                         f"correction of the linear model, read it with care")
    return head + "; ".join(words) + "."
