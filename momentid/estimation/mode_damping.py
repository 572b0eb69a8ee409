"""One storey mode's damping answer (:class:`ModeDamping`) and where it came from (:class:`Source`), as
:func:`momentid.estimation.damping.resolve_damping` gives it."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Source", "ModeDamping"]


class Source:
    """Where a damping answer came from (closed set of names)."""

    LINEAR = "linear fit"
    FREE_DECAY = "free decays"
    FORCED = "forced response"
    POOLED = "free decays and forced windows"
    WHOLE_RECORD = "whole record's linear fit (delete-a-block jackknife error)"


@dataclass(frozen=True)
class ModeDamping:
    """One storey mode's damping answer (:func:`~momentid.estimation.damping.resolve_damping`).

    Attributes
    ----------
    damping_ratio, damping_ratio_std : float
        At small amplitude (1), and its standard error (model error included).
    interval : tuple of float
        95 % interval (Student's t with ``dof`` degrees of freedom).
    dof : int
    source : str
        A :class:`Source` name.
    amplitude_dependent : bool
        The free decays show a damping that grows (or falls) with amplitude.
    slope, exponent : float
        ``zeta = zeta0 + slope E^exponent`` (E: envelope in m/s^2 on the mode's strongest floor); 0, 0 for a
        constant law.
    frequency, frequency_slope : float
        Frequency at small amplitude (Hz) and its change per m/s^2 (free decays; the linear fit's
        frequency and 0 otherwise).
    amplitude_range : tuple of float
        10th and 90th percentiles of the amplitudes (m/s^2) the answer rests on.
    equivalent : float
        The linear fit's damping ratio over the whole record (the equivalent linear damping).
    cycles : float
        Cycles of the mode the answer rests on.
    evidence : float
        How many standard errors the amplitude dependence stands out by (0: none tried).
    refusal : str
        Why the damping ratio is not an answer ('' when it is).
    """

    damping_ratio: float
    damping_ratio_std: float
    interval: tuple
    dof: int
    source: str
    amplitude_dependent: bool
    slope: float
    exponent: float
    frequency: float
    frequency_slope: float
    amplitude_range: tuple
    equivalent: float
    cycles: float
    refusal: str = ""
    evidence: float = 0.0

    @property
    def is_answer(self) -> bool:
        """Whether the damping ratio is an answer (no refusal)."""
        return not self.refusal

    def to_dict(self) -> dict:
        """The estimate as a JSON-ready dict (frequencies in Hz, amplitudes in m/s^2; no refusal: None)."""
        return {"damping_ratio": self.damping_ratio, "damping_ratio_std": self.damping_ratio_std,
                "interval_95": list(self.interval), "dof": self.dof, "source": self.source,
                "amplitude_dependent": self.amplitude_dependent, "slope_per_m_s2_power": self.slope,
                "exponent": self.exponent, "frequency_hz": self.frequency,
                "frequency_slope_hz_per_m_s2": self.frequency_slope,
                "amplitude_range_m_s2": list(self.amplitude_range),
                "equivalent_linear_damping_ratio": self.equivalent, "cycles": self.cycles,
                "refusal": self.refusal or None}

    def words(self) -> str:
        """One line: the answer (or the refusal) and where it came from."""
        if self.refusal:
            return f"damping NOT AN ANSWER: {self.refusal}"
        law = (f", rising as {self.slope:.3g} E^{self.exponent:g} with the envelope E (m/s^2)"
               if self.amplitude_dependent else "")
        lo, hi = self.amplitude_range
        return (f"damping {100 * self.damping_ratio:.3g} +- {100 * self.damping_ratio_std:.2g} % at small amplitude "
                f"(95 %: {100 * self.interval[0]:.3g}-{100 * self.interval[1]:.3g} %), from {self.cycles:.0f} cycles "
                f"of {self.source} at {lo:.2g}-{hi:.2g} m/s^2{law}; equivalent linear over the record "
                f"{100 * self.equivalent:.3g} %")
