"""SB3 agents on SoftSphere: hyper-parameters from rl-zoo-style YAML, training on the batched twin
with CSV/TensorBoard logs, evaluation on the test targets, checkpoints and resume; saved agents
carry their scene and observation layout, checked on load."""

from __future__ import annotations

import ast
import json
from pathlib import Path
from typing import Any

import numpy as np

from softenv.envs.config import config_key, make_config

from .evaluate import scene_kwargs
from .policies import SB3Policy

HYPERPARAMS = Path(__file__).parent / "hyperparams"
# name -> (SB3 class name, YAML file); the observation mode and any scene settings come from the
# YAML's env_kwargs, as rl-zoo3 reads them
ALGOS: dict[str, tuple[str, str]] = {
    "ppo": ("PPO", "ppo.yml"),
    "sac": ("SAC", "sac.yml"),
    "td3": ("TD3", "td3.yml"),
    "sac-her": ("SAC", "her.yml"),
}
AGENT_FORMAT_VERSION = 1


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
    kwargs = agent_env_kwargs(algo, scene)[1]
    obs_mode = kwargs.pop("obs_mode")
    config = make_config(**kwargs)
    return {"scene": scene, "obs_mode": obs_mode,
            "scene_key": config_key(config, ("tissue", "mesh", "shape_model", "response", "device", "dynamics", "task"))}


def make_training_env(algo: str, scene: str, n_envs: int, split: str = "train") -> Any:
    from stable_baselines3.common.vec_env import VecMonitor  # the rl extra

    from softenv.envs.sb3 import SoftSphereSB3VecEnv        # stable-baselines3: the rl extra

    env_id, kwargs = agent_env_kwargs(algo, scene, split)
    # the adapter's default infos: is_success, all SB3 reads (the other terms would cost a dict entry each)
    return VecMonitor(SoftSphereSB3VecEnv(n_envs, env_id, **kwargs))


