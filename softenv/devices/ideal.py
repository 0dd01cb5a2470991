"""The ideal device: the action *is* the force, with no dynamics (SoftSphere-v0 and its kin)."""

from __future__ import annotations

import numpy as np

from ..forces import Workspace


class IdealDevice:
    """Action in ``[-1, 1]^4`` -> force features: ``low + (a + 1) (high - low) / 2`` per column.

    Columns: insertion (m of arc along the midline), lateral (m of arc off the midline), normal force
    (N, pressing), sideways force (N, toward +y). The device has no dynamics: the force follows the
    command at once.
    """

    def __init__(self, workspace: Workspace) -> None:
        low, high = np.asarray(workspace.low), np.asarray(workspace.high)
        self.mid = (low + high) / 2
        self.half = (high - low) / 2
        self._mid, self._half = self.mid.tolist(), self.half.tolist()
        self.rest_action = np.array([0.0, 0.0, -1.0, 0.0], dtype=np.float32)   # zero force, mid contact

    def features(self, action: np.ndarray) -> np.ndarray:
        """Force features of actions ``(..., 4)``."""
        return self.mid + action * self.half

    def features_one(self, action: list[float]) -> list[float]:
        """Scalar twin of :meth:`features` for one action given as Python floats."""
        return [m + a * h for m, a, h in zip(self._mid, action, self._half)]

    def normalised(self, features: np.ndarray) -> np.ndarray:
        """Features mapped back onto ``[-1, 1]`` (the device state in observations)."""
        return (features - self.mid) / self.half

    def normalised_one(self, features: list[float]) -> list[float]:
        """Scalar twin of :meth:`normalised`."""
        return [(f - m) / h for f, m, h in zip(features, self._mid, self._half)]
