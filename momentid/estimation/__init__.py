"""Estimation: M, C, K and the Rayleigh coefficients from recorded runs.

- :mod:`~momentid.estimation.identification`: :func:`identify` (equation (3) by least squares,
  the paper's eq. (2), or errors-in-variables); :mod:`~momentid.estimation.equation_form` (the
  equation forms by streaming QR, and the streamed variant), :mod:`~momentid.estimation.identified`
  (the result, its warnings, damping-model tests), :mod:`~momentid.estimation.layout` (where each
  unknown sits, the memory guard).
- :mod:`~momentid.estimation.reconstruct`: velocities and displacements from what was measured.
- :mod:`~momentid.estimation.linear`: exact discretisation and simulation of the linear model.
- :mod:`~momentid.estimation.eiv`: frequency-domain errors-in-variables maximum likelihood.
- Runs without added mass (accelerometers only): :mod:`~momentid.estimation.scaled` (``identify``'s
  result), :mod:`~momentid.estimation.modal_select` (how many modes, which are the storeys'),
  :mod:`~momentid.estimation.modal` and :mod:`~momentid.estimation.modal_model` (the fit),
  :mod:`~momentid.estimation.subspace` (starts and the damping's second opinion),
  :mod:`~momentid.estimation.modal_checks` (what is refused or flagged).
- :mod:`~momentid.estimation.design`: Cramér-Rao bounds and experiment planning.
- :mod:`~momentid.estimation.comparison`: identified against analytic parameters.
"""

from momentid.estimation.identification import Identification, identify, identify_stream
from momentid.estimation.comparison import Comparison, analytic_parameters, compare
from momentid.estimation.design import cramer_rao, plan

__all__ = [
    "Identification", "identify", "identify_stream",
    "Comparison", "analytic_parameters", "compare",
    "cramer_rao", "plan",
]
