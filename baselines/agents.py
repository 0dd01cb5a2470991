"""SB3 agents on SoftSphere: hyper-parameters from rl-zoo-style YAML, training on the batched twin
with CSV/TensorBoard logs and evaluation on the test targets; a run directory holds a finished run or
nothing; saved agents carry their scene, observation layout and model digest, checked on load.

A finished run is reused only when it was trained on the same simulator: its ``agent.json`` records
the libraries that train it and a digest of what its envs return to seeded random actions
(:func:`dynamics_digest`), so a run directory can be kept across sessions and code changes, and an
agent is trained again exactly when a change reaches what it learns from."""

from __future__ import annotations

import ast
import hashlib
import json
import os
import shutil
import time
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np

from softenv.envs.config import config_key, make_config

from .evaluate import scene_kwargs
from .fingerprint import PROBE_ENVS, library_versions, probe_steps, rollout_digest
from .policies import SB3Policy

HYPERPARAMS = files(__package__ or "softenv.baselines") / "hyperparams"     # package data
# name -> (SB3 class name, YAML file); the observation mode and any scene settings come from the
# YAML's env_kwargs, as rl-zoo3 reads them
ALGOS: dict[str, tuple[str, str]] = {
    "ppo": ("PPO", "ppo.yml"),
    "sac": ("SAC", "sac.yml"),
    "td3": ("TD3", "td3.yml"),
    "sac-her": ("SAC", "her.yml"),
}
AGENT_FORMAT_VERSION = 4        # 4: the hyper-parameters; 3: the dynamics' digest and the libraries' versions;
                                # 2: the model's digest


def _literal_dict(text: str) -> dict[str, Any]:
    """Parse rl-zoo's ``"dict(a=1, b=[2, 3])"`` strings without eval: literals only."""
    node = ast.parse(text, mode="eval").body
    if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "dict" and not node.args):
        raise ValueError(f"expected dict(key=literal, ...), got {text!r}")
    return {str(kw.arg): ast.literal_eval(kw.value) for kw in node.keywords}


def hyperparams(algo: str, env_id: str) -> dict[str, Any]:
    """The YAML hyper-parameters of ``algo`` on ``env_id`` (a fresh dict)."""
    import yaml                                             # the rl extra

    if algo not in ALGOS:
        raise ValueError(f"unknown agent {algo!r}; valid agents: {list(ALGOS)}")
    table = yaml.safe_load((HYPERPARAMS / ALGOS[algo][1]).read_text())
    if env_id not in table:
        raise ValueError(f"{ALGOS[algo][1]} has no entry for {env_id!r}; entries: {list(table)}")
    params = dict(table[env_id])
    for key in ("policy_kwargs", "replay_buffer_kwargs"):
        if isinstance(params.get(key), str):
            params[key] = _literal_dict(params[key])
    return params


def agent_env_kwargs(algo: str, scene: str, split: str = "test") -> tuple[str, dict[str, Any]]:
    """Env id and ``gym.make`` kwargs of ``algo`` on ``scene``: the scene's, then the YAML's
    ``env_kwargs`` (``obs_mode``, scene sections merged key by key), on the ``split`` targets."""
    env_id, kwargs = scene_kwargs(scene)
    for key, value in hyperparams(algo, env_id).get("env_kwargs", {}).items():
        kwargs[key] = {**kwargs.get(key, {}), **value} if isinstance(value, dict) else value
    kwargs["task"] = {**kwargs.get("task", {}), "split": split}
    return env_id, kwargs


def _layout(algo: str, scene: str) -> dict[str, Any]:
    sections = agent_env_kwargs(algo, scene)[1]
    obs_mode = sections.pop("obs_mode")
    config = make_config(**sections)
    return {"scene": scene, "obs_mode": obs_mode,
            "scene_key": config_key(config, ("tissue", "mesh", "shape_model", "response", "device", "dynamics", "task"))}


def make_training_env(algo: str, scene: str, n_envs: int, split: str = "train") -> Any:
    from stable_baselines3.common.vec_env import VecMonitor  # the rl extra

    from softenv.envs.sb3 import SoftSphereSB3VecEnv        # stable-baselines3: the rl extra

    env_id, kwargs = agent_env_kwargs(algo, scene, split)
    # the adapter's default infos: is_success, all SB3 reads (the other terms would cost a dict entry each)
    return VecMonitor(SoftSphereSB3VecEnv(n_envs, env_id, **kwargs))


