"""The ideal device on torch tensors (:class:`~softenv.devices.base.DeviceTensors`): the action is the
force, for the torch twin."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from .base import Config, DeviceScene
from .force_box import IDEAL_OBS, ForceBox


class IdealDeviceTensors:
    """``n`` ideal devices on tensors: :class:`~softenv.devices.ideal.IdealDeviceBatch` on torch."""

    obs_names = IDEAL_OBS
    info_keys: tuple[str, ...] = ()
    episode_info_keys: tuple[str, ...] = ()
    scene_params: tuple[str, ...] = ("tissue_stiffness",)     # the force is commanded: the tissue acts through the response only

    def __init__(self, scene: DeviceScene, config: Config, n: int, torch_device: torch.device,
                 dtype: torch.dtype) -> None:
        box = ForceBox(scene.workspace)

        def tensor(value: Any) -> torch.Tensor:
            return torch.as_tensor(np.asarray(value, dtype=np.float64), device=torch_device).to(dtype)

        self._mid, self._half, self._rest = tensor(box.mid), tensor(box.half), tensor(box.rest_action)

    def reset(self, mask: torch.Tensor) -> torch.Tensor:
        return self._rest

    def act(self, actions: torch.Tensor, stepped: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        f = self._mid + actions * self._half
        return f, f[:, 2], f[:, 3]

    def observation(self, features: torch.Tensor) -> torch.Tensor:
        return (features - self._mid) / self._half

    def report(self, info: dict[str, Any], stepped: torch.Tensor) -> float:
        return 0.0

    def compile(self, options: dict[str, Any]) -> bool:
        return False                 # a few elementwise operations: compiled with the env's step

    def differentiable(self) -> None:
        """The action maps to the force affinely: torch differentiates it as it is."""

    def detach(self) -> None:
        """No state of its own."""

    def track_state(self) -> dict[str, torch.Tensor]:
        """No state of its own."""
        return {}

    def use_params(self, params: dict[str, torch.Tensor]) -> None:
        """Nothing of the device reads them."""
