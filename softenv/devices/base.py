"""The device contract: what an env asks of a force device, for one device on Python floats and for a
batch on arrays.

An env (:class:`softenv.envs.single.SoftSphereEnv`, :class:`softenv.envs.vector.SoftSphereVectorEnv`)
is the task -- tissue, response, dynamics, targets, reward -- plus a device, chosen by the scene's
``device.kind`` alone. Each step the env hands the device the checked action; the device returns the
force features the tissue's response reads (insertion and lateral arc in m, normal and sideways
force in N), and the normal and sideways force for the force reward. The device then adds its own
observation slice, its reward terms and info keys, and at an episode's end its episode record
(the laryngoscope's clinical metrics).

A kind is a :class:`DeviceKind`: its name, its observation names, and factories of the two forms.
``device.kind`` names a built-in kind (:data:`BUILT_IN`) or, as Gymnasium's entry points do, a
``"module:attribute"`` whose attribute is a :class:`DeviceKind`, so a new device plugs in through
the config alone (``examples/probe_device.py``; README "Adding a device").
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Callable, Protocol, runtime_checkable

import numpy as np

from ..forces import Workspace
from ..geometry import SphereMesh
from ..shape_model import ShapeModel
from ..tissue import TissueParams
from .contact import ContactCurve
from ..sections import SceneConfig

Config = SceneConfig


class DeviceScene(Protocol):
    """What a device may read of the scene (:class:`softenv.envs.scene.Scene` has it)."""

    @property
    def mesh(self) -> SphereMesh: ...

    @property
    def tissue(self) -> TissueParams: ...

    @property
    def shape_model(self) -> ShapeModel: ...

    @property
    def workspace(self) -> Workspace: ...             # the force-feature box the response covers

    @property
    def rest_features(self) -> np.ndarray: ...       # zero force at the middle of the contact range

    def contact_curve(self, design_force: float) -> ContactCurve: ...


class DeviceNames(Protocol):
    """What both forms of a device name: ``obs_names`` its observation slice (values in [-1, 1]),
    ``info_keys`` what ``report`` adds to ``info`` every step, ``episode_info_keys`` what
    ``episode_info`` adds at an episode's last step."""

    @property
    def obs_names(self) -> tuple[str, ...]: ...

    @property
    def info_keys(self) -> tuple[str, ...]: ...

    @property
    def episode_info_keys(self) -> tuple[str, ...]: ...


@runtime_checkable
class Device(DeviceNames, Protocol):
    """One device, stepped on Python floats (the single env; a step's budget is microseconds). A device
    that holds what cannot be pickled (a pymunk space) pickles its :meth:`state` and rebuilds
    (``__getstate__`` / ``__setstate__``)."""


    def reset(self) -> list[float]:
        """Put the device at rest; returns the previous action an episode starts with (4 floats)."""
        ...

    def act(self, action: list[float]) -> tuple[list[float], float, float]:
        """Apply a checked action (4 floats in [-1, 1]) for one control period: the force features on
        the tissue (within the scene's workspace), and the normal and sideways force (N)."""
        ...

    def observation(self, features: list[float]) -> list[float]:
        """The observation slice after the step that produced ``features``."""
        ...

    def report(self, info: dict[str, Any]) -> float:
        """Add this step's ``info_keys`` to ``info`` (its reward terms among them, named ``reward_*``);
        returns the sum of its reward terms, added left to right in the order written (HER's
        ``compute_reward`` sums them again from ``info``)."""
        ...

    def episode_info(self, b: np.ndarray) -> dict[str, Any]:
        """What ``info`` gets at an episode's last step, given the tissue's shape ``b`` then."""
        ...

    def drawing(self) -> dict[str, Any] | None:
        """What a renderer draws of the device beside the tissue (``None``: nothing)."""
        ...

    def state(self) -> Any:
        """Everything that a device rebuilt from the scene needs to continue bit for bit."""
        ...

    def load_state(self, state: Any) -> None:
        """Continue from :meth:`state`."""
        ...


