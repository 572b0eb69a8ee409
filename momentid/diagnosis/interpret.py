"""What a discovered force is, physically: its class and the numbers an engineer reads off it.

The open search (:mod:`~momentid.diagnosis.discovery`) returns a force as a sum of library terms
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
"""

from __future__ import annotations

__all__ = ["physics", "LINEAR_TERMS"]

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


def physics(location: dict, terms: list[dict]) -> dict:
    """The class of physics a discovered force's terms say (see the module docstring).

    Parameters
    ----------
    location : dict
        ``{"storey": i}`` or ``{"floor": j}`` (1-based): the force's place.
    terms : list of dict
        The force's terms (``term``, ``coefficient`` and the term's shape parameters).

    Returns
    -------
    dict
        ``class`` and its numbers in SI units: ``side``, ``gap_pos``, ``gap_neg``, ``stiffness`` (a
        stop); ``gap``, ``stiffness`` (a gap); ``yield_drift``, ``exponent`` (hysteresis); ``time``
        (a stiffness change); ``terms`` (every other class).
    """
    (kind, _), = location.items()
    nonlinear = {t["term"]: t for t in terms if t["term"] not in LINEAR_TERMS}
    names = set(nonlinear)
    if not names:
        return {"class": "linear"}
    if names <= {"gap_pos", "gap_neg"}:
        return _stop(nonlinear, False)
    if names == {"dead_zone"}:
        if kind == "floor":
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