def dynamics_digest(algo: str, scene: str) -> str:
    """:func:`~baselines.fingerprint.rollout_digest` of ``algo``'s training envs on ``scene`` (the SB3 adapter,
    float32, as training sees them). A change no random step reaches must bump :data:`AGENT_FORMAT_VERSION`."""
    return rollout_digest(lambda split: make_training_env(algo, scene, PROBE_ENVS, split),
                          probe_steps(agent_env_kwargs(algo, scene)[1]))


def training_fingerprint(algo: str, scene: str) -> dict[str, Any]:
    """What a trained agent depends on beyond its settings: the training libraries' versions and
    :func:`dynamics_digest`. A finished run is reused, and a tuning study resumed, only when it matches."""
    return {"libraries": library_versions(), "dynamics": dynamics_digest(algo, scene)}


def recorded_train_seconds(run_dir: Path) -> float | None:
    """The wall time in seconds a finished run's training took (with its evaluations), as its ``agent.json``
    recorded it; None for a run trained before agents recorded it."""
    seconds = json.loads((run_dir / "agent.json").read_text()).get("train_seconds")
    return None if seconds is None else float(seconds)


def train_agent(algo: str, scene: str, seed: int, out_dir: str | Path, timesteps: int | None = None,
                progress: bool = True, eval_episodes: int = 20, reuse: bool = True,
                overrides: dict[str, Any] | None = None) -> Path:
    """Train one agent from its seed into ``out_dir``; returns the path of its model (``model.zip``).
    ``overrides`` replace YAML hyper-parameters (a tuner's trial: ``{"gamma": 0.99}``); they are part of
    the run's settings, so a run made with others is not reused.

    The run is written into ``<out_dir>.partial`` and renamed to ``out_dir`` once whole, so ``out_dir``
    holds a finished run or nothing. With ``reuse``, a finished run of the same agent, seed, budget and
    scene is loaded, not trained again; anything else there (a run of other settings, a damaged
    model) is replaced. A run that was stopped starts again from its seed: training from the seed is
    bit for bit reproducible, a restart from a checkpoint would not be (SB3's checkpoints keep neither
    the envs' states nor the random streams), and a job loses at most its own minutes."""
    import stable_baselines3 as sb3                         # the rl extra
    from stable_baselines3.common.callbacks import EvalCallback  # the rl extra
    from stable_baselines3.common.logger import configure   # the rl extra

    env_id = scene_kwargs(scene)[0]
    params = hyperparams(algo, env_id)
    unknown = sorted(set(overrides or {}) - set(params) - {"n_envs"})
    if unknown:
        raise ValueError(f"overrides {unknown} are not hyper-parameters of {algo} on {env_id}; "
                         f"those it has: {sorted(params)}")
    params.update(overrides or {})
    # every hyper-parameter it trains with, as JSON reads it back: a YAML changed under a kept run retrains it
    resolved = json.loads(json.dumps(params, sort_keys=True))
    n_envs = int(params.pop("n_envs", 1))
    budget = int(timesteps if timesteps is not None else params.pop("n_timesteps"))
    params.pop("n_timesteps", None)
    params.pop("env_kwargs", None)               # for the env (make_training_env), not the algorithm
    out = Path(out_dir)
    wanted = {"format_version": AGENT_FORMAT_VERSION, "algo": algo, "seed": seed, "timesteps": budget,
              "overrides": dict(overrides or {}), "hyperparams": resolved, **_layout(algo, scene),
              **training_fingerprint(algo, scene)}
    if reuse and finished_run(out, wanted) is None:
        return out / "model.zip"
    partial = out.with_name(out.name + ".partial")
    shutil.rmtree(partial, ignore_errors=True)   # what a stopped run left
    partial.mkdir(parents=True)
    env = make_training_env(algo, scene, n_envs)
    cls = getattr(sb3, ALGOS[algo][0])
    if params.get("replay_buffer_class") == "HerReplayBuffer":
        from stable_baselines3 import HerReplayBuffer       # the rl extra

        params["replay_buffer_class"] = HerReplayBuffer
    noise_type, noise_std = params.pop("noise_type", None), params.pop("noise_std", 0.1)
    if noise_type == "normal":
        from stable_baselines3.common.noise import NormalActionNoise  # the rl extra

        params["action_noise"] = NormalActionNoise(np.zeros(4), noise_std * np.ones(4))
    model = cls(params.pop("policy"), env, seed=seed, device="cpu", verbose=0, **params)
    formats = ["csv"]
    try:
        import tensorboard  # noqa: F401

        formats.append("tensorboard")
    except ImportError:
        pass
    model.set_logger(configure(str(partial / "logs"), formats))
    eval_env = make_training_env(algo, scene, min(eval_episodes, 10), split="test")
    eval_env.seed(seed)                          # else its first reset draws from entropy: the curve would not repeat
    # ten evaluations over the steps learn() takes: an on-policy algorithm collects whole rollouts (n_steps an env)
    taken = max(budget, int(params.get("n_steps", 0)) * n_envs)
    callback = EvalCallback(eval_env, n_eval_episodes=eval_episodes, eval_freq=max(taken // (10 * n_envs), 1),
                            log_path=str(partial / "eval"), best_model_save_path=str(partial / "best"), verbose=0)
    began = time.perf_counter()
    try:
        model.learn(budget, callback=callback, progress_bar=progress and _has_progress_bar())
    finally:                                     # the logger's files too: an open progress.csv outlived its run
        model.logger.close()
        env.close()
        eval_env.close()
    model.save(partial / "model.zip")
    # the training's wall time (with its evaluations) is a record, not a setting: reuse does not compare it
    meta = {**wanted, "model_sha256": _sha256(partial / "model.zip"), "train_seconds": time.perf_counter() - began}
    (partial / "agent.json").write_text(json.dumps(meta, indent=2))
    if out.exists():
        shutil.rmtree(out)                       # a run of other settings, or one not reused
    os.replace(partial, out)                     # the whole run appears at once
    return out / "model.zip"


def finished_run(out: Path, wanted: dict[str, Any]) -> str | None:
    """``None`` when ``out`` holds a finished run with the settings ``wanted``; else why not."""
    meta_path, model = out / "agent.json", out / "model.zip"
    if not (meta_path.is_file() and model.is_file()):
        return "no finished run"
    try:
        meta = json.loads(meta_path.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        return f"agent.json is unreadable ({exc})"
    if not isinstance(meta, dict):
        return "agent.json is not a JSON object"
    meta.setdefault("overrides", {})             # written before overrides existed: the YAML's settings
    other = {k: (meta.get(k), v) for k, v in wanted.items() if meta.get(k) != v}
    if other:
        return "made with other settings: " + ", ".join(f"{k}={a!r} (wanted {b!r})" for k, (a, b) in other.items())
    if meta.get("model_sha256") != _sha256(model):
        return "model.zip does not match the digest in agent.json (damaged or replaced)"
    return None


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def load_agent(path: str | Path, scene: str) -> SB3Policy:
    """Load an agent saved by :func:`train_agent` for ``scene``; another scene or layout, or a model
    that is not the one its ``agent.json`` names, is an error."""
    import stable_baselines3 as sb3                         # the rl extra

    path = Path(path)
    meta_path = path.parent / "agent.json"
    if not meta_path.exists():
        raise ValueError(f"{str(path)!r} has no agent.json beside it (format and scene unknown)")
    meta = json.loads(meta_path.read_text())
    if meta.get("format_version") != AGENT_FORMAT_VERSION:
        raise ValueError(f"{str(meta_path)!r}: format_version={meta.get('format_version')!r}; "
                         f"this softenv reads {AGENT_FORMAT_VERSION} (train the agent again)")
    algo = meta.get("algo")
    if algo not in ALGOS:
        raise ValueError(f"{str(meta_path)!r}: unknown agent {algo!r}; valid agents: {list(ALGOS)}")
    wanted = _layout(algo, scene)
    for key in ("scene_key", "obs_mode"):
        if meta.get(key) != wanted[key]:
            raise ValueError(f"agent {str(path)!r} was trained for scene {meta.get('scene')!r} "
                             f"({key}={meta.get(key)!r}); asked for scene {scene!r} ({key}={wanted[key]!r})")
    if meta.get("model_sha256") != _sha256(path):
        raise ValueError(f"{str(path)!r} does not match model_sha256 in {str(meta_path)!r}: the model is damaged "
                         "or not the one trained with it")
    # HER's replay buffer needs an env to rebuild itself, even for inference
    env = make_training_env(algo, scene, 1, split="test") if algo == "sac-her" else None
    model = getattr(sb3, ALGOS[algo][0]).load(path, env=env, device="cpu")
    policy = SB3Policy(model, algo)
    policy.obs_mode = wanted["obs_mode"]
    return policy


def _has_progress_bar() -> bool:
    try:
        import rich  # noqa: F401
        import tqdm  # noqa: F401
    except ImportError:
        return False
    return True
