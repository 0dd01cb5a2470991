"""Trainee profiles built to match published clinical measurements, to check the score against them.

Manikin and patient studies measure experienced and novice laryngoscopists; the scene can express
some of their measures as ratios of a group's to the experts' (its procedure is a 5 s reach, not a
whole intubation, so absolute times and paths do not carry over):

| study | groups | measure | values | in the scene |
|---|---|---|---|---|
| Bishop et al. 1992 | experienced, novice | peak force; mean force; time | 43 vs 55 N; 22 vs 29 N; 19 vs 40 s | mean tongue force and time to target, as ratios (peak force follows) |
| Bucx et al. 1992 | anaesthetists | peak force; mean force | 35 +- 12 N; 20 +- 6 N | the expert's own peak and mean tongue force, in newtons |
| Carlson et al. 2012 | expert, intermediate, novice | time | 5.5, 6.3, 12.4 s | time to target, as a ratio |
| Kerrey et al. 2020 | experienced, novice | laryngoscope path | 78 vs 114 cm | the hand's path, as a ratio |

A profile degrades the scripted expert's hand log (:func:`softenv.training.trainee.degrade`) by
hesitation until its time to target is the published ratio of the experts', then by overshoot (a
deeper press) until its mean tongue force is, then by tremor until its hand path is: each amount found
by bisection, since each measure grows with its error. The profiles' scores must then rank in the
published order. Not expressed: the force on the incisors (the studies measure it on the maxillary
teeth of manikins with other instruments), and success rates.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..sections import SceneConfig
from .hand import hand_config
from .scoring import Replay, replay_hand
from .trainee import degrade

# (profile, study, the group's measure over the experts': time, mean force, path); 1 = as the experts
PROFILES = [
    ("expert", "the scripted expert", 1.0, 1.0, 1.0),
    ("intermediate", "Carlson et al. 2012: time 6.3 / 5.5 s", 6.3 / 5.5, 1.0, 1.0),
    ("novice (time)", "Carlson et al. 2012: time 12.4 / 5.5 s", 12.4 / 5.5, 1.0, 1.0),
    ("novice (force)", "Bishop et al. 1992: mean force 29 / 22 N alone", 1.0, 29.0 / 22.0, 1.0),
    ("novice", "Bishop et al. 1992: time 40 / 19 s, mean force 29 / 22 N; Kerrey et al. 2020: path 114 / 78 cm",
     40.0 / 19.0, 29.0 / 22.0, 114.0 / 78.0),
]
BUCX_1992 = {"peak_N": (35.0, 12.0), "mean_N": (20.0, 6.0)}      # mean, SD over anaesthetists
BISHOP_1992 = {"experienced": {"peak_N": 43.0, "mean_N": 22.0, "time_s": 19.0},
               "novice": {"peak_N": 55.0, "mean_N": 29.0, "time_s": 40.0}}


def time_to_target(r: Replay) -> float:
    return r.time_to_target_s if r.time_to_target_s is not None else float(r.time_s[-1])


def mean_force(r: Replay) -> float:
    return r.clinical["mean_tongue_force_N"]


def hand_path(r: Replay) -> float:
    return r.clinical["hand_path_m"]


# the error that grows each measure, its search range, and the measure
KNOBS: list[tuple[str, float, Callable[[Replay], float]]] = [
    ("hesitation", 10.0, time_to_target), ("overshoot", 50.0, mean_force), ("tremor", 5.0, hand_path)]


@dataclass
class Profile:
    """A profile's log, the amounts of error it took, and the ratios it reached (against the asked)."""

    name: str
    study: str
    amounts: dict[str, float]
    asked: tuple[float, float, float]
    reached: tuple[float, float, float]
    log: np.ndarray
    peak_N: float                                  # its peak tongue force


def build(name: str, study: str, ratios: tuple[float, float, float], expert_log: np.ndarray, expert: Replay,
          config: SceneConfig | None = None, iterations: int = 14) -> Profile:
    """The profile whose time to target, mean tongue force and hand path are ``ratios`` times the expert's."""
    config = hand_config(config)
    amounts: dict[str, float] = {}

    def measure(amount: float, knob: str, of: Callable[[Replay], float]) -> float:
        return of(replay_hand(_degraded(expert_log, config, {**amounts, knob: amount}), config)) / of(expert)

    for (knob, high, of), ratio in zip(KNOBS, ratios):
        if ratio <= 1.0:
            continue
        low = 0.0
        for _ in range(iterations):                # the measure grows with its error: bisect for the ratio
            middle = 0.5 * (low + high)
            low, high = (middle, high) if measure(middle, knob, of) < ratio else (low, middle)
        amounts[knob] = 0.5 * (low + high)
    log = _degraded(expert_log, config, amounts)
    r = replay_hand(log, config)
    reached = (time_to_target(r) / time_to_target(expert), mean_force(r) / mean_force(expert),
               hand_path(r) / hand_path(expert))
    return Profile(name, study, amounts, ratios, reached, log, r.peak_force_N)


def _degraded(expert_log: np.ndarray, config: SceneConfig, amounts: dict[str, float]) -> np.ndarray:
    return degrade(expert_log, config, hesitation=amounts.get("hesitation", 0.0), overshoot=amounts.get("overshoot", 0.0),
                   tremor=amounts.get("tremor", 0.0))
