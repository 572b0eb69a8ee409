"""The diagnosis of a rig identified with added masses
(:func:`~momentid.diagnosis.added_mass.path.diagnose_added_mass`).

Its stages (``docs/diagnosis.md`` numbers them): the linear model and its residuals (:mod:`.residuals`),
the sensors against each other (:mod:`.kinematic_check`, read as sensor faults by :mod:`.sensor_faults`),
where the mismatch is (:mod:`.locate`), the screening of every mechanism (:mod:`.screening`), the choice
by re-simulation (:mod:`.selection` on :mod:`.resimulation`, replaying :mod:`.augmented` models), further
mechanisms (:mod:`.compound`, screened by :mod:`.compound_screening`), stages 1-6 in one call
(:mod:`.stages`), the open search (:mod:`.open_search`), and its evidence in words (:mod:`.words`).
"""

from momentid.diagnosis.added_mass.path import diagnose_added_mass

__all__ = ["diagnose_added_mass"]
