"""PPO that never leaves the device: CleanRL's continuous-action PPO on softenv's torch twin.

Rollouts, advantages, observation statistics and updates are tensors on one device (``--device cuda``
or ``cpu``); the env is ``gym.make_vec(..., backend="torch")`` with same-step autoreset, so nothing is
copied to numpy while training. Its training targets are drawn on the device (``target_draw="device"``:
a step never synchronises with the host; on CPU it is also the faster draw). Read it top to bottom: arguments, the agent, the observation
normaliser, one training loop (rollout -> GAE -> clipped updates), then evaluation on the test
targets with the benchmark's protocol (``baselines.evaluate``: 100 episodes, normalized score
against the scene's oracle).

    python -m softenv.baselines.ppo_torch --scene SoftSphere-v0 --seeds 0 1 2 3 4 --device cpu --jobs 2 \\
        --report results/ppo-torch.md

Hyper-parameters follow ``baselines/hyperparams/ppo.yml`` (SB3's PPO on the same scene): 16 envs x
128 steps per rollout, minibatches of 256, 5 epochs, gamma 0.95, lambda 0.9, [64, 64] tanh nets,
initial log std -1; plus CleanRL's observation normalisation, and 600k env steps (300k reach 94.5
with one seed, 600k 97.3). A truncated episode's last reward is bootstrapped from the value of its final
observation (``info["final_obs"]``), as SB3 does.

Sixteen envs leave a GPU idle between kernel launches. Wide batches (``--num-envs 1024 --num-steps 16
--minibatch-size 2048 --total-timesteps 3000000``) reach the same score with 5x the steps in less time,
on a CPU too (README, results/ppo-torch-wide.md).
"""

from __future__ import annotations

import argparse
import shlex
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Protocol

import gymnasium as gym
import numpy as np
import torch
from torch import nn

import softenv  # noqa: F401  (registers the ids)
from softenv._artifact import atomic_write
from softenv.bench.timing import code_revision, machine_info
from softenv.envs.torch_twin import usable_device
from softenv.parallel import Interrupted, Job, describe, run_jobs
from softenv.stats import bootstrap_ci, nested_interval

from .anchors import anchor_job
from .evaluate import SCENES, evaluate, normalized_scores, scene_kwargs
from .fingerprint import PROBE_ENVS, library_versions, probe_steps, rollout_digest

FORMAT_VERSION = 3                # 3: every setting and the fingerprint of its simulator; 2: the seed and budget


@dataclass
class Args:
    scene: str = "SoftSphere-v0"             # a benchmark scene (baselines.evaluate.SCENES)
    seed: int = 0
    device: str = "cpu"
    target_draw: str = "device"              # where training targets are drawn: "device" or "host"
    total_timesteps: int = 600_000
    num_envs: int = 16
    num_steps: int = 128                     # rollout length per env
    minibatch_size: int = 256
    update_epochs: int = 5
    learning_rate: float = 3e-4
    anneal_lr: bool = True
    gamma: float = 0.95
    gae_lambda: float = 0.9
    clip_coef: float = 0.2
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    log_std_init: float = -1.0
    normalize_obs: bool = True               # running mean/std of observations (CleanRL's wrapper)
    compile_env: bool = False                # the env compiles its step (the laryngoscope: its substep), recorded as
                                             # CUDA graphs on a GPU; compiling takes 10-30 s (laryngoscope: 1-3 min)
    hidden: list[int] = field(default_factory=lambda: [64, 64])


class RunningNorm(nn.Module):
    """Observation mean and variance (Chan et al.'s parallel update), kept as buffers on the device."""

    mean: torch.Tensor
    var: torch.Tensor
    count: torch.Tensor

    def __init__(self, size: int) -> None:
        super().__init__()
        self.register_buffer("mean", torch.zeros(size, dtype=torch.float64))
        self.register_buffer("var", torch.ones(size, dtype=torch.float64))
        self.register_buffer("count", torch.tensor(1e-4, dtype=torch.float64))

    def update(self, x: torch.Tensor) -> None:
        x = x.to(torch.float64)
        mean, var, n = x.mean(0), x.var(0, unbiased=False), x.shape[0]
        delta, total = mean - self.mean, self.count + n
        self.mean += delta * n / total
        self.var = (self.var * self.count + var * n + delta ** 2 * self.count * n / total) / total
        self.count = total

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.clamp((x - self.mean.float()) / torch.sqrt(self.var.float() + 1e-8), -10.0, 10.0)


