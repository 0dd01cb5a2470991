"""The force-feature box: the affine map between action units ``[-1, 1]^4`` and a scene's force
features, which every scene has (targets are given in its units), whatever its device; the ideal device
is this map alone (:mod:`.ideal`, and on tensors :mod:`.ideal_tensors`)."""

from __future__ import annotations

import numpy as np

from ..forces import Workspace

IDEAL_OBS = ("insertion", "lateral", "normal", "sideways")


class ForceBox:
    """Action units ``[-1, 1]^4`` <-> force features: ``low + (a + 1) (high - low) / 2`` per column.

    Columns: insertion (m of arc along the midline), lateral (m of arc off the midline), normal force
    (N, pressing), sideways force (N, toward +y). ``rest_action`` is zero force at mid contact.
    """

    def __init__(self, workspace: Workspace) -> None:
        low, high = np.asarray(workspace.low), np.asarray(workspace.high)
        self.mid = (low + high) / 2
        self.half = (high - low) / 2
        self._mid, self._half = self.mid.tolist(), self.half.tolist()
        self.rest_action = np.array([0.0, 0.0, -1.0, 0.0], dtype=np.float32)

    def features(self, action: np.ndarray) -> np.ndarray:
        """Force features of actions ``(..., 4)``."""
        return self.mid + action * self.half

    def features_one(self, action: list[float]) -> list[float]:
        """:meth:`features` of one action given as Python floats (the same bits)."""
        return [m + a * h for m, a, h in zip(self._mid, action, self._half)]

    def normalised(self, features: np.ndarray) -> np.ndarray:
        """Features mapped back onto ``[-1, 1]``."""
        return (features - self.mid) / self.half

    def normalised_one(self, features: list[float]) -> list[float]:
        """:meth:`normalised` of one row of Python floats (the same bits)."""
        return [(f - m) / h for f, m, h in zip(features, self._mid, self._half)]