@runtime_checkable
class DeviceBatch(DeviceNames, Protocol):
    """``n`` devices stepped together on arrays (the vector env), bit for bit the single device's
    arithmetic where the kind says so (the ideal device and device 0 of the laryngoscope exactly).
    Pickling as :class:`Device` does."""


    def reset(self, mask: np.ndarray) -> np.ndarray:
        """Put the masked devices at rest; returns the previous action their episodes start with
        (broadcastable to ``(mask.sum(), 4)``)."""
        ...

    def act(self, actions: np.ndarray, stepped: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Apply checked actions ``(n, 4)``; rows outside ``stepped`` hold still (their results are
        discarded): force features ``(n, 4)``, normal and sideways force ``(n,)``."""
        ...

    def observation(self, features: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """Observation slices of every device (``mask`` None) or of the masked ones; ``features`` are
        the force features of the same rows."""
        ...

    def report(self, info: dict[str, Any], stepped: np.ndarray) -> Any:
        """Add the ``info_keys`` (arrays over all devices) to ``info`` and record the ``stepped`` rows;
        returns the sum of the reward terms (``reward_*`` keys, as :meth:`Device.report`; an array, or 0.0)."""
        ...

    def episode_info(self, i: int, b: np.ndarray) -> dict[str, Any]:
        """Device ``i``'s episode-end info, given its tissue shape ``b``."""
        ...

    def drawing(self, i: int) -> dict[str, Any] | None:
        """What a renderer draws of device ``i``."""
        ...

    def state(self) -> Any:
        """Everything that the batch rebuilt from the scene needs to continue bit for bit."""
        ...

    def load_state(self, state: Any) -> None:
        """Continue from :meth:`state`."""
        ...


@runtime_checkable
class DeviceTensors(DeviceNames, Protocol):
    """``n`` devices on torch tensors of one torch device (the torch twin,
    :class:`softenv.envs.torch_twin.SoftSphereTorchVectorEnv`): :class:`DeviceBatch`'s step on tensors,
    with no read back to the host, so that a GPU step never waits for it, and its state written where the
    last step left it (one address a tensor), so that the twin's ``cuda_graph`` may record the step."""

    def reset(self, mask: Any) -> Any:
        """Put the masked devices at rest; returns the previous action their episodes start with
        (a tensor broadcastable to ``(n, 4)``)."""
        ...

    def act(self, actions: Any, stepped: Any) -> tuple[Any, Any, Any]:
        """As :meth:`DeviceBatch.act`, on tensors in the env's dtype."""
        ...

    def observation(self, features: Any) -> Any:
        """Observation slices ``(n, m)`` of every device."""
        ...

    def report(self, info: dict[str, Any], stepped: Any) -> Any:
        """As :meth:`DeviceBatch.report` (tensors); records nothing for the episode's end."""
        ...

    def compile(self, options: dict[str, Any]) -> bool:
        """The twin's ``compile_options``: return True where this device keeps its step apart, compiled here
        with ``torch.compile(**options)`` or a kernel of its own, and the env compiles its work around the
        device's calls (each a graph break, run as it is); or return False, and the env compiles its whole
        step, this device's work inlined (``fullgraph``)."""
        ...

    def differentiable(self) -> None:
        """The twin's ``differentiable=True``: from now on :meth:`act`, :meth:`observation` and :meth:`report`
        carry torch autograd's graph from the actions and the device's state (held out of place), or raise a
        ``ValueError`` naming the setting this device cannot differentiate."""
        ...

    def detach(self) -> None:
        """Cut autograd's graph at the device's current state (the twin's ``detach()``)."""
        ...

    def track_state(self) -> dict[str, Any]:
        """The twin's ``track_state()``: hold the device's state as new leaves of autograd's graph (after
        :meth:`differentiable`) and return them by name; a device with no state returns ``{}``."""
        ...

    @property
    def scene_params(self) -> tuple[str, ...]:
        """The scene parameters (the twin's ``track_params()`` names: factors on the scene's values) whose
        effect on this device its step carries; a device on which the tissue's modulus acts only through
        the response (the twin's own lookup) names ``"tissue_stiffness"`` with nothing to do for it. The
        twin decides which of them the scene has: it offers ``"stiffening_depth"`` only where the tongue is
        analytic on the stiffening law, whatever the device names."""
        ...

    def use_params(self, params: dict[str, Any]) -> None:
        """The twin's ``track_params()``: the leaves of :attr:`scene_params` it tracks (``(n,)`` factors, by
        name), which every later :meth:`act` reads."""
        ...


@dataclass(frozen=True)
class DeviceKind:
    """A kind of device: what ``device.kind`` names. ``single(scene, config)`` and ``batch(scene, config,
    n)`` build it, and, for a kind the torch twin can step, ``tensors(scene, config, n, torch_device,
    dtype)``; ``obs_names`` are known without building it (observation spaces, controllers)."""

    name: str
    obs_names: tuple[str, ...]
    single: Callable[[DeviceScene, Config], Device]
    batch: Callable[[DeviceScene, Config, int], DeviceBatch]
    tensors: Callable[[DeviceScene, Config, int, Any, Any], DeviceTensors] | None = None


# the built-in kinds, as entry points: a kind's module loads when a scene names it (pymunk stays out otherwise)
BUILT_IN = {"ideal": "softenv.devices.ideal:IDEAL", "laryngoscope": "softenv.devices.laryngoscope:LARYNGOSCOPE"}


def device_kind(name: Any, setting: str = "device.kind") -> DeviceKind:
    """The :class:`DeviceKind` that ``name`` names: a built-in kind or a ``"module:attribute"`` entry point."""
    allowed = f"allowed: {sorted(BUILT_IN)} or 'module:attribute' naming a softenv.devices.base.DeviceKind"
    if not isinstance(name, str):
        raise ValueError(f"{setting}={name!r} must be a string; {allowed}")
    entry = BUILT_IN.get(name, name)
    module, _, attribute = entry.partition(":")
    if not module or not attribute:
        raise ValueError(f"{setting}={name!r} is not a device kind; {allowed}")
    try:
        kind = getattr(importlib.import_module(module), attribute)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"{setting}={name!r} cannot be loaded ({type(exc).__name__}: {exc}); {allowed}") from exc
    if not isinstance(kind, DeviceKind):
        raise ValueError(f"{setting}={name!r} names a {type(kind).__name__}, not a DeviceKind; {allowed}")
    return kind
