"""The hand-log vocabulary: what a hand-pose log (:data:`softenv.training.logs.HAND_LOG`) means on the
simulated laryngoscope. Its scene (SoftSphereHaptic-v0's, with a caller's sections), the hand's pose
relative to its start, the workspace each column may span, the resampling of a log at the control
period with the device's speed limits, and the path a hand on the device follows when a log asks
for more. Scoring, the synthetic trainees and ``softenv play`` all speak it.

The scene is made once where it enters (:func:`haptic_config` from a caller's sections, in ``softenv play``,
``softenv score`` and the skills lab) and passed inward as the made config; the functions here take that
config, ``None`` meaning SoftSphereHaptic-v0's own."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any, cast

import numpy as np

from ..devices.laryngoscope.params import LaryngoscopeParams
from .._ops import ScalarOps
from ..devices.laryngoscope.physics import hand_action, hand_command
from ..envs import HAPTIC_SCENES
from ..envs.config import check_config, scene_config, scene_sections
from ..envs.single import SoftSphereEnv
from ..sections import SceneConfig
from .logs import HAND_LOG, MAX_GAP_S, check_limits, check_table


def haptic_config(scene: dict[str, Any] | None) -> SceneConfig:
    """SoftSphereHaptic-v0's config with ``scene``'s sections merged in; a scene of another device is refused
    (a hand moves the laryngoscope: hand logs, play and their scoring need it)."""
    return _laryngoscope(scene_config(HAPTIC_SCENES["SoftSphereHaptic-v0"], scene_sections(scene), "scene"))


def hand_config(config: SceneConfig | None) -> SceneConfig:
    """``config`` (made by :func:`haptic_config`), or SoftSphereHaptic-v0's own for ``None``; a config of another
    device is refused."""
    return haptic_config(None) if config is None else _laryngoscope(check_config(config, "config", "haptic_config(sections)"))


def _laryngoscope(config: SceneConfig) -> SceneConfig:
    kind = config["device"]["kind"]
    if kind != "laryngoscope":
        raise ValueError(f"device.kind={kind!r}: a hand-pose log moves the laryngoscope, so replaying and scoring "
                         "it needs device.kind='laryngoscope' (a force-command log is the ideal device's)")
    return config


def reach_env(config: SceneConfig, horizon: int, render_mode: str | None = None) -> Any:
    """An env of the made ``config`` reaching one target over ``horizon`` steps (a replay's, a scripted hand's)."""
    task = {**config["task"], "kind": "reach", "horizon": horizon}
    return SoftSphereEnv.from_config(cast(SceneConfig, {**config, "task": task}), render_mode)


def relative_hand_pose(env: Any) -> np.ndarray:
    """The hand's pose (x, z, pitch, y) relative to its start pose."""
    laryngoscope = env.device.laryngoscope
    gx, gy = laryngoscope.params.grip_start
    x, z, pitch, y = laryngoscope.hand_pose
    return np.array([x - gx, z - gy, pitch, y])


def sensor_readings(env: Any) -> dict[str, float]:
    """What the device's sensors read now (:data:`~softenv.training.logs.SENSOR_COLUMNS`): the tongue's normal
    force on the blade (N) and the blade's height (mm, its centre of mass in the sagittal frame)."""
    laryngoscope = env.device.laryngoscope
    return {"tongue_force_N": float(laryngoscope.tongue_force),
            "blade_z_mm": float(laryngoscope.blade_pose()[0][1]) * 1e3}


def workspace(config: SceneConfig) -> tuple[np.ndarray, np.ndarray]:
    """The hand's workspace relative to its start pose under ``config`` (low, high; x, z, pitch, y)."""
    return relative_box(LaryngoscopeParams.from_config(config))


def hand_limits(config: SceneConfig) -> dict[str, tuple[float, float]]:
    """The hand-pose columns' ranges relative to the start pose (the hand's workspace)."""
    low, high = workspace(config)
    return {c: (float(lo), float(hi)) for c, lo, hi in zip(HAND_LOG.columns[1:], low, high)}


