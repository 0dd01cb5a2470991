"""The evaluation protocol: test targets only, many episodes at once on the batched twin, per-episode
metrics, and rliable-style summaries (mean with a 95 % bootstrap interval, interquartile mean)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from softenv.airway import GRADES
from softenv.envs import ENV_SCENES, HAPTIC_SCENES
from softenv.stats import bootstrap_ci, iqm, nested_interval

# The protocol: test targets only, episode i seeded FIRST_SEED + i, EPISODES of them. Bump the version when
# anything a score depends on changes (the seeds, the error sum, the split): shipped anchors and leaderboard
# results name it, and one made under another version is refused.
PROTOCOL_VERSION = 1
FIRST_SEED = 1000
EPISODES = 100
SPLIT = "test"
TRAIN_SPLIT = "train"          # the targets agents train on, and offline datasets record

METRICS = ("final_error_mm", "success", "normalized_score", "steps_to_success", "peak_force_N")
# the laryngoscope scenes' clinical metrics (softenv.devices.laryngoscope.clinical), from info["clinical"] at each episode's end
CLINICAL = ("peak_tongue_force_N", "mean_tongue_force_N", "tongue_force_time_Ns", "peak_incisor_force_N",
            "peak_jaw_force_N", "incisor_contact_s", "lever_share", "duration_s", "hand_path_m", "sparc", "ldlj", "glottic_view_pct")

# benchmark scenes: name -> (env id, scene overrides); nonlinear variants where the law matters, and the
# default scene on the finite-element tongue (its shipped data)
SCENES: dict[str, tuple[str, dict[str, Any]]] = {
    "SoftSphere-v0": ("SoftSphere-v0", {}),
    "SoftSphere-v0/stiffening": ("SoftSphere-v0", {"tissue": {"law": "stiffening"}}),
    "SoftSphereViscoelastic-v0": ("SoftSphereViscoelastic-v0", {}),
    "SoftSphereViscoelastic-v0/stiffening": ("SoftSphereViscoelastic-v0", {"tissue": {"law": "stiffening"}}),
    "SoftSphereProcedure-v0": ("SoftSphereProcedure-v0", {}),
    "SoftSphereProcedure-v0/stiffening": ("SoftSphereProcedure-v0", {"tissue": {"law": "stiffening"}}),
    "SoftSphereHaptic-v0": ("SoftSphereHaptic-v0", {}),
    "SoftSphereHapticProcedure-v0": ("SoftSphereHapticProcedure-v0", {}),
    "SoftSphere-v0/fem": ("SoftSphere-v0", {"tissue": {"model": "fem"}}),     # the finite-element tongue
}
# the difficult airways (softenv.airway): SoftSphereAirway-v0 at each grade, one device range for all
GRADED_SCENES = {grade: f"SoftSphereAirway-v0/grade{grade}" for grade in GRADES}
SCENES.update({scene: ("SoftSphereAirway-v0", {"airway": {"grade": grade}}) for grade, scene in GRADED_SCENES.items()})


def episode_seeds(episodes: int = EPISODES) -> list[int]:
    """The seeds of the protocol's first ``episodes`` test episodes."""
    return [FIRST_SEED + i for i in range(episodes)]


def scene_kwargs(scene: str, obs_mode: str = "vector", split: str = SPLIT,
                 make: dict[str, Any] | None = None) -> tuple[str, dict[str, Any]]:
    """Env id and ``gym.make`` kwargs of a benchmark scene on its test targets (or ``split``'s), with
    ``make``'s sections merged in key by key (``{"task": {"split": "train"}}``)."""
    if scene not in SCENES:
        raise ValueError(f"unknown scene {scene!r}; valid scenes: {list(SCENES)}")
    env_id, overrides = SCENES[scene]
    kwargs = {**{**ENV_SCENES, **HAPTIC_SCENES}[env_id], **overrides}
    kwargs["task"] = {**kwargs.get("task", {}), "split": split}
    for section, values in (make or {}).items():
        kwargs[section] = {**kwargs.get(section, {}), **values}
    return env_id, {**kwargs, "obs_mode": obs_mode}


def device_kind(scene: str) -> str:
    """``"laryngoscope"`` for the SoftSphereHaptic scenes, ``"ideal"`` otherwise."""
    return "laryngoscope" if scene_kwargs(scene)[0] in HAPTIC_SCENES else "ideal"


def normalized_scores(error_sum: np.ndarray, zero: np.ndarray, oracle: np.ndarray) -> np.ndarray:
    """The benchmark's normalized score per episode: ``100 (E_zero - E) / (E_zero - E_oracle)`` with ``E``
    the episode's summed shape error on the same target (0 = no force, 100 = the planning oracle)."""
    return 100.0 * (zero - error_sum) / np.maximum(zero - oracle, 1e-12)


