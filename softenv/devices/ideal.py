"""The ideal device: the action *is* the force, with no dynamics (SoftSphere-v0 and its kin): the
scene's :class:`~.force_box.ForceBox` alone."""

from __future__ import annotations

from typing import Any

import numpy as np

from .base import Config, DeviceKind, DeviceScene
from .force_box import IDEAL_OBS, ForceBox


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
