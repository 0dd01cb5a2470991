"""The hand-log vocabulary: what a hand-pose log (:data:`softenv.training.logs.HAND_LOG`) means on the
simulated laryngoscope. Its scene (SoftSphereHaptic-v0's, with a caller's sections), the hand's pose
relative to its start, the workspace each column may span, the resampling of a log at the control
period with the device's speed limits, and the path a hand on the device follows when a log asks
for more. Scoring, the synthetic trainees and ``softenv play`` all speak it."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..devices.laryngoscope.params import LaryngoscopeParams
from ..devices.laryngoscope.physics import hand_action
from ..envs import HAPTIC_SCENES
from ..envs.config import scene_config, scene_sections
from ..envs.single import SoftSphereEnv
from .logs import HAND_LOG, MAX_GAP_S, check_limits, check_table


def haptic_config(scene: dict[str, Any] | None) -> dict[str, dict[str, Any]]:
    """SoftSphereHaptic-v0's config with ``scene``'s sections merged in."""
    return scene_config(HAPTIC_SCENES["SoftSphereHaptic-v0"], scene_sections(scene), "scene")


def haptic_env(scene: dict[str, Any] | None, horizon: int) -> Any:
    """A SoftSphereHaptic-v0 env on ``scene``'s sections, reaching one target over ``horizon`` steps."""
    scene = scene_sections(scene)
    scene["task"] = {**scene.get("task", {}), "kind": "reach", "horizon": horizon}
    return SoftSphereEnv(base_scene=HAPTIC_SCENES["SoftSphereHaptic-v0"], **scene)


def relative_hand_pose(env: Any) -> np.ndarray:
    """The hand's pose (x, z, pitch, y) relative to its start pose."""
    laryngoscope = env.device.laryngoscope
    gx, gy = laryngoscope.params.grip_start
    x, z, pitch, y = laryngoscope.hand_pose
    return np.array([x - gx, z - gy, pitch, y])


def hand_limits(config: dict) -> dict[str, tuple[float, float]]:
    """The hand-pose columns' ranges relative to the start pose (the hand's workspace)."""
    p = LaryngoscopeParams.from_config(config)
    low, high = p.hand_box
    start = (*p.grip_start, 0.0, 0.0)
    return {c: (lo - s, hi - s) for c, lo, hi, s in zip(HAND_LOG.columns[1:], low, high, start)}


def hand_actions(table: np.ndarray, scene: dict[str, Any] | None = None,
                 source: str = "trajectory") -> tuple[np.ndarray, np.ndarray]:
    """Check a hand-pose log against the laryngoscope of ``scene`` and resample it at the control
    period: returns the control times ``(K,)`` (s, ends of each period) and the poses ``(K + 1, 4)``
    relative to the start. Errors name the row and column: a pose outside the hand's workspace, or a
    move faster than the device's speed limits."""
    table = check_table(table, HAND_LOG, source)
    config = haptic_config(scene)
    relative = table.copy()
    relative[:, 0] -= table[0, 0]
    relative[:, 1:] -= table[0, 1:]
    check_limits(relative, HAND_LOG, hand_limits(config), source)
    gaps = np.diff(relative[:, 0])
    if gaps.max() > MAX_GAP_S:
        i = int(np.argmax(gaps)) + 1
        raise ValueError(f"{source}: row {i + 1}, column 'time_s' = {table[i, 0]:g}: {gaps[i - 1]:g} s after the row "
                         f"before; hand poses are interpolated between rows at most {MAX_GAP_S:g} s apart")
    dt = config["dynamics"]["dt"]
    steps = int(math.floor(relative[-1, 0] / dt + 1e-9))
    if steps < 1:
        raise ValueError(f"{source}: row {len(table)}, column 'time_s': the log lasts {relative[-1, 0]:g} s, shorter "
                         f"than one control period ({dt:g} s)")
    times = np.arange(steps + 1) * dt
    poses = np.column_stack([np.interp(times, relative[:, 0], relative[:, j]) for j in range(1, 5)])
    p = LaryngoscopeParams.from_config(config)
    names = ("hand_x_m / hand_z_m (along the blade)", "hand_x_m / hand_z_m (across the blade)", "hand_y_m",
             "hand_pitch_rad")
    limits = (p.max_hand_speed, p.max_hand_speed, p.max_sweep_speed, p.max_pitch_rate)
    for k in range(steps):
        v = (poses[k + 1] - poses[k]) / dt
        a = hand_action(v[0], v[1], v[2], v[3], poses[k, 2], p)
        worst = int(np.argmax(np.abs(a)))
        if abs(a[worst]) > 1.0 + 1e-6:
            row = int(np.searchsorted(relative[:, 0], times[k + 1] - 1e-12)) + 1
            raise ValueError(f"{source}: row {row}, column {names[worst]!r}: the hand moves at "
                             f"{abs(a[worst]) * limits[worst]:.3g} {'rad/s' if worst == 3 else 'm/s'} near "
                             f"time_s = {table[0, 0] + times[k + 1]:g}; the device allows [0, {limits[worst]:g}]")
    return times[1:], poses


def speed_limited(pose: np.ndarray, dt: float, scene: dict[str, Any] | None) -> np.ndarray:
    """The path a hand on the device follows: each step's move scaled down to the speed limits."""
    p = LaryngoscopeParams.from_config(haptic_config(scene))
    out = pose.copy()
    for k in range(len(pose) - 1):
        move = pose[k + 1] - out[k]
        v = move / dt
        excess = max(1.0, max(abs(a) for a in hand_action(v[0], v[1], v[2], v[3], out[k, 2], p)) * (1.0 + 1e-9))
        out[k + 1] = out[k] + move / excess
    return out
