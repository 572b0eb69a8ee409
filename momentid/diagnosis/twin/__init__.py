"""The diagnosis of accelerometer-only recordings on the rig's MuJoCo twin
(:func:`~momentid.diagnosis.twin.path.diagnose_twin`).

The verdict (:mod:`.path`) from the held-out fold of the twins fitted by :mod:`momentid.twin.fit`
(:mod:`.folds`), and its evidence in words (:mod:`.words`).
"""

from momentid.diagnosis.twin.path import diagnose_twin

__all__ = ["diagnose_twin"]