def _mlp(sizes: list[int], out_gain: float) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        linear = nn.Linear(a, b)
        last = i == len(sizes) - 2
        nn.init.orthogonal_(linear.weight, out_gain if last else np.sqrt(2))
        nn.init.zeros_(linear.bias)
        layers += [linear] if last else [linear, nn.Tanh()]
    return nn.Sequential(*layers)


class Agent(nn.Module):
    """Gaussian actor and value critic, separate tanh MLPs over the normalised observation ``x =
    agent.norm(obs)`` (rollouts store ``x``, as CleanRL's normalising wrapper does, so the updates see
    the inputs the actions were drawn from)."""

    def __init__(self, obs_size: int, act_size: int, hidden: list[int], log_std_init: float) -> None:
        super().__init__()
        self.norm = RunningNorm(obs_size)
        self.critic = _mlp([obs_size, *hidden, 1], 1.0)
        self.actor_mean = _mlp([obs_size, *hidden, act_size], 0.01)
        self.actor_logstd = nn.Parameter(torch.full((1, act_size), log_std_init))

    def value(self, x: torch.Tensor) -> torch.Tensor:
        return self.critic(x).squeeze(-1)

    def act(self, x: torch.Tensor, action: torch.Tensor | None = None
            ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """A sampled (or the given) action, its log-probability, the entropy and the value."""
        mean = self.actor_mean(x)
        dist = torch.distributions.Normal(mean, self.actor_logstd.expand_as(mean).exp())
        if action is None:
            action = dist.sample()
        return action, dist.log_prob(action).sum(-1), dist.entropy().sum(-1), self.critic(x).squeeze(-1)

    def deterministic(self, obs: torch.Tensor) -> torch.Tensor:
        """The mean action of raw observations, clipped to the action box (evaluation)."""
        return torch.clamp(self.actor_mean(self.norm(obs)), -1.0, 1.0)


def torch_twin(scene: str, num_envs: int, split: str = "train", **options: Any) -> Any:
    """``scene``'s torch twin on its ``split`` targets, as the torch learners train on it: float32,
    same-step autoreset, actions unchecked (a learner sends its box's own); ``options`` are further
    ``gym.make_vec`` keywords (device, target draw, compilation, gradients)."""
    if scene not in SCENES:
        raise ValueError(f"unknown scene {scene!r}; valid scenes: {list(SCENES)}")
    env_id, kwargs = scene_kwargs(scene)
    kwargs["task"] = {**kwargs["task"], "split": split}
    return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", backend="torch",
                        dtype=torch.float32, check_actions=False, autoreset_mode="same_step", **kwargs, **options)


def twin_fingerprint(scene: str, make: Callable[[int, str], Any]) -> dict[str, Any]:
    """What a torch-twin learner on ``scene`` depends on beyond its settings (:mod:`baselines.fingerprint`):
    the libraries' versions and the digest of its env, ``make(num_envs, split)``."""
    return {"libraries": library_versions(("torch", "gymnasium", "numpy")),
            "dynamics": rollout_digest(lambda split: make(PROBE_ENVS, split), probe_steps(scene_kwargs(scene)[1]))}


def make_env(args: Args, split: str = "train", num_envs: int | None = None) -> Any:
    options: dict[str, Any] = {"torch_device": args.device, "target_draw": args.target_draw}
    if args.compile_env:    # CUDA graphs overwrite a step's outputs at the next step; the loop is done with them
        options |= {"compile_options": {"mode": "default"}, "cuda_graph": usable_device(args.device).type == "cuda"}
    return torch_twin(args.scene, args.num_envs if num_envs is None else num_envs, split, **options)


