"""A modal identification read back from the JSON object ``momentid identify --json`` prints for runs
without added mass (:meth:`momentid.estimation.scaled.ModalIdentification.to_dict`), for ``view
--result``.

Strict JSON holds no NaN: :func:`momentid.core.series.json_safe` wrote every non-finite number as
``null``, read back here as NaN.  Every key the viewer draws from (frequencies, damping ratios, shapes,
the matrices and sensors of :meth:`~momentid.estimation.scaled.ModalIdentification.table`) is checked
for its shape; a missing or malformed one is one :class:`~momentid.errors.ViewerError` naming the file
and the key.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from momentid.errors import ViewerError

if TYPE_CHECKING:
    from momentid.estimation.scaled import ModalIdentification

__all__ = ["is_modal_payload", "modal_from_dict"]

#: Keys that only the modal result carries (the added-mass result has M, C, K, mu, kappa instead).
MODAL_KEYS = ("frequency_hz", "damping_ratio", "mode_shapes", "runs")


def is_modal_payload(data: object) -> bool:
    """True for the JSON object of a modal fit (runs without added mass)."""
    return isinstance(data, dict) and "frequency_hz" in data and "mu" not in data


def _nan(value):
    if value is None:
        return np.nan
    if isinstance(value, list):
        return [_nan(v) for v in value]
    return value


class _Reader:
    """Reads keys of one JSON object, naming the file and the key in every refusal."""

    def __init__(self, data: dict, source: str):
        self.data, self.source = data, source

    def refuse(self, key: str, value, expected: str):
        shown = repr(value)
        shown = shown if len(shown) <= 60 else shown[:57] + "..."
        return ViewerError(f"{self.source}: key {key!r}: {shown}; expected {expected} "
                           f"(a result of `momentid identify --json`)")

    def array(self, key: str, shape: tuple, where: dict | None = None, *, optional: bool = False,
              label: str | None = None):
        """``where[key]`` as a float array of ``shape`` (None: NaN); None when ``optional`` and absent;
        ``label`` names the key in a refusal (default ``key``)."""
        where = self.data if where is None else where
        value = where.get(key)
        if value is None and optional:
            return None
        try:
            out = np.asarray(_nan(value), float)
        except (TypeError, ValueError):
            out = None
        if out is None or out.shape != shape:
            raise self.refuse(label or key, value, f"numbers of shape {shape}")
        return out

    def std(self, key: str, shape: tuple):
        """The standard errors of ``key`` (``std`` object of the result)."""
        where = self.data.get("std")
        return self.array(key, shape, where if isinstance(where, dict) else {}, label=f"std.{key}")

    def number(self, key: str, where: dict | None = None, default=None) -> float:
        value = (self.data if where is None else where).get(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float, type(None))):
            raise self.refuse(key, value, "a number")
        return np.nan if value is None else float(value)

    def texts(self, key: str, where: dict | None = None) -> tuple:
        value = (self.data if where is None else where).get(key, [])
        if not isinstance(value, list) or not all(isinstance(v, (str, type(None))) for v in value):
            raise self.refuse(key, value, "a list of strings")
        return tuple(v or "" for v in value)

    def flags(self, key: str, count: int):
        """``key``'s list of ``count`` booleans as an array; None when absent."""
        value = self.data.get(key)
        if value is None:
            return None
        if not isinstance(value, list) or len(value) != count or not all(isinstance(v, bool) for v in value):
            raise self.refuse(key, value, f"{count} booleans, one per mode")
        return np.array(value, bool)

    def records(self, key: str, count: int | None = None) -> list:
        value = self.data.get(key) or []
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value) or \
                (count is not None and value and len(value) != count):
            raise self.refuse(key, value, "a list of objects" + (f", one per mode ({count})" if count else ""))
        return value


def _mode_damping(read: _Reader, entry: dict):
    """One mode's damping answer (``damping`` entries: :meth:`~momentid.estimation.damping.ModeDamping.to_dict`)."""
    from momentid.estimation.damping import ModeDamping

    interval = read.array("interval_95", (2,), entry)
    amplitudes = read.array("amplitude_range_m_s2", (2,), entry)
    source = entry.get("source")
    if not isinstance(source, str):
        raise read.refuse("damping[].source", source, "the name of where the damping came from")
    return ModeDamping(
        damping_ratio=read.number("damping_ratio", entry), damping_ratio_std=read.number("damping_ratio_std", entry),
        interval=tuple(interval), dof=int(np.nan_to_num(read.number("dof", entry, 0))), source=source,
        amplitude_dependent=bool(entry.get("amplitude_dependent", False)),
        slope=read.number("slope_per_m_s2_power", entry, 0.0), exponent=read.number("exponent", entry, 0.0),
        frequency=read.number("frequency_hz", entry),
        frequency_slope=read.number("frequency_slope_hz_per_m_s2", entry, 0.0),
        amplitude_range=tuple(amplitudes), equivalent=read.number("equivalent_linear_damping_ratio", entry),
        cycles=read.number("cycles", entry), refusal=entry.get("refusal") or "")


