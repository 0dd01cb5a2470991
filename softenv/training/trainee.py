"""Synthetic trainees on the laryngoscope: the scripted expert's hand log and graded errors of technique.

:func:`expert_hand_log` runs :class:`softenv.devices.laryngoscope.control.HandController` (insert, lift along the handle,
sweep right) toward the scene's family-centre target and records the hand's pose every control
period, as a haptic device would (the :data:`softenv.training.logs.HAND_LOG` schema). Its lift builds the
tongue's force at :data:`FORCE_RATE`, as a hand does, not at once: a harder airway, which needs more
force, takes the expert longer. :func:`degrade` adds
the errors a trainee makes, each by an amount that grades it (0 = none):

| error | amount | what the hand does |
|---|---|---|
| ``tremor`` | mm | an 8 Hz tremor (physiological tremor is 8-12 Hz) of that amplitude in x and z, half of it sideways, and 0.01 rad per mm of pitch |
| ``hesitation`` | s | three pauses of that length (at 25, 50 and 75 % of the expert's movement), the hand held still |
| ``lever`` | rad | the press done by turning the blade instead of lowering the hand: the handle turned tip-down by that angle beyond the expert's, the hand's descent cut by its share of 0.3 rad (from 0.3 rad on, the hand rises 5 mm instead). From about 0.25 rad the flange bears on the upper incisors, the fulcrum of a lever that presses the tongue (``lever_share`` near 1) |
| ``overshoot`` | mm | the lift pressed that much deeper than the expert's, growing over 30 % of the log from where the expert's lift is done |
| ``direction`` | 0-1 | the sideways path mirrored by that share (1: sweeps left instead of right) |

Every degraded log starts at the start pose and stays in the hand's workspace (clipped to it); where
an error would move the hand faster than the device allows, the hand lags behind (each step's move
scaled down to the speed limit), as a real hand on the device would.
"""

from __future__ import annotations

import math

import numpy as np

from .._validation import check_int, check_real
from ..devices.laryngoscope.control import HandController
from ..sections import SceneConfig
from .hand import hand_config, hand_limits, reach_env, relative_hand_pose, speed_limited
from .logs import HAND_LOG, Schema, check_table

TREMOR_HZ = 8.0
PAUSES = (0.25, 0.5, 0.75)               # where the hesitant trainee stops, as shares of the movement
LEVER_FULL_RAD, LEVER_RISE_M = 0.3, 0.005   # from this lever on, the hand no longer presses down but rises
LIFTED, OVERSHOOT_SPAN = 0.98, 0.3    # the lift is done at this share of its descent; an overshoot grows over this share of the log
FORCE_RATE = 20.0       # N/s: how fast the expert's lift builds the tongue's force (a stated choice, docs/airways.md)
# the largest amount of each error degrade() takes
LIMITS = {"tremor": 5.0, "hesitation": 60.0, "lever": 0.5, "overshoot": 50.0, "direction": 1.0}


def expert_hand_log(config: SceneConfig | None = None, duration_s: float = 5.0,
                    force_rate: float | None = FORCE_RATE) -> np.ndarray:
    """The scripted expert's hand log ``(n, 5)`` (``time_s`` and the relative hand pose) toward the
    centre of the scene's laryngoscopy family (``config``: made by :func:`~softenv.training.hand.haptic_config`;
    None: SoftSphereHaptic-v0's). From the step the blade first rests on the tongue, the force the
    controller tracks rises from the tongue's force at ``force_rate`` (N/s) to the target's, its sideways
    force in proportion (``None``: the target's at once)."""
    check_real(duration_s, "duration_s", 0.1, 600.0)
    if force_rate is not None:
        check_real(force_rate, "force_rate", 1.0, 1e4)
    config = hand_config(config)
    dt = config["dynamics"]["dt"]
    steps = max(1, int(round(duration_s / dt)))
    env = reach_env(config, steps)
    world = env.world
    target = world.family.centre
    controller = HandController(world.config)
    obs, _ = env.reset(seed=0, options={"target": world.force_box.normalised(target)})
    device = slice(2 * world.k, 2 * world.k + world.device_obs_size)
    poses = [relative_hand_pose(env)]
    lift: float | None = None                    # the normal force the lift tracks, once the blade rests on the tongue
    for _ in range(steps):
        force = float(env.device.laryngoscope.tongue_force)
        if lift is None and force > 0.0 and force_rate is not None:
            lift = force
        goal = target
        if lift is not None and force_rate is not None and target[2] > 0.0:
            lift = min(lift + force_rate * dt, float(target[2]))
            goal = np.concatenate([target[:2], target[2:] * (lift / target[2])])
        obs, *_ = env.step(controller.act(obs[None, device], goal[None])[0].astype(np.float32))
        poses.append(relative_hand_pose(env))
    return np.column_stack([np.arange(steps + 1) * dt, np.array(poses)])


def withdrawn(log: np.ndarray, schema: Schema = HAND_LOG, settle_s: float = 0.5) -> np.ndarray:
    """``log`` (of ``schema``), then the same path backward at the same pace, then ``settle_s`` held where
    it started: a trainee who reaches the target and lets it go again (scores about 0)."""
    log = check_table(log, schema, "log")
    check_real(settle_s, "settle_s", 0.0, 60.0)
    back = np.concatenate([log[-2::-1], log[:1]])
    back[:, 0] = 2 * log[-1, 0] - back[:, 0]
    back[-1, 0] = back[-2, 0] + max(settle_s, 1e-3)
    return np.concatenate([log, back])