def train_agent(algo: str, scene: str, seed: int, out_dir: str | Path, timesteps: int | None = None,
                progress: bool = True, eval_episodes: int = 20, resume: bool = True) -> Path:
    """Train (or resume) one agent; returns the path of the final model (``model.zip``).

    A run that finds checkpoints in ``out_dir`` (and no final model) resumes from the last one; its
    ``agent.json`` lists the env steps it resumed at (``resumed_at``), because a resumed run is not
    bit for bit the same as one that ran through."""
    import stable_baselines3 as sb3                         # the rl extra
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback, EvalCallback  # the rl extra
    from stable_baselines3.common.logger import configure   # the rl extra

    env_id = scene_kwargs(scene)[0]
    params = hyperparams(algo, env_id)
    n_envs = int(params.pop("n_envs", 1))
    budget = int(timesteps if timesteps is not None else params.pop("n_timesteps"))
    params.pop("n_timesteps", None)
    params.pop("env_kwargs", None)               # for the env (make_training_env), not the algorithm
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    final = out / "model.zip"
    if final.exists() and resume:
        return final
    env = make_training_env(algo, scene, n_envs)
    cls = getattr(sb3, ALGOS[algo][0])
    if params.get("replay_buffer_class") == "HerReplayBuffer":
        from stable_baselines3 import HerReplayBuffer       # the rl extra

        params["replay_buffer_class"] = HerReplayBuffer
    noise_type, noise_std = params.pop("noise_type", None), params.pop("noise_std", 0.1)
    if noise_type == "normal":
        from stable_baselines3.common.noise import NormalActionNoise  # the rl extra

        params["action_noise"] = NormalActionNoise(np.zeros(4), noise_std * np.ones(4))
    checkpoints = sorted(out.glob("checkpoints/agent_*_steps.zip"), key=lambda p: int(p.stem.split("_")[1]))
    resumes = out / "checkpoints" / "resumed_at.json"
    if checkpoints and resume:
        model = cls.load(checkpoints[-1], env=env, device="cpu")
        buffer = checkpoints[-1].with_name(checkpoints[-1].stem.replace("agent_", "agent_replay_buffer_") + ".pkl")
        if buffer.exists() and hasattr(model, "load_replay_buffer"):
            model.load_replay_buffer(buffer)
        # a checkpoint keeps the model and replay buffer, not the envs' mid-episode states or the random
        # streams, so a resumed run is not bit for bit the run that was not stopped: it is recorded
        resumed_at = [*(json.loads(resumes.read_text()) if resumes.exists() else []), int(model.num_timesteps)]
        resumes.write_text(json.dumps(resumed_at))
    else:
        model = cls(params.pop("policy"), env, seed=seed, device="cpu", verbose=0, **params)
        resumed_at = []
        resumes.unlink(missing_ok=True)
    formats = ["csv"]
    try:
        import tensorboard  # noqa: F401

        formats.append("tensorboard")
    except ImportError:
        pass
    model.set_logger(configure(str(out / "logs"), formats))
    eval_env = make_training_env(algo, scene, min(eval_episodes, 10), split="test")
    callbacks = CallbackList([
        EvalCallback(eval_env, n_eval_episodes=eval_episodes, eval_freq=max(budget // (10 * n_envs), 1),
                     log_path=str(out / "eval"), best_model_save_path=str(out / "best"), verbose=0),
        CheckpointCallback(max(budget // (4 * n_envs), 1), str(out / "checkpoints"), name_prefix="agent",
                           save_replay_buffer=hasattr(model, "replay_buffer")),
    ])
    model.learn(budget - model.num_timesteps, callback=callbacks, progress_bar=progress and _has_progress_bar(),
                reset_num_timesteps=False)
    model.save(final)
    meta = {"format_version": AGENT_FORMAT_VERSION, "algo": algo, "seed": seed, "timesteps": budget,
            "resumed_at": resumed_at, **_layout(algo, scene)}
    (out / "agent.json").write_text(json.dumps(meta, indent=2))
    env.close()
    eval_env.close()
    return final


def load_agent(path: str | Path, scene: str) -> SB3Policy:
    """Load an agent saved by :func:`train_agent` for ``scene``; another scene or layout is an error."""
    import stable_baselines3 as sb3                         # the rl extra

    path = Path(path)
    meta_path = path.parent / "agent.json"
    if not meta_path.exists():
        raise ValueError(f"{str(path)!r} has no agent.json beside it (format and scene unknown)")
    meta = json.loads(meta_path.read_text())
    if meta.get("format_version") != AGENT_FORMAT_VERSION:
        raise ValueError(f"{str(meta_path)!r}: format_version={meta.get('format_version')!r}; "
                         f"this softenv reads {AGENT_FORMAT_VERSION}")
    algo = meta.get("algo")
    if algo not in ALGOS:
        raise ValueError(f"{str(meta_path)!r}: unknown agent {algo!r}; valid agents: {list(ALGOS)}")
    wanted = _layout(algo, scene)
    for key in ("scene_key", "obs_mode"):
        if meta.get(key) != wanted[key]:
            raise ValueError(f"agent {str(path)!r} was trained for scene {meta.get('scene')!r} "
                             f"({key}={meta.get(key)!r}); asked for scene {scene!r} ({key}={wanted[key]!r})")
    resumed_at = meta.get("resumed_at", [])       # absent in files written before it was recorded
    if not (isinstance(resumed_at, list) and all(type(step) is int for step in resumed_at)):
        raise ValueError(f"{str(meta_path)!r}: resumed_at={resumed_at!r}; expected a list of env steps (ints)")
    # HER's replay buffer needs an env to rebuild itself, even for inference
    env = make_training_env(algo, scene, 1, split="test") if algo == "sac-her" else None
    model = getattr(sb3, ALGOS[algo][0]).load(path, env=env, device="cpu")
    policy = SB3Policy(model, algo)
    policy.obs_mode = wanted["obs_mode"]
    policy.resumed_at = resumed_at
    return policy


def _has_progress_bar() -> bool:
    try:
        import rich  # noqa: F401
        import tqdm  # noqa: F401
    except ImportError:
        return False
    return True
