"""The diagnosis of accelerometer-only recordings by the modal model
(:func:`~momentid.diagnosis.modal.path.diagnose_modal`).

The held-out check of the modal model (:mod:`.check`), the verdict (:mod:`.path`), the open search on
one mode (:mod:`.open_search`) and its evidence in words (:mod:`.words`).
"""

from momentid.diagnosis.modal.path import diagnose_modal

__all__ = ["diagnose_modal"]