def train(args: Args, log: Any = print) -> tuple[Agent, dict[str, float]]:
    """Train one agent; returns it and the run's figures (wall time, env steps per second)."""
    for name in ("num_envs", "num_steps", "minibatch_size", "update_epochs"):
        if getattr(args, name) < 1:
            raise ValueError(f"{name}={getattr(args, name)!r} must be >= 1")
    if args.total_timesteps < args.num_envs * args.num_steps:
        raise ValueError(f"total_timesteps={args.total_timesteps!r} must be >= num_envs x num_steps "
                         f"({args.num_envs * args.num_steps}, one rollout)")
    torch.manual_seed(args.seed)
    envs = make_env(args)
    device = envs.torch_device                   # checked by the env: one that this process can use
    obs_size = envs.single_observation_space.shape[0]
    agent = Agent(obs_size, 4, args.hidden, args.log_std_init).to(device)
    optimizer = torch.optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5)
    n, steps = args.num_envs, args.num_steps
    batch = n * steps
    iterations = args.total_timesteps // batch
    obs_buf = torch.zeros((steps, n, obs_size), device=device)
    act_buf = torch.zeros((steps, n, 4), device=device)
    logp_buf, rew_buf, done_buf, val_buf = (torch.zeros((steps, n), device=device) for _ in range(4))

    started = time.perf_counter()
    obs, _ = envs.reset(seed=args.seed)
    done = torch.zeros(n, device=device)
    for iteration in range(iterations):
        if args.anneal_lr:
            optimizer.param_groups[0]["lr"] = args.learning_rate * (1.0 - iteration / iterations)
        # -- rollout: the env and the policy on the same device ---------------------------------
        for step in range(steps):
            if args.normalize_obs:
                agent.norm.update(obs)
            x = agent.norm(obs)
            obs_buf[step], done_buf[step] = x, done
            with torch.no_grad():
                action, logp, _, value = agent.act(x)
            act_buf[step], logp_buf[step], val_buf[step] = action, logp, value
            obs, reward, terminated, truncated, info = envs.step(torch.clamp(action, -1.0, 1.0))
            with torch.no_grad():          # a truncated episode goes on in value: bootstrap from its final observation
                reward = reward + args.gamma * agent.value(agent.norm(info["final_obs"])) * (truncated & ~terminated)
            rew_buf[step] = reward
            done = (terminated | truncated).float()
        # -- generalised advantage estimation ---------------------------------------------------
        with torch.no_grad():
            next_value = agent.value(agent.norm(obs))
            advantages = torch.zeros_like(rew_buf)
            last = torch.zeros(n, device=device)
            for t in reversed(range(steps)):
                not_done = 1.0 - (done if t == steps - 1 else done_buf[t + 1])
                following = next_value if t == steps - 1 else val_buf[t + 1]
                delta = rew_buf[t] + args.gamma * following * not_done - val_buf[t]
                last = delta + args.gamma * args.gae_lambda * not_done * last
                advantages[t] = last
            returns = advantages + val_buf
        # -- clipped policy and value updates ---------------------------------------------------
        b_obs, b_act, b_logp = obs_buf.reshape(batch, -1), act_buf.reshape(batch, 4), logp_buf.reshape(batch)
        b_adv, b_ret = advantages.reshape(batch), returns.reshape(batch)
        for _ in range(args.update_epochs):
            for mb in torch.randperm(batch, device=device).split(args.minibatch_size):
                _, logp, entropy, value = agent.act(b_obs[mb], b_act[mb])
                ratio = (logp - b_logp[mb]).exp()
                adv = (b_adv[mb] - b_adv[mb].mean()) / (b_adv[mb].std() + 1e-8)
                policy_loss = torch.max(-adv * ratio, -adv * torch.clamp(ratio, 1 - args.clip_coef, 1 + args.clip_coef)).mean()
                value_loss = 0.5 * ((value - b_ret[mb]) ** 2).mean()
                loss = policy_loss - args.ent_coef * entropy.mean() + args.vf_coef * value_loss
                optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(agent.parameters(), args.max_grad_norm)
                optimizer.step()
        if iteration % 20 == 0 or iteration == iterations - 1:
            log(f"seed {args.seed}: {(iteration + 1) * batch:,} steps, mean reward {rew_buf.mean().item():.3f}, "
                f"{(iteration + 1) * batch / (time.perf_counter() - started):,.0f} steps/s")
    wall = time.perf_counter() - started
    return agent, {"wall_s": wall, "steps_per_s": iterations * batch / wall, "env_steps": iterations * batch}


