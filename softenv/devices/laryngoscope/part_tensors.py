"""The laryngoscope as a part the torch twin composes (:class:`~softenv.devices.base.DeviceTensors`), on
the engine ``device.batch_engine`` and the tensors' device pick (:func:`tensor_engine`)."""

from __future__ import annotations

import importlib.util
from typing import Any

import torch

from ..base import Config, DeviceScene
from . import BATCH_ENGINES, LARYNGOSCOPE_OBS
from .part import INFO_KEYS, batch_report, in_workspace, laryngoscope_parts
from .space import DeviceState
from .tensors import LaryngoscopeTensors


def tensor_engine(batch_engine: str, torch_device: torch.device) -> type[LaryngoscopeTensors]:
    """The torch twin's engine for ``device.batch_engine``: ``compiled`` (the default) runs each control
    period as one Triton kernel (:class:`~.fused.LaryngoscopeFused`) on a CUDA device where Triton is
    installed (it comes with torch's CUDA builds on Linux), and the tensor engine
    (:class:`~.tensors.LaryngoscopeTensors`, the numpy array engine's code on torch's operations)
    elsewhere; ``numpy`` is the tensor engine everywhere (what ``compile_options`` compiles)."""
    if batch_engine not in ("compiled", "numpy"):
        raise ValueError(f"device.batch_engine={batch_engine!r} has no torch engine: the torch twin takes 'compiled' "
                         f"(a Triton kernel on CUDA) or 'numpy' (the tensor engine); {list(BATCH_ENGINES)} are the "
                         "numpy twin's")
    if batch_engine == "compiled" and fused_available(torch_device):
        from .fused import LaryngoscopeFused          # triton: optional, for CUDA devices only

        return LaryngoscopeFused
    return LaryngoscopeTensors


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
        engine = tensor_engine(config["device"]["batch_engine"], torch_device)
        self.laryngoscopes = engine(*laryngoscope_parts(scene, config), n, torch_device)
        self.dtype = dtype
        start = self.laryngoscopes.start_state(n)
        self._start_state = DeviceState(*(self.laryngoscopes._array(v) for v in vars(start).values()))  # type: ignore[arg-type]
        t = self.laryngoscopes._array
        self._low, self._high = t(scene.workspace.low), t(scene.workspace.high)
        self._rest = t(scene.rest_features)
        self._prev = torch.zeros(4, dtype=dtype, device=torch_device)
        self._weights = dict(config["reward"])

    def reset(self, mask: torch.Tensor) -> torch.Tensor:
        self.laryngoscopes.load_state(self._start_state, rows=mask)
        return self._prev

    def act(self, actions: torch.Tensor, stepped: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        dev = self.laryngoscopes
        dev.control_step(actions.to(torch.float64), moving=stepped)
        features, touching = dev.features()
        f = in_workspace(features, touching, self._low, self._high, self._rest, dev.xp)
        return f.to(self.dtype), dev.normal_force.to(self.dtype), dev.sideways_force.to(self.dtype)

    def observation(self, features: torch.Tensor) -> torch.Tensor:
        return self.laryngoscopes.observation().to(self.dtype)

    def report(self, info: dict[str, Any], stepped: torch.Tensor) -> torch.Tensor:
        term, values = batch_report(self.laryngoscopes, self._weights, lambda x: x.to(self.dtype))
        info.update(values)
        return term

    def compile(self, options: dict[str, Any]) -> bool:
        """Compile the engine's own step (:meth:`~.tensors.LaryngoscopeTensors.compile_substep`: the tensor
        engine's substep; the fused kernel has nothing left to compile) and keep it apart: the env compiles
        its work around the device's calls."""
        self.laryngoscopes.compile_substep(options)
        return True