def hand_actions(table: np.ndarray, config: SceneConfig | None = None,
                 source: str = "trajectory") -> tuple[np.ndarray, np.ndarray]:
    """Check a hand-pose log against the laryngoscope of ``config`` and resample it at the control
    period: returns the control times ``(K,)`` (s, ends of each period) and the poses ``(K + 1, 4)``
    relative to the start. Errors name the row and column: a pose outside the hand's workspace, or a
    move faster than the device's speed limits."""
    table = check_table(table, HAND_LOG, source)
    config = hand_config(config)
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
    box = relative_box(p)
    for k in range(steps):
        if action_to(poses[k], poses[k + 1], dt, p, box) is None:
            v = (poses[k + 1] - poses[k]) / dt
            a = hand_action(v[0], v[1], v[2], v[3], poses[k, 2], p)
            worst = int(np.argmax(np.abs(a)))
            row = int(np.searchsorted(relative[:, 0], times[k + 1] - 1e-12)) + 1
            raise ValueError(f"{source}: row {row}, column {names[worst]!r}: the hand moves at "
                             f"{abs(a[worst]) * limits[worst]:.3g} {'rad/s' if worst == 3 else 'm/s'} near "
                             f"time_s = {table[0, 0] + times[k + 1]:g}; the device allows [0, {limits[worst]:g}]")
    return times[1:], poses


def relative_box(p: LaryngoscopeParams) -> tuple[np.ndarray, np.ndarray]:
    """The hand's workspace relative to its start pose, in hand-log column order (x, z, pitch, y)."""
    low, high = p.hand_box
    start = np.array([*p.grip_start, 0.0, 0.0])
    return np.array(low) - start, np.array(high) - start


def action_to(now: np.ndarray, goal: np.ndarray, dt: float, p: LaryngoscopeParams,
              box: tuple[np.ndarray, np.ndarray], tol: float = 1e-6) -> np.ndarray | None:
    """The action in [-1, 1] that moves the hand from pose ``now`` to ``goal`` (relative poses) in one control
    period, or ``None`` if the device cannot.

    Off the workspace's walls the move fixes the action (:func:`hand_action`). An axis that ends on a wall
    was stopped there, so the action may have asked for more along it: the hand's walls clip the world
    x, z, pitch and y velocities, while the action bounds the velocities in the hand's frame (at full
    insert and press the hand moves up to sqrt(2) times the speed along a world axis). Among the
    actions that reach ``goal``, the one that drives hardest into the walls is taken: it reaches them
    soonest, as the full-speed action that usually put the hand there did.
    """
    v = (goal - now) / dt
    action = np.array(hand_action(v[0], v[1], v[2], v[3], now[2], p))
    low, high = box
    side = np.where(goal >= high - 1e-9, 1.0, np.where(goal <= low + 1e-9, -1.0, 0.0))
    wall = side * (side * (goal - now) >= 0.0)                # ends on a wall it moved toward (or sat at)
    if not wall.any():
        return np.clip(action, -1.0, 1.0) if np.abs(action).max() <= 1.0 + tol else None
    for axis, j, speed in ((3, 2, p.max_sweep_speed), (2, 3, p.max_pitch_rate)):   # y <- action[2], pitch <- [3]
        if wall[axis]:
            if wall[axis] * v[axis] > speed * (1.0 + tol):
                return None
            action[j] = wall[axis]
        elif abs(action[j]) > 1.0 + tol:
            return None
    if wall[0] or wall[1]:
        planar = _planar_action(v[:2], wall[:2], now[2], p.max_hand_speed, tol)
        if planar is None:
            return None
        action[:2] = planar
    elif max(abs(action[0]), abs(action[1])) > 1.0 + tol:
        return None
    return np.clip(action, -1.0, 1.0)