def degrade(log: np.ndarray, config: SceneConfig | None = None, tremor: float = 0.0, hesitation: float = 0.0,
            lever: float = 0.0, overshoot: float = 0.0, direction: float = 0.0, seed: int = 0) -> np.ndarray:
    """The hand log ``log`` with a trainee's errors (see the module docstring; amounts >= 0)."""
    amounts = {"tremor": tremor, "hesitation": hesitation, "lever": lever, "overshoot": overshoot, "direction": direction}
    for name, value in amounts.items():
        check_real(value, name, 0.0, LIMITS[name])
    check_int(seed, "seed", 0, 2**32 - 1)
    config = hand_config(config)
    log = check_table(log, HAND_LOG, "log").copy()
    t: np.ndarray = log[:, 0] - log[0, 0]                  # the log's own clock does not matter
    pose = log[:, 1:].copy()
    duration = t[-1]
    ramp = lambda a, b: 0.5 - 0.5 * np.cos(np.pi * np.clip((t / duration - a) / (b - a), 0.0, 1.0))  # noqa: E731
    # the expert's lift: its hand goes down (z) until it holds the target's force; an overshoot presses on from
    # there, so the trainee passes the target's shape when the expert reaches it
    descent = pose[:, 1] - pose[0, 1]
    lifted = float(t[np.argmax(descent <= LIFTED * descent.min())] / duration) if descent.min() < 0.0 else 0.0
    pose[:, 3] *= 1.0 - 2.0 * direction
    if lever > 0.0:
        share, pivot = min(1.0, lever / LEVER_FULL_RAD), ramp(0.0, 0.2)
        pose[:, 1] += (share * LEVER_RISE_M * pivot - pose[:, 1]) * share
        pose[:, 2] += lever * pivot
    pose[:, 1] -= overshoot * 1e-3 * ramp(lifted, lifted + OVERSHOOT_SPAN)
    if tremor > 0.0:
        phase = np.random.default_rng(seed).uniform(0.0, 2.0 * math.pi, 4)
        onset = np.clip(t / 0.25, 0.0, 1.0)                           # from rest, over a quarter second
        shake = onset[:, None] * np.sin(2.0 * math.pi * TREMOR_HZ * t[:, None] + phase[None])
        pose += tremor * 1e-3 * shake * np.array([1.0, 1.0, 10.0, 0.5])
    if hesitation > 0.0:
        moving = np.flatnonzero(np.any(np.abs(np.diff(log[:, 1:], axis=0)) > 1e-4, axis=1))   # faster than 5 mm/s
        t, pose = _pause(t, pose, hesitation, (moving[0], moving[-1] + 1) if moving.size else (0, len(t) - 1))
    limits = np.array(list(hand_limits(config).values()))      # (4, 2): the workspace per column
    return np.column_stack([t, speed_limited(np.clip(pose, limits[:, 0], limits[:, 1]), float(t[1] - t[0]), config)])


def _pause(t: np.ndarray, pose: np.ndarray, pause: float, movement: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Hold the hand still for ``pause`` seconds at each of :data:`PAUSES` of the rows ``movement``
    (first, last) where the expert moves (the log grows longer)."""
    dt = float(t[1] - t[0])
    first, last = movement
    stops = sorted(int(round(first + share * (last - first))) for share in PAUSES)
    held = int(round(pause / dt))
    rows = np.concatenate([np.arange(len(t))] + [np.full(held, s) for s in stops])
    rows = np.sort(rows, kind="stable")
    return np.arange(len(rows)) * dt, pose[rows]


# the largest amount of each error (skill level 4 of 4); each trainee draws 0.5-1.5 times its level's share
WORST = {"tremor": 0.8, "hesitation": 0.4, "lever": 0.3, "overshoot": 6.0}
# the score part each error lowers (softenv.training.scoring.HAND_WEIGHTS)
LOWERS = {"tremor": "smoothness", "hesitation": "speed", "lever": "teeth", "overshoot": "safety", "direction": "accuracy"}


def skill_population(expert_log: np.ndarray, levels: int = 5, per_level: int = 20, seed: int = 0,
                     config: SceneConfig | None = None) -> list[tuple[int, dict[str, float], np.ndarray]]:
    """Trainees at graded skill: error level ``L`` of ``0 .. levels - 1`` (skill ``levels - 1 - L``) degrades the expert's log by every
    error of :data:`WORST` at ``L / (levels - 1)`` of its worst amount, times a factor drawn from
    [0.5, 1.5] per trainee and error (level 0 is the expert). Returns ``(level, amounts, log)``."""
    rng = np.random.default_rng(seed)
    config = hand_config(config)
    out = []
    for level in range(levels):
        for _ in range(per_level):
            share = level / max(levels - 1, 1)
            amounts = {name: float(share * worst * rng.uniform(0.5, 1.5)) for name, worst in WORST.items()}
            out.append((level, amounts, degrade(expert_log, config, seed=int(rng.integers(1 << 31)), **amounts)))
    return out


def spearman(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman's rank correlation (ties get their average rank)."""
    def ranks(v: np.ndarray) -> np.ndarray:
        v = np.asarray(v, dtype=np.float64)
        order = np.argsort(v, kind="stable")
        r = np.empty(len(v))
        r[order] = np.arange(len(v), dtype=np.float64)
        for value in np.unique(v):                      # average rank over ties
            tied = v == value
            r[tied] = r[tied].mean()
        return r
    return float(np.corrcoef(ranks(x), ranks(y))[0, 1])
