"""The laryngoscope as a part the torch twin composes (:class:`~softenv.devices.base.DeviceTensors`), on
the engine ``device.batch_engine`` and the tensors' device pick (:func:`tensor_engine`)."""

from __future__ import annotations

import importlib.util
from typing import Any

import torch

from ..base import Config, DeviceScene
from ..contact import depth_derivative
from . import BATCH_ENGINES, LARYNGOSCOPE_OBS
from .params import SCENE_COLUMNS
from .part import INFO_KEYS, batch_report, in_workspace, laryngoscope_parts
from .state import DeviceState
from .tensors import LaryngoscopeTensors


def tensor_engine(batch_engine: str, torch_device: torch.device) -> type[LaryngoscopeTensors]:
    """The torch twin's engine ``device.batch_engine`` names on ``torch_device``: ``triton`` one Triton
    kernel a control period (:class:`~.fused.LaryngoscopeFused`: CUDA, with triton installed); ``warp`` the
    Warp kernel on the tensors' device (:class:`~.warp_tensors.LaryngoscopeWarpTensors`); ``auto`` triton
    where it runs, warp elsewhere. A name the device cannot serve is refused, never swapped."""
    if batch_engine == "triton" or (batch_engine == "auto" and fused_available(torch_device)):
        if not fused_available(torch_device):
            raise ValueError(f"device.batch_engine='triton' with torch_device={str(torch_device)!r}: Triton steps CUDA "
                             "tensors only, with triton installed; choose 'warp' or 'auto'")
        from .fused import LaryngoscopeFused          # triton: optional, for CUDA devices only

        return LaryngoscopeFused
    if batch_engine not in ("auto", "warp"):
        raise ValueError(f"device.batch_engine={batch_engine!r} has no torch engine: the torch twin takes 'auto', "
                         f"'warp' or 'triton' (of {list(BATCH_ENGINES)}); 'pymunk' steps the numpy twin only")
    from .warp_tensors import LaryngoscopeWarpTensors    # warp: only for the torch twin on its engine

    return LaryngoscopeWarpTensors


def fused_available(torch_device: torch.device) -> bool:
    """Whether the fused Triton engine runs on ``torch_device``: a CUDA device, with triton installed."""
    return torch_device.type == "cuda" and importlib.util.find_spec("triton") is not None


class LaryngoscopeTensorPart:
    """The laryngoscope as the torch twin composes it (:class:`~softenv.devices.base.DeviceTensors`): as
    :class:`~.part_batch.LaryngoscopePartBatch` (the workspace clip, the incisor reward term, the info
    keys) on tensors, on the engine :func:`tensor_engine` picks; no clinical record (the numpy twin keeps
    it)."""

    obs_names = LARYNGOSCOPE_OBS
    info_keys = INFO_KEYS
    episode_info_keys: tuple[str, ...] = ()

    def __init__(self, scene: DeviceScene, config: Config, n: int, torch_device: torch.device,
                 dtype: torch.dtype) -> None:
        self._engine_name, self._parts = config["device"]["batch_engine"], laryngoscope_parts(scene, config)
        self._scene, self._design_force = scene, config["device"]["max_normal_force"]
        self.scene_params = SCENE_COLUMNS   # what its kernel reads per device (warp_kernel.scene_row)
        self._use(tensor_engine(self._engine_name, torch_device), n, torch_device)
        self.dtype = dtype
        t = self.laryngoscopes._array
        self._low, self._high = t(scene.workspace.low), t(scene.workspace.high)
        self._rest = t(scene.rest_features)
        self._prev = torch.zeros(4, dtype=dtype, device=torch_device)
        self._weights = config["reward"].copy()
        self._factors: dict[str, torch.Tensor] = {}

    def _use(self, engine: type[LaryngoscopeTensors], n: int, torch_device: torch.device) -> None:
        self.laryngoscopes = engine(*self._parts, n, torch_device)
        start = self.laryngoscopes.start_state(n)
        self._start_state = DeviceState(*(self.laryngoscopes._array(v) for v in vars(start).values()))  # type: ignore[arg-type]

    def reset(self, mask: torch.Tensor) -> torch.Tensor:
        self.laryngoscopes.load_state(self._start_state, rows=mask)
        return self._prev

    def act(self, actions: torch.Tensor, stepped: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        dev = self.laryngoscopes
        if self._factors:                  # tracked scene parameters: the kernel's columns times their factors
            ones = torch.ones(dev.n, dtype=torch.float64, device=dev.torch_device)
            factors = [self._factors.get(name, ones).to(torch.float64) for name in SCENE_COLUMNS]
            dev.scene_params = self._scene_defaults * torch.stack(factors, dim=1)
        dev.control_step(actions.to(torch.float64), moving=stepped)
        features, touching = dev.features()
        f = in_workspace(features, touching, self._low, self._high, self._rest, dev.ops)
        return f.to(self.dtype), dev.normal_force.to(self.dtype), dev.sideways_force.to(self.dtype)

    def observation(self, features: torch.Tensor) -> torch.Tensor:
        return self.laryngoscopes.observation().to(self.dtype)

    def report(self, info: dict[str, Any], stepped: torch.Tensor) -> torch.Tensor:
        term, values = batch_report(self.laryngoscopes, self._weights, lambda x: x.to(self.dtype))
        info.update(values)
        return term

    def compile(self, options: dict[str, Any]) -> bool:
        """Keep the device's step apart: its engine is a kernel already (Warp's or Triton's), so the env
        compiles its own work around the device's calls."""
        return True

    def differentiable(self) -> None:
        """Gradients come from the Warp kernel's adjoint, a control period at a time
        (:func:`~.warp_tensors.differentiable_rollout`). Triton's kernel has none: ``device.batch_engine='auto'``
        then runs Warp where it would have run Triton, and ``'triton'`` is refused."""
        dev = self.laryngoscopes
        if not dev.has_adjoint:
            if self._engine_name != "auto":
                raise ValueError(f"device.batch_engine={self._engine_name!r} has no adjoint, so differentiable=True "
                                 "cannot take gradients through it: choose 'warp' or 'auto' (Warp's adjoint)")
            self._use(tensor_engine("warp", dev.torch_device), dev.n, dev.torch_device)
        self.laryngoscopes.taped = True

    def detach(self) -> None:
        self.laryngoscopes.detach()

    def track_state(self) -> dict[str, torch.Tensor]:
        return self.laryngoscopes.track_state()

    def use_params(self, params: dict[str, torch.Tensor]) -> None:
        """The coupling's stiffness and damping, the tongue's stiffness (its load table and lateral grip),
        the wrist's rotary stiffness and damping, and the stiffening law's depth (its load table to first
        order, :func:`~..contact.depth_derivative`) as factors on the kernel's scene parameters (the Warp
        engine's, which :meth:`differentiable` sets)."""
        self._scene_defaults = self.laryngoscopes.scene_params.detach().clone()
        self._factors = {name: x for name, x in params.items() if name in self.scene_params}
        if "stiffening_depth" in self._factors:
            scene = self._scene
            self.laryngoscopes.use_depth_derivative(*depth_derivative(self._parts[1], scene.tissue, scene.mesh,
                                                                      self._design_force))
