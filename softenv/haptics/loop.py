"""The haptic loop: the laryngoscope's physics at 1 kHz for a real force-feedback device or a person.

A device driver (or a mouse, or a recorded hand path) calls :meth:`HapticLoop.tick` every
millisecond with the hand's pose and renders the force it returns; at a graphics rate (30-60 Hz)
:meth:`HapticLoop.surface` gives the tongue's surface ``X = m + Phi b`` to draw. The physics is the
single env's (:class:`softenv.devices.laryngoscope.single.Laryngoscope`, same scene config)::

    from softenv.haptics import HapticLoop

    loop = HapticLoop()                      # SoftSphereHaptic-v0's scene, 1 kHz
    pose = loop.hand_pose                                     # x, z (m), pitch (rad), y (m)
    for tick in range(2000):                                  # 2 s of a hand pressing down at 2 cm/s
        force = loop.tick(pose - [0.0, 0.02 * tick / 1000, 0.0, 0.0])
        # driver.set_force(force)                             # (3,) N, world x, y, z, within the preset
    vertices = loop.surface().reshape(-1, 3)                 # for the graphics thread

The hand moves by velocity: each tick sets the hand's velocity to reach the given pose at the
tick's end (so the coupling's damper sees the motion); a pose outside the hand's workspace is
projected onto it (documented limits: :meth:`LaryngoscopeParams.hand_box`). The force is the
coupling's pull on the hand, scaled to the ``device.haptic_preset`` device's stiffness and
saturated at its maximum force.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from .._validation import check_array, check_real, real_array
from ..devices.laryngoscope.part import laryngoscope_parts
from ..devices.laryngoscope.single import Laryngoscope
from ..envs import HAPTIC_SCENES
from ..envs.config import scene_config
from ..envs.task import Dynamics
from ..envs.world import World


class HapticLoop:
    """The laryngoscope and tongue of a scene, ticked at ``rate`` Hz.

    Args:
        env_id: a SoftSphereHaptic id whose scene to use.
        rate: ticks per second (1,000 or more: haptic rendering needs 1 kHz).
        **scene: scene sections merged into the id's (as for ``gym.make``).
    """

    def __init__(self, env_id: str = "SoftSphereHaptic-v0", rate: float = 1000.0, **scene: Any) -> None:
        if env_id not in HAPTIC_SCENES:
            raise ValueError(f"env_id={env_id!r} is not a haptic id; choose one of {list(HAPTIC_SCENES)}")
        rate = check_real(rate, "rate", 1000.0, 1e5)
        self.world = World(scene_config(HAPTIC_SCENES[env_id], scene))
        params, contact = laryngoscope_parts(self.world.scene, self.world.config)
        params = dataclasses.replace(params, dt=1.0 / rate)
        self.device = Laryngoscope(params, contact)
        self.period = 1.0 / rate
        dyn = self.world.config["dynamics"]
        self._dynamics: dict[str, Any] = {"kind": dyn["kind"], "relaxed_fraction": dyn["relaxed_fraction"],
                          "time_constant": dyn["time_constant"]}
        self._low, self._high = params.hand_box
        self.reset()

    def reset(self) -> None:
        """Blade at its start pose, at rest; tissue at rest."""
        self.device.reset()
        self.time = 0.0
        self._z = self.world.b_rest.copy()
        self.b = self.world.b_rest.copy()
        self._shape_time = 0.0

    @property
    def hand_pose(self) -> np.ndarray:
        """The hand's pose: grip x, z (m), pitch (rad), lateral y (m)."""
        return np.array(self.device.hand_pose)

    def tick(self, hand_pose: Any) -> np.ndarray:
        """Advance one period toward ``hand_pose`` (x, z, pitch, y); returns the force ``(3,)`` (N, world
        x, y, z) to render to the hand."""
        pose = hand_pose.tolist() if type(hand_pose) is np.ndarray and hand_pose.dtype == np.float64 else hand_pose
        # plain floats: a tick's budget has no room for array checks; anything else goes through the one rule
        if type(pose) is not list or len(pose) != 4 or not all(type(v) is float for v in pose):
            pose = real_array(hand_pose, "hand_pose", (4,)).astype(np.float64).tolist()
        if not all(map(math.isfinite, pose)):
            raise ValueError(f"hand_pose must be 4 finite numbers (x, z, pitch, y), got {hand_pose!r}")
        now = self.device.hand_pose
        v = [(min(max(p, lo), hi) - q) / self.period for p, lo, hi, q in zip(pose, self._low, self._high, now)]
        self.device.substeps(v[0], v[1], v[2], v[3], self.device.n_substeps)
        self.time += self.period
        return self.device.haptic_force()[0]

    def features(self) -> np.ndarray:
        """The tongue's force features now (insertion, lateral arc in m; normal, sideways force in N)."""
        f = self.device.features()
        if f is None:
            return self.world.scene.rest_features.copy()
        box = self.world.scene.workspace
        return np.minimum(np.maximum(np.array(f), box.low), box.high)

    def surface(self) -> np.ndarray:
        """The tongue's surface now, ``(3 n,)`` (m): the response to the current contact, with the
        scene's creep over the time since the last call (the force taken as held over it)."""
        elapsed = self.time - self._shape_time
        self._shape_time = self.time
        if elapsed > 0.0:
            g = self.world.response_one(self.features().tolist())
            self.b = Dynamics(dt=elapsed, **self._dynamics).step(self._z, g)
        return self.world.scene.shape_model.decode(self.b)

    def run(self, poses: Any) -> np.ndarray:
        """Tick through hand poses ``(T, 4)``; returns the forces ``(T, 3)``."""
        poses = check_array(poses, "poses", ndim=2, shape=(4,))
        return np.stack([self.tick(p) for p in poses])
