"""A third device, plugged in through the config alone: a rigid probe pressing along one axis.

The probe touches the tongue where the action's first two entries put it (as the ideal device does)
and moves along the surface's normal at up to ``device.max_hand_speed`` (the third entry: +1 presses
in, -1 backs out); the fourth entry is unused. The tongue pushes back with its own load-indentation
curve (``scene.contact_curve``: the same law the laryngoscope's blade feels), so the force lags the
command: the agent must learn to press to a depth, not to a force.

Use it from any SoftSphere id, with this file's folder on ``sys.path``::

    env = gym.make("softenv:SoftSphere-v0", device={"kind": "probe_device:PROBE"})

The single env steps :class:`Probe` (Python floats), the vector env :class:`ProbeBatch` (numpy), with
the same IEEE operations, so the two agree bit for bit (``tests/test_devices.py``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from softenv import Config, DeviceKind, DeviceScene, ForceBox

PROBE_OBS = ("insertion", "lateral", "depth", "normal")


class ProbeLaw:
    """What single and batch share: the force box, the speed, the depth range and the tissue's curve."""

    def __init__(self, scene: DeviceScene, config: Config) -> None:
        self.box = ForceBox(scene.workspace)
        curve = scene.contact_curve(config["device"]["max_normal_force"])
        self.depths, self.loads = np.r_[0.0, curve.depths], np.r_[0.0, curve.loads]
        self.max_depth = float(curve.design_depth)             # the depth at the device's largest force
        self.step = config["device"]["max_hand_speed"] * config["dynamics"]["dt"]   # m per control step at +1
        self.low, self.high = np.asarray(scene.workspace.low), np.asarray(scene.workspace.high)

    def depth_after(self, depth: Any, press: Any) -> Any:
        return np.minimum(np.maximum(depth + press * self.step, 0.0), self.max_depth)

    def force(self, depth: Any) -> Any:
        return np.minimum(np.interp(depth, self.depths, self.loads), self.high[2])

    def observation(self, features: Any, depth: Any) -> Any:
        unit = self.box.normalised(features)
        return np.stack([unit[..., 0], unit[..., 1], 2.0 * depth / self.max_depth - 1.0, unit[..., 2]], axis=-1)


class Probe:
    """One probe (:class:`softenv.devices.base.Device`)."""

    obs_names = PROBE_OBS
    info_keys = ("probe_depth_m",)
    episode_info_keys: tuple[str, ...] = ()

    def __init__(self, scene: DeviceScene, config: Config) -> None:
        self.law = ProbeLaw(scene, config)
        self.depth = 0.0

    def reset(self) -> list[float]:
        self.depth = 0.0
        return [0.0, 0.0, -1.0, 0.0]

    def act(self, action: list[float]) -> tuple[list[float], float, float]:
        law = self.law
        self.depth = float(law.depth_after(np.array([self.depth]), action[2])[0])
        normal = float(law.force(np.array([self.depth]))[0])
        place = law.box.features(np.array(action))
        return [float(place[0]), float(place[1]), normal, 0.0], normal, 0.0

    def observation(self, features: list[float]) -> list[float]:
        return self.law.observation(np.array([features]), np.array([self.depth]))[0].tolist()

    def report(self, info: dict[str, Any]) -> float:
        info["probe_depth_m"] = self.depth
        return 0.0

    def episode_info(self, b: np.ndarray) -> dict[str, Any]:
        return {}

    def drawing(self) -> None:
        return None

    def state(self) -> float:
        return self.depth

    def load_state(self, state: float) -> None:
        self.depth = float(state)


class ProbeBatch:
    """``n`` probes (:class:`softenv.devices.base.DeviceBatch`): :class:`Probe`'s arithmetic on arrays."""

    obs_names = PROBE_OBS
    info_keys = ("probe_depth_m",)
    episode_info_keys: tuple[str, ...] = ()

    def __init__(self, scene: DeviceScene, config: Config, n: int) -> None:
        self.law = ProbeLaw(scene, config)
        self.depth = np.zeros(n)

    def reset(self, mask: np.ndarray) -> np.ndarray:
        self.depth[mask] = 0.0
        return np.array([0.0, 0.0, -1.0, 0.0])

    def act(self, actions: np.ndarray, stepped: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        law = self.law
        self.depth = np.where(stepped, law.depth_after(self.depth, actions[:, 2]), self.depth)
        normal = law.force(self.depth)
        place = law.box.features(actions)
        features = np.stack([place[:, 0], place[:, 1], normal, np.zeros_like(normal)], axis=1)
        return features, normal, np.zeros_like(normal)

    def observation(self, features: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        return self.law.observation(features, self.depth if mask is None else self.depth[mask])

    def report(self, info: dict[str, Any], stepped: np.ndarray) -> float:
        info["probe_depth_m"] = self.depth.copy()
        return 0.0

    def episode_info(self, i: int, b: np.ndarray) -> dict[str, Any]:
        return {}

    def drawing(self, i: int) -> None:
        return None

    def state(self) -> np.ndarray:
        return self.depth.copy()

    def load_state(self, state: np.ndarray) -> None:
        self.depth = np.array(state, dtype=np.float64)


PROBE = DeviceKind("probe", PROBE_OBS, Probe, ProbeBatch)