def _extra_mode(read: _Reader, entry: dict, d: int):
    """One resonance beyond the storey modes (``extra_modes`` entries:
    :meth:`~momentid.estimation.modal_checks.ExtraMode.to_dict`)."""
    from momentid.estimation.modal_checks import ExtraMode

    return ExtraMode(
        frequency=read.number("frequency_hz", entry), frequency_std=read.number("frequency_std", entry),
        damping_ratio=read.number("damping_ratio", entry), damping_ratio_std=read.number("damping_ratio_std", entry),
        residues=read.array("residues", (d,), entry), residues_std=read.array("residues_std", (d,), entry),
        seen_by=read.texts("seen_by", entry), damping_independent=read.number("damping_ratio_subspace", entry),
        residues_quadrature=read.array("residues_quadrature", (d,), entry, optional=True))


def modal_from_dict(data: dict, source: str) -> ModalIdentification:
    """The :class:`~momentid.estimation.scaled.ModalIdentification` of a modal ``identify --json`` object.

    Parameters
    ----------
    data : dict
        The JSON object (:func:`is_modal_payload`).
    source : str
        The file it was read from, named in every refusal.

    Returns
    -------
    ModalIdentification
        With the standard errors of the equivalent linear damping unknown (NaN: the JSON does not
        carry them).

    Raises
    ------
    ViewerError
        A key is missing or of the wrong shape.
    """
    from momentid.estimation.scaled import ModalIdentification

    read = _Reader(data, source)
    missing = [k for k in MODAL_KEYS if k not in data]
    if missing:
        raise ViewerError(f"{source}: not a result of `momentid identify --json`: missing {', '.join(missing)} "
                          f"(expected keys {', '.join(MODAL_KEYS)} for runs without added mass)")
    runs = read.texts("runs")
    value = data["frequency_hz"]
    d = len(value) if isinstance(value, list) and value else 0
    if not d:
        raise read.refuse("frequency_hz", value, "a list of frequencies (Hz), mode 1 first")
    frequency, n = read.array("frequency_hz", (d,)), len(runs)
    damping_ratio, shapes = read.array("damping_ratio", (d,)), read.array("mode_shapes", (d, d))
    masses = data.get("masses")
    scaled = masses is not None
    if scaled:
        masses = tuple(float(m) for m in read.array("masses", (d,)))
    matrix = {key: (read.array(key, (d, d)) if scaled else None) for key in ("M", "K", "C")}
    damping = tuple(_mode_damping(read, e) for e in read.records("damping", d))
    return ModalIdentification(
        frequency=frequency, frequency_std=read.std("frequency_hz", (d,)),
        damping_ratio=damping_ratio, damping_ratio_std=read.std("damping_ratio", (d,)),
        shapes=shapes, shapes_std=read.std("mode_shapes", (d, d)),
        stiffness_over_mass=read.array("M^-1 K", (d, d)), stiffness_over_mass_std=read.std("M^-1 K", (d, d)),
        damping_over_mass=read.array("M^-1 C", (d, d)), damping_over_mass_std=read.std("M^-1 C", (d, d)),
        masses=masses, M=matrix["M"], K=matrix["K"], C=matrix["C"],
        K_std=read.std("K", (d, d)) if scaled else None, C_std=read.std("C", (d, d)) if scaled else None,
        sensor_gain=read.array("sensor_gain", (n, d)), sensor_gain_std=read.std("sensor_gain", (n, d)),
        sensor_offset=read.array("sensor_offset_s", (n, d)),
        sensor_offset_std=read.std("sensor_offset_s", (n, d)),
        amplitude=read.array("amplitude_m_s2", (n,)), residual_rms=read.number("residual_rms"), runs=runs,
        noise=read.texts("noise"), f_max=read.number("f_max_hz"), nfev=int(np.nan_to_num(read.number("nfev", None, 0))),
        notes=read.texts("notes"), warnings=read.texts("warnings"), estimator=str(data.get("estimator", "modal-eiv")),
        extra_modes=tuple(_extra_mode(read, e, d) for e in read.records("extra_modes")),
        damping_ratio_subspace=read.array("damping_ratio_subspace", (d,), optional=True),
        damping_is_answer=read.flags("damping_is_answer", d),
        damping_ratio_equivalent=read.array("damping_ratio_equivalent", (d,), optional=True),
        equivalent_std=np.full(d, np.nan),
        damping_interval=read.array("damping_interval_95", (d, 2), optional=True),
        damping_refusal=read.texts("damping_refusal"), damping=damping,
        frequency_is_answer=read.flags("frequency_is_answer", d))
