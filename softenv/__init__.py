"""softenv: a Gymnasium environment and learning benchmark for soft-tissue deformation under a
force-input device.

The offline core (this package's top level) needs only numpy: the analytic tissue model, the
paper's data sets and the PCA shape model, the env classes, the device contract (for a device of
one's own: ``docs/adding-a-device.md``) and the response models; the torch twin's class loads torch
when it is first named. Importing it registers the SoftSphere environments with Gymnasium
(``gym.make("SoftSphere-v0")``).
"""

from __future__ import annotations

import importlib
from typing import Any

from .devices.base import Config, Device, DeviceBatch, DeviceKind, DeviceScene, DeviceTensors
from .devices.force_box import ForceBox
from .envs import default_config, describe_config, make_config, register_envs
from .envs.single import SoftSphereEnv
from .envs.vector import SoftSphereVectorEnv
from .response import make_response
from .datasets import ForceShapeData, paper_dataset, split_by_contact, split_rows, workspace_dataset
from .forces import DorsumLayout, PaperLayout, Workspace, sample_workspace
from .geometry import SphereMesh, icosphere_mesh, latlong_mesh, make_mesh, paper_mesh
from .shape_model import ShapeModel
from .tissue import AnalyticTissue, TissueParams

__version__ = "0.1.0"

register_envs()

# names whose modules pull an optional dependency: loaded when first asked for
_LAZY = {"SoftSphereTorchVectorEnv": "softenv.envs.torch_twin"}       # torch


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'softenv' has no attribute {name!r}")

__all__ = [
    "AnalyticTissue", "DorsumLayout", "ForceShapeData", "PaperLayout", "ShapeModel", "SphereMesh", "TissueParams",
    "Workspace", "icosphere_mesh", "latlong_mesh", "make_mesh", "paper_dataset", "paper_mesh", "sample_workspace",
    "split_by_contact", "split_rows", "workspace_dataset", "default_config", "describe_config", "make_config",
    "register_envs", "Config", "Device", "DeviceBatch", "DeviceKind", "DeviceScene", "DeviceTensors", "ForceBox",
    "SoftSphereEnv", "SoftSphereVectorEnv", "make_response",
]
