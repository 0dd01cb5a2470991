"""The laryngoscope as a part an env composes (the contract of :mod:`softenv.devices.base`), for one
device (the batch's part is :mod:`.part_batch`): the contact's force features clipped to the scene's
workspace, the incisor reward term, the info keys, and the clinical record of each episode
(:mod:`softenv.devices.laryngoscope.clinical`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from . import clinical
from ..._ops import PhysicsOps, ScalarOps
from ..base import Config, DeviceScene
from ..contact import TongueContact
from . import LARYNGOSCOPE_OBS
from .params import LaryngoscopeParams
from .single import Laryngoscope
from .state import DeviceState
from ...sections import RewardSection

WALL_FACTOR = 1e3       # the saturated tongue's wall: this many times the coupling's stiffness
INFO_KEYS = ("reward_incisor", "tongue_force_N", "incisor_force_N", "haptic_force_N", "blade_pose")


def laryngoscope_parts(scene: DeviceScene, config: Config) -> tuple[LaryngoscopeParams, TongueContact]:
    """The laryngoscope's parameters and its contact law with the scene's tongue."""
    dev = config["device"]
    contact = TongueContact(scene.contact_curve(dev["max_normal_force"]), dev["friction"],
                            wall_stiffness=WALL_FACTOR * dev["coupling_stiffness"])
    return LaryngoscopeParams.from_config(config), contact


def glottic_view(scene: DeviceScene, b: np.ndarray) -> float:
    """The glottic-view proxy (%) of the tongue's shape ``b`` (:func:`softenv.devices.laryngoscope.clinical.glottic_view`)."""
    vertices = scene.shape_model.decode(b) / scene.tissue.radius
    return clinical.glottic_view(clinical.sagittal_profile(vertices, scene.mesh.triangles), 1.0)


def incisor_term(incisor_force: Any, weights: RewardSection) -> Any:
    """``reward_incisor``: ``-w F_incisor / F_safe`` (any force on the teeth is an error of technique)."""
    return -weights["incisor_weight"] * (incisor_force / weights["safe_force"])


def in_workspace(features: Any, touching: Any, low: Any, high: Any, rest: Any, ops: PhysicsOps) -> Any:
    """A batch's force features ``(n, 4)`` clipped to the scene's workspace (``ops.clip``, as the single
    device clips each of its own: ``ArrayOps`` or ``TorchOps`` here), the rest features where a device
    does not touch the tongue."""
    return ops.where(touching[:, None], ops.clip(features, low, high), rest)


def batch_report(dev: Any, weights: RewardSection, cast: Any = None) -> tuple[Any, dict[str, Any]]:
    """A batch's incisor reward term and its :data:`INFO_KEYS` values, each through ``cast`` (a dtype
    conversion of tensors; none for arrays)."""
    same = cast or (lambda x: x)
    incisor = dev.incisor_force
    term = same(incisor_term(incisor, weights))
    return term, {"reward_incisor": term, "tongue_force_N": same(dev.tongue_force), "incisor_force_N": same(incisor),
                  "haptic_force_N": same(dev.haptic_force()), "blade_pose": same(dev.blade_pose())}


class PickledByState:
    """Pickles a part's pymunk physics (the attribute ``physics_name``) as its ``state()``, and rebuilds
    it from the scene when unpickled: pymunk's space cannot be pickled, and a device rebuilt from its
    state continues bit for bit (:mod:`.space`)."""

    physics_name: str
    _scene: DeviceScene
    _config: Config

    def _rebuilt(self, state: DeviceState) -> Any:
        raise NotImplementedError

    def __getstate__(self) -> dict[str, Any]:
        out = self.__dict__.copy()
        out[self.physics_name] = getattr(self, self.physics_name).state()
        return out

    def __setstate__(self, state: dict[str, Any]) -> None:
        device_state = state.pop(self.physics_name)
        self.__dict__.update(state)
        physics = self._rebuilt(device_state)
        physics.load_state(device_state)
        setattr(self, self.physics_name, physics)


class LaryngoscopePart(PickledByState):
    """One laryngoscope in an env (:class:`~softenv.devices.base.Device`); ``laryngoscope`` is its
    physics (:class:`~.single.Laryngoscope`), ``clinical`` its episode's record."""

    obs_names = LARYNGOSCOPE_OBS
    info_keys = INFO_KEYS
    episode_info_keys = ("clinical",)
    physics_name = "laryngoscope"

    def __init__(self, scene: DeviceScene, config: Config) -> None:
        self._scene, self._config = scene, config
        self.laryngoscope = Laryngoscope(*laryngoscope_parts(scene, config))
        self._box = (scene.workspace.low, scene.workspace.high)
        self._rest = scene.rest_features.tolist()
        self._weights = config["reward"].copy()
        self.clinical = clinical.ClinicalRecorder(1, config["dynamics"]["dt"], config["task"]["horizon"])

    def reset(self) -> list[float]:
        self.laryngoscope.reset()
        self.clinical.start(0, self.laryngoscope.clinical_values())
        return [0.0, 0.0, 0.0, 0.0]

    def act(self, action: list[float]) -> tuple[list[float], float, float]:
        dev = self.laryngoscope
        dev.control_step(action)
        f = dev.features()
        P, Q = dev.normal_force, dev.sideways_force
        if f is None:
            return self._rest, P, Q
        lo, hi = self._box
        return [ScalarOps.clip(x, low, high) for x, low, high in zip(f, lo, hi)], P, Q

    def observation(self, features: list[float]) -> list[float]:
        return self.laryngoscope.observation()

    def report(self, info: dict[str, Any]) -> float:
        dev = self.laryngoscope
        incisor = dev.incisor_force
        term = incisor_term(incisor, self._weights)
        info.update({"reward_incisor": term, "tongue_force_N": dev.tongue_force, "incisor_force_N": incisor,
                     "haptic_force_N": dev.haptic_force()[0], "blade_pose": dev.blade_pose()[0]})
        self.clinical.record_one(dev.clinical_values())
        return term

    def clinical_summary(self, b: np.ndarray) -> dict[str, float]:
        """The episode's clinical metrics so far, with the tongue's shape ``b`` now."""
        return self.clinical.summary(0, glottic_view(self._scene, b))

    def episode_info(self, b: np.ndarray) -> dict[str, Any]:
        return {"clinical": self.clinical_summary(b)}

    def drawing(self) -> dict[str, Any]:
        return self.laryngoscope.drawing()[0]

    def state(self) -> Any:
        return self.laryngoscope.state()

    def load_state(self, state: Any) -> None:
        self.laryngoscope.load_state(state)

    def _rebuilt(self, state: DeviceState) -> Laryngoscope:
        return Laryngoscope(*laryngoscope_parts(self._scene, self._config))