def action_toward(env: Any, goal: np.ndarray, tol: float = 1e-3) -> np.ndarray:
    """The action that brings ``env``'s hand from where it is to the relative pose ``goal`` in one
    control period (:func:`action_to`); where the device cannot, the nearest it can (clipped): the hand
    lags, as a hand on the device would. Closed loop: the replay of a log and a pose device's session
    both steer by it, so rounding never accumulates."""
    p = env.device.laryngoscope.params
    now, dt = relative_hand_pose(env), env.world.config["dynamics"]["dt"]
    action = action_to(now, goal, dt, p, relative_box(p), tol=tol)
    if action is None:
        v = (goal - now) / dt
        action = np.clip(hand_action(v[0], v[1], v[2], v[3], now[2], p), -1.0, 1.0)
    return action.astype(np.float32)


def steer(env: Any, poses: np.ndarray) -> Iterator[tuple[np.ndarray, dict[str, Any]]]:
    """Step ``env``'s hand along ``poses`` ``(K + 1, 4)`` (relative; the first where it is), each control
    period toward the next (:func:`action_toward`): yields each action and the step's info."""
    for k in range(len(poses) - 1):
        action = action_toward(env, poses[k + 1])
        yield action, env.step(action)[4]


def pose_after(env: Any, action: np.ndarray) -> np.ndarray:
    """The relative pose (x, z, pitch, y) ``env``'s hand reaches after one control period of ``action``: the
    command in the hand's frame at the period's start (:func:`hand_command`), each axis stopped at its wall.
    A rate device (keys, a stick) steers toward it with :func:`action_toward`, as a log's replay does, so
    its session replays as it was played even where the hand runs into a wall part way through a period."""
    p = env.device.laryngoscope.params
    now = relative_hand_pose(env)
    velocity = np.array(hand_command(np.asarray(action, dtype=np.float64), now[2], p, ScalarOps))
    low, high = relative_box(p)
    return np.clip(now + velocity * env.world.config["dynamics"]["dt"], low, high)


def _planar_action(v: np.ndarray, wall: np.ndarray, pitch: float, speed: float, tol: float) -> np.ndarray | None:
    """Insert and press ``(a0, a1)`` in the square whose world velocity ``speed * M a`` equals ``v`` on the
    free axes and reaches at least ``v`` into the walls on the others, driving hardest into them (a linear
    programme in two variables, solved at the vertices of its feasible polygon)."""
    c, s = math.cos(pitch), math.sin(pitch)
    M = speed * np.array([[-c, s], [-s, -c]])                  # hand_command's world velocity per unit action
    lines = [(np.array([1.0, 0.0]), e) for e in (-1.0, 1.0)] + [(np.array([0.0, 1.0]), e) for e in (-1.0, 1.0)]
    lines += [(M[i], v[i]) for i in range(2)]
    best, best_value = None, -math.inf
    for i in range(len(lines)):
        for j in range(i + 1, len(lines)):
            A = np.array([lines[i][0], lines[j][0]])
            if abs(np.linalg.det(A)) < 1e-12:
                continue
            a = np.linalg.solve(A, [lines[i][1], lines[j][1]])
            w = M @ a
            fits = np.all(np.abs(a) <= 1.0 + tol) and all(
                abs(w[k] - v[k]) <= tol * speed if wall[k] == 0 else wall[k] * (w[k] - v[k]) >= -tol * speed
                for k in range(2))
            value = float(wall @ w)
            if fits and value > best_value:
                best, best_value = a, value
    return best


def speed_limited(pose: np.ndarray, dt: float, config: SceneConfig) -> np.ndarray:
    """The path a hand on the device follows: each step's move scaled down to the speed limits."""
    p = LaryngoscopeParams.from_config(config)
    out = pose.copy()
    for k in range(len(pose) - 1):
        move = pose[k + 1] - out[k]
        v = move / dt
        excess = max(1.0, max(abs(a) for a in hand_action(v[0], v[1], v[2], v[3], out[k, 2], p)) * (1.0 + 1e-9))
        out[k + 1] = out[k] + move / excess
    return out