@dataclass
class Episodes:
    """Per-episode metrics of one policy on one scene: ``runs`` training seeds' episodes one after the
    other (each the same number), or one run."""

    policy: str
    scene: str
    values: dict[str, np.ndarray]
    decision_us: float
    runs: int = 1

    def summary(self, seed: int = 0) -> dict[str, Any]:
        """Each metric's mean with its 95 % interval and its IQM: over the runs (training seeds), then the
        episodes within each drawn run (:func:`softenv.stats.nested_interval`), so seeds that learned apart
        widen it; a metric some episodes lack (steps to success) over the episodes that have it."""
        out: dict[str, Any] = {"policy": self.policy, "scene": self.scene, "episodes": len(self.values["success"]),
                               "decision_us": self.decision_us, "runs": self.runs}
        for name in (*METRICS, *(c for c in CLINICAL if c in self.values)):
            v = self.values[name].astype(np.float64)
            finite = v[np.isfinite(v)]
            if finite.size == v.size and v.size:
                by_run = v.reshape(self.runs, -1)
                mean, lo, hi = nested_interval(by_run, seed=seed)
            else:
                mean, lo, hi = bootstrap_ci(finite, seed=seed)
            out[name] = {"mean": mean, "ci_low": lo, "ci_high": hi, "iqm": iqm(finite), "n": int(finite.size)}
        return out


def evaluate(policy: Any, scene: str, episodes: int = EPISODES, seed: int | list[int] = FIRST_SEED,
             vectorization_mode: str = "vector_entry_point", **make: Any) -> Episodes:
    """Run ``episodes`` test episodes of ``policy`` at once (one per env of the batched twin, or with
    ``vectorization_mode="sync"`` of as many single envs), env ``i`` seeded ``seed + i`` (or ``seed[i]``);
    ``make`` overrides scene sections (``device={"batch_engine": ...}``). A policy that plans offline
    reports its own ``decision_us``."""
    obs_mode = getattr(policy, "obs_mode", "vector")
    env_id, kwargs = scene_kwargs(scene, obs_mode, make=make)
    if vectorization_mode == "sync":
        venv = gym.make_vec(env_id, num_envs=episodes, vectorization_mode="sync",
                            vector_kwargs={"autoreset_mode": gym.vector.AutoresetMode.SAME_STEP}, **kwargs)
    else:
        venv = gym.make_vec(env_id, num_envs=episodes, vectorization_mode=vectorization_mode,
                            autoreset_mode=gym.vector.AutoresetMode.SAME_STEP, **kwargs)
    policy.reset()
    obs, _ = venv.reset(seed=seed)  # type: ignore[arg-type]  # SoftSphere's vector env takes a seed per env
    done = np.zeros(episodes, dtype=bool)
    first_success = np.full(episodes, np.nan)
    error_sum = np.zeros(episodes)                 # the episode's summed RMS shape error (mm x steps)
    returns = np.zeros(episodes)                   # the episode's summed reward
    final: dict[str, np.ndarray] = {}
    step = 0
    while not done.all():
        obs, reward, terminated, truncated, info = venv.step(policy.predict(obs))
        step += 1
        running = ~done
        success_now = np.where(info.get("_is_success", np.zeros(episodes, bool)), info.get("is_success", False), False)
        ended = (terminated | truncated) & running
        # this step's error: from final_info where an episode ended (info then holds the reset)
        now = info.get("shape_error_mm", np.zeros(episodes))
        if ended.any():
            fi = info["final_info"]
            now = np.where(ended, fi["shape_error_mm"], now)
            success_now = np.where(ended, fi["is_success"], success_now)
            for key in ("shape_error_mm", "is_success", "normalized_score", "peak_force_N"):
                final.setdefault(key, np.zeros(episodes, dtype=fi[key].dtype))[ended] = fi[key][ended]
            for key in CLINICAL if "clinical" in fi else ():
                final.setdefault(key, np.full(episodes, np.nan))[ended] = fi["clinical"][key][ended]
        error_sum += np.where(running, now, 0.0)
        returns += np.where(running, reward, 0.0)
        first_success = np.where(running & success_now & np.isnan(first_success), step, first_success)
        done |= ended
    values = {"final_error_mm": final["shape_error_mm"], "success": final["is_success"].astype(np.float64),
              "normalized_score": final["normalized_score"], "steps_to_success": first_success,
              "peak_force_N": final["peak_force_N"], "error_sum_mm": error_sum, "return": returns, **{key: final[key] for key in CLINICAL if key in final}}
    decision_us = getattr(policy, "decision_us", None)
    return Episodes(getattr(policy, "name", str(policy)), scene, values,
                    decision_us if decision_us is not None else decision_latency_us(policy, obs))


def decision_latency_us(policy: Any, obs: np.ndarray, calls: int = 200) -> float:
    """Median time of one decision on one observation row (the haptic-loop latency)."""
    n = len(obs) if isinstance(obs, np.ndarray) else len(obs["observation"])
    samples = np.empty(calls)
    for i in range(calls):
        row = obs[i % n] if isinstance(obs, np.ndarray) else {key: v[i % n] for key, v in obs.items()}
        t0 = time.perf_counter()
        policy.predict(row)
        samples[i] = time.perf_counter() - t0
    return float(np.median(samples) * 1e6)