class Actor(Protocol):
    """What :class:`TorchPolicy` needs of an agent (this module's :class:`Agent`, ``baselines/shac.py``'s)."""

    def cpu(self) -> Any: ...

    def deterministic(self, obs: torch.Tensor) -> torch.Tensor: ...


class TorchPolicy:
    """A trained agent behind the baselines' ``predict(obs) -> action`` (numpy in and out; deterministic)."""

    def __init__(self, agent: Actor, name: str = "ppo-torch") -> None:
        self.agent = agent.cpu().eval()
        self.name = name

    def reset(self) -> None:
        pass

    def predict(self, obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return self.agent.deterministic(torch.as_tensor(np.asarray(obs), dtype=torch.float32)).numpy()


def save(agent: Agent, args: Args, path: Path) -> None:
    """Weights and the statistics of the observation normaliser, plain tensors (safe to load), with the
    settings and the fingerprint (:func:`twin_fingerprint`) it was trained with, written by rename (a
    stop leaves the old file or the new one)."""
    payload = {"format_version": FORMAT_VERSION, "scene": args.scene, "hidden": list(args.hidden),
               "settings": settings(args), "fingerprint": fingerprint(args), "state_dict": agent.state_dict()}
    atomic_write(path, lambda fh: torch.save(payload, fh))


def settings(args: Args) -> dict[str, Any]:
    """What of ``args`` an agent is trained with: every argument but where it runs (device, compilation)."""
    return {k: v for k, v in asdict(args).items() if k not in ("device", "compile_env")}


def fingerprint(args: Args) -> dict[str, Any]:
    """:func:`twin_fingerprint` of the env ``args`` train on, stepped eagerly (compiling it would cost
    minutes and change no setting of the simulator)."""
    return twin_fingerprint(args.scene, lambda n, split: make_env(replace(args, compile_env=False), split, n))


def load(path: Path, scene: str, args: Args | None = None) -> Agent:
    """The agent saved at ``path`` for ``scene``; with ``args``, refused unless trained with their
    :func:`settings` on the same simulator and libraries (a run to reuse, not merely to evaluate)."""
    data = torch.load(path, weights_only=True, map_location="cpu")
    if data.get("format_version") != FORMAT_VERSION:
        raise ValueError(f"{str(path)!r}: format_version={data.get('format_version')!r}; expected {FORMAT_VERSION}")
    if data.get("scene") != scene:
        raise ValueError(f"{str(path)!r} was trained on scene {data.get('scene')!r}, not {scene!r}")
    if args is not None and data.get("settings") != settings(args):
        other = {k: (v, data.get("settings", {}).get(k)) for k, v in settings(args).items()
                 if data.get("settings", {}).get(k) != v}
        raise ValueError(f"{str(path)!r} was trained with other settings: "
                         + ", ".join(f"{k}={b!r} (asked {a!r})" for k, (a, b) in other.items()))
    if args is not None and data["fingerprint"] != (now := fingerprint(args)):
        raise ValueError(f"{str(path)!r} was trained on another simulator or other libraries "
                         f"({data['fingerprint']}; now {now})")
    weights = data["state_dict"]
    agent = Agent(weights["norm.mean"].shape[0], 4, data["hidden"], 0.0)
    agent.load_state_dict(weights)
    return agent


def seed_job(args: Args, episodes: int, out: str | None) -> tuple[np.ndarray, dict[str, float]]:
    """Train one seed, save it when ``out`` is given, and return its summed shape errors on the test
    targets (the benchmark's protocol) with the run's figures."""
    torch.set_num_threads(1)
    agent, run = train(args, log=lambda line: None)
    if out is not None:
        Path(out).mkdir(parents=True, exist_ok=True)
        save(agent, args, Path(out) / f"ppo-torch-{args.seed}.pt")
    return evaluate(TorchPolicy(agent), args.scene, episodes).values["error_sum_mm"], run


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default=Args.scene)
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--target-draw", choices=["host", "device"], default=Args.target_draw,
                   help="where training targets are drawn (default: device; host: the numpy generators)")
    p.add_argument("--total-timesteps", type=int, default=Args.total_timesteps)
    p.add_argument("--num-envs", type=int, default=Args.num_envs, help="envs stepped at once (a GPU wants thousands)")
    p.add_argument("--num-steps", type=int, default=Args.num_steps, help="rollout length per env")
    p.add_argument("--minibatch-size", type=int, default=Args.minibatch_size)
    p.add_argument("--update-epochs", type=int, default=Args.update_epochs)
    p.add_argument("--no-normalize-obs", action="store_true", help="feed raw observations (as SB3's PPO here)")
    p.add_argument("--compile-env", action="store_true",
                   help="the env compiles its step (CUDA graphs on a GPU; needs --target-draw device; refused for "
                        "the laryngoscope on CUDA, where one Triton kernel runs its step: docs/laryngoscope.md)")
    p.add_argument("--episodes", type=int, default=100, help="test episodes per seed")
    p.add_argument("--jobs", type=int, default=1, help="seeds trained at once (local worker processes)")
    p.add_argument("--out", help="folder for the weights (ppo-torch-<seed>.pt)")
    p.add_argument("--report", type=Path, help="write the results as Markdown here")
    a = p.parse_args(argv)
    command = "python -m softenv.baselines.ppo_torch " + " ".join(shlex.quote(x) for x in (argv if argv is not None else sys.argv[1:]))
    torch.set_num_threads(1)
    zero, oracle, _ = anchor_job(a.scene, a.episodes, {})
    jobs = [Job(f"seed {seed}", seed_job, (Args(scene=a.scene, seed=seed, device=a.device, target_draw=a.target_draw,
                                                total_timesteps=a.total_timesteps, num_envs=a.num_envs,
                                                num_steps=a.num_steps, minibatch_size=a.minibatch_size,
                                                update_epochs=a.update_epochs, compile_env=a.compile_env,
                                                normalize_obs=not a.no_normalize_obs), a.episodes, a.out))
            for seed in a.seeds]
    try:
        results = run_jobs(jobs, "local", a.jobs)
    except Interrupted as stop:
        where = f"seeds that finished have their weights in {a.out}" if a.out else "no weights kept (no --out)"
        print(f"ppo_torch: stopped by {signal.Signals(stop.signum).name}; {where}; a rerun trains every seed again",
              file=sys.stderr)
        raise SystemExit(stop.exit_status) from None
    failed = [r for r in results if not r.ok]
    if failed:
        raise SystemExit("; ".join(f"{r.key}: {r.error}" for r in failed))
    lines = ["| seed | normalized score | env steps | wall (s) | env steps/s |", "|---|---|---|---|---|"]
    scores = []
    for seed, r in zip(a.seeds, results):
        errors, run = r.value
        score = normalized_scores(errors, zero, oracle)
        scores.append(score)
        mean, lo, hi = bootstrap_ci(score)
        lines.append(f"| {seed} | {mean:.1f} [{lo:.1f}, {hi:.1f}] | {run['env_steps']:,} | {run['wall_s']:.0f} | "
                     f"{run['steps_per_s']:,.0f} |")
    mean, lo, hi = nested_interval(np.stack(scores))
    summary = (f"{a.scene}, ppo-torch on {a.device}, {len(a.seeds)} seeds x {a.episodes} test episodes: normalized "
               f"score {mean:.1f} [{lo:.1f}, {hi:.1f}] (mean [95 % interval: seeds, then their episodes, resampled])")
    print("\n".join(lines) + "\n\n" + summary)
    if a.report is not None:
        machine = machine_info()
        report = "\n".join([
            "# PPO on the torch twin (`baselines/ppo_torch.py`)\n",
            f"Made by `{command}` at {code_revision()} ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {machine['cpu']}, "
            f"{machine['logical_cores']} cores, one torch thread per seed, {describe('local', a.jobs)}; torch {torch.__version__}).\n",
            "Protocol as `softenv compare`: test targets, normalized score against the scene's anchors "
            "(0 = no force, 100 = the planning oracle). Each seed trains on `gym.make_vec(..., backend=\"torch\")` "
            f"(float32, same-step autoreset, {a.target_draw} target draw) and is evaluated on the numpy twin.\n", *lines, "", summary, ""])
        atomic_write(a.report, lambda fh: fh.write(report), text=True)


if __name__ == "__main__":
    main()
