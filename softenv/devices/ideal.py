"""The ideal device: the action *is* the force, with no dynamics (SoftSphere-v0 and its kin).

:class:`ForceBox` is the affine map between action units ``[-1, 1]^4`` and the scene's force-feature
box; every scene has one (targets are given in its units), whatever its device.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..forces import Workspace
from .base import Config, DeviceKind, DeviceScene

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


class IdealDevice:
    """One ideal device (:class:`~softenv.devices.base.Device`): features = the action mapped onto the
    box; its observation is the applied force in action units."""

    obs_names = IDEAL_OBS
    info_keys: tuple[str, ...] = ()
    episode_info_keys: tuple[str, ...] = ()

    def __init__(self, scene: DeviceScene, config: Config) -> None:
        self.box = ForceBox(scene.workspace)

    def reset(self) -> list[float]:
        return self.box.rest_action.astype(np.float64).tolist()

    def act(self, action: list[float]) -> tuple[list[float], float, float]:
        f = self.box.features_one(action)
        return f, f[2], f[3]

    def observation(self, features: list[float]) -> list[float]:
        return self.box.normalised_one(features)

    def report(self, info: dict[str, Any]) -> float:
        return 0.0

    def episode_info(self, b: np.ndarray) -> dict[str, Any]:
        return {}

    def drawing(self) -> None:
        return None

    def state(self) -> None:
        return None

    def load_state(self, state: None) -> None:
        pass


class IdealDeviceBatch:
    """``n`` ideal devices (:class:`~softenv.devices.base.DeviceBatch`): the same arithmetic on arrays."""

    obs_names = IDEAL_OBS
    info_keys: tuple[str, ...] = ()
    episode_info_keys: tuple[str, ...] = ()

    def __init__(self, scene: DeviceScene, config: Config, n: int) -> None:
        self.box = ForceBox(scene.workspace)

    def reset(self, mask: np.ndarray) -> np.ndarray:
        return self.box.rest_action

    def act(self, actions: np.ndarray, stepped: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        f = self.box.features(actions)
        return f, f[:, 2], f[:, 3]

    def observation(self, features: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        return self.box.normalised(features)

    def report(self, info: dict[str, Any], stepped: np.ndarray) -> float:
        return 0.0

    def episode_info(self, i: int, b: np.ndarray) -> dict[str, Any]:
        return {}

    def drawing(self, i: int) -> None:
        return None

    def state(self) -> None:
        return None

    def load_state(self, state: None) -> None:
        pass


def _tensors(scene: DeviceScene, config: Config, n: int, torch_device: Any, dtype: Any) -> Any:
    from .ideal_tensors import IdealDeviceTensors           # torch: only for the torch twin

    return IdealDeviceTensors(scene, config, n, torch_device, dtype)


IDEAL = DeviceKind("ideal", IDEAL_OBS, IdealDevice, IdealDeviceBatch, _tensors)
