"""Pass marks by the contrasting-groups method: the score where the expert group's and the novice
group's score distributions cross.

The method (Livingston & Zieky 1982; its use in simulation-based assessment: Jørgensen, Konge &
Subhi 2018, *Advances in Simulation* 3:5) fits a normal distribution to each group's scores and puts
the mark where the two densities are equal, between the group means: below it a score is more
likely a novice's, above it an expert's. Its consequences are the false-pass rate (novices at or
above the mark) and the false-fail rate (experts below it), reported as counted in the groups.

The groups here are synthetic trainees of the published profiles (:mod:`softenv.training.profiles`):
the **expert** profile (the scripted expert) and the **novice** profile (Bishop et al. 1992's time and
force ratios, Kerrey et al. 2020's path). A profile is one set of error amounts; a group's members
vary around it, as people of one level do (a stated choice, as no study reports the spread of these
errors): each member draws each of its profile's amounts times a factor in [0.5, 1.5] and, on top,
a physiological tremor of 0-0.2 mm and hesitations of 0-0.1 s that even experts show (each amount at
most what :func:`softenv.training.trainee.degrade` takes).
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from .._validation import check_int
from ..training import profiles, scoring
from ..training.hand import haptic_config
from ..training.scoring import replay_hand, score_hand_log
from ..training.trainee import LIMITS, degrade, expert_hand_log

METHOD = "contrasting groups"
GROUPS = ("expert", "novice")
BASELINE = {"tremor": 0.2, "hesitation": 0.1}         # the most of each error a member of any group shows


@dataclass(frozen=True)
class PassMark:
    """A scene's pass mark and its evidence: each group's scores, and the false pass and fail rates."""

    scene: str
    mark: float
    method: str
    formula_version: int
    groups: dict[str, list[float]] = field(default_factory=dict)

    @property
    def false_pass(self) -> float:
        """The share of the novice group at or above the mark."""
        novice = np.asarray(self.groups.get("novice", []))
        return float(np.mean(novice >= self.mark)) if novice.size else math.nan

    @property
    def false_fail(self) -> float:
        """The share of the expert group below the mark."""
        expert = np.asarray(self.groups.get("expert", []))
        return float(np.mean(expert < self.mark)) if expert.size else math.nan

    def evidence(self) -> dict[str, Any]:
        return {"groups": self.groups}

    @classmethod
    def from_evidence(cls, scene: str, mark: float, method: str, formula_version: int,
                      evidence: dict[str, Any]) -> PassMark:
        return cls(scene, mark, method, formula_version, {k: list(v) for k, v in evidence.get("groups", {}).items()})


def crossing(expert: np.ndarray, novice: np.ndarray) -> float:
    """Where the normal densities fitted to the two groups' scores are equal, between their means
    (the midpoint of the means when both spreads are equal)."""
    expert, novice = np.asarray(expert, dtype=np.float64), np.asarray(novice, dtype=np.float64)
    for name, group in (("expert", expert), ("novice", novice)):
        if group.ndim != 1 or group.size < 2 or not np.all(np.isfinite(group)):
            raise ValueError(f"the {name} group needs at least 2 finite scores, got {group.tolist()!r}")
    m1, s1 = float(expert.mean()), float(expert.std(ddof=1))
    m2, s2 = float(novice.mean()), float(novice.std(ddof=1))
    if m1 <= m2:
        raise ValueError(f"the expert group's mean score ({m1:.2f}) is not above the novice group's ({m2:.2f}): "
                         "the groups do not contrast, so no mark separates them")
    s1, s2 = max(s1, 1e-9), max(s2, 1e-9)
    # log N(x; m1, s1) = log N(x; m2, s2)  <=>  a x^2 + b x + c = 0
    a = 1.0 / s2**2 - 1.0 / s1**2
    b = 2.0 * (m1 / s1**2 - m2 / s2**2)
    c = m2**2 / s2**2 - m1**2 / s1**2 + 2.0 * math.log(s2 / s1)
    if abs(a) < 1e-12:
        return -c / b
    roots = np.roots([a, b, c])
    real = [float(r.real) for r in roots if abs(r.imag) < 1e-9]
    between = [r for r in real if m2 <= r <= m1]
    return between[0] if between else 0.5 * (m1 + m2)


def group_amounts(profile: dict[str, float], n: int, seed: int) -> list[tuple[dict[str, float], int]]:
    """``n`` members' error amounts around ``profile`` (see the module docstring) and their tremor seeds."""
    rng = np.random.default_rng(seed)
    members = []
    for _ in range(n):
        amounts = with_baseline({k: float(v * rng.uniform(0.5, 1.5)) for k, v in profile.items()}, rng)
        members.append((amounts, int(rng.integers(1 << 31))))
    return members


def with_baseline(amounts: dict[str, float], rng: np.random.Generator) -> dict[str, float]:
    """``amounts`` plus the :data:`BASELINE` tremor and hesitation anyone shows, each at most what
    :func:`softenv.training.trainee.degrade` takes."""
    out = dict(amounts)
    for k, most in BASELINE.items():
        out[k] = out.get(k, 0.0) + float(rng.uniform(0.0, most))
    return {k: float(min(v, LIMITS[k])) for k, v in out.items()}


def profile_amounts(name: str, scene: dict[str, Any] | None = None) -> dict[str, float]:
    """The error amounts of the published profile ``name`` (:data:`softenv.training.profiles.PROFILES`) on
    ``scene`` (found once a process: a few seconds of bisection)."""
    rows = {row[0]: row for row in profiles.PROFILES}
    if name not in rows:
        raise ValueError(f"profile {name!r} is not one of {list(rows)}")
    return dict(_profile_amounts(name, json.dumps(scene or {}, sort_keys=True)))


@functools.lru_cache(maxsize=32)
def _profile_amounts(name: str, scene_json: str) -> tuple[tuple[str, float], ...]:
    _, study, *ratios = next(row for row in profiles.PROFILES if row[0] == name)
    if all(r == 1.0 for r in ratios):
        return ()
    config = haptic_config(json.loads(scene_json))
    log = expert_hand_log(config)
    built = profiles.build(name, study, (ratios[0], ratios[1], ratios[2]), log, replay_hand(log, config), config)
    return tuple(built.amounts.items())


def contrasting_groups(scene_key: str, scene: dict[str, Any] | None = None, per_group: int = 20, seed: int = 0,
                       progress: Callable[[int, int], None] | None = None) -> PassMark:
    """The pass mark on a hand-pose scene (``scene``'s sections; ``scene_key`` how the store names it)
    from ``per_group`` synthetic members of the expert and of the novice profile."""
    check_int(per_group, "per_group", 2, 1000)
    config = haptic_config(scene)                    # the scene, made once for every member's replay
    log = expert_hand_log(config)
    expert = replay_hand(log, config, "the expert's log")
    groups: dict[str, list[float]] = {}
    total, done = len(GROUPS) * per_group, 0
    for g, group in enumerate(GROUPS):
        profile = profile_amounts(group, scene)
        groups[group] = []
        for amounts, tremor_seed in group_amounts(profile, per_group, seed + g):
            member = degrade(log, config, seed=tremor_seed, **amounts)
            groups[group].append(score_hand_log(member, config, f"a {group}-profile member", expert)[0]["score"])
            done += 1
            if progress is not None:
                progress(done, total)
    return PassMark(scene_key, crossing(np.array(groups["expert"]), np.array(groups["novice"])), METHOD,
                    scoring.SCORE_VERSION, groups)
