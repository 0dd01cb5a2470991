"""SHAC, a first-order agent: short-horizon actor-critic (Xu et al., "Accelerated Policy Learning with
Parallel Differentiable Simulation", ICLR 2022) through softenv's differentiable torch twin.

Where PPO, SAC and TD3 estimate the policy gradient from sampled returns, SHAC takes it through the
simulator: the actor acts for ``horizon`` steps in ``num_envs`` envs with autograd's graph recorded
(``make_vec(..., backend="torch", differentiable=True)``), and its loss is minus the discounted rewards of
that window plus the target critic's value where the window ends (or an episode is cut by its time
limit). One backward pass gives the gradient of that loss through every step, contact and response
(docs/gradients.md says what the gradient is through contact). Then the graph is cut
(``env.unwrapped.detach()``), the critic is fitted to TD(lambda) returns of the window, and the next
window starts from where this one stopped. Read it top to bottom: arguments, the agent, one training
loop (window -> actor step -> critic fit), evaluation on the test targets with the benchmark's protocol.

    python -m softenv.baselines.shac --scene SoftSphere-v0 --seeds 0 1 2 [--total-timesteps 200000]

Defaults follow the paper's (windows of 32 steps, gamma 0.99, lambda 0.95, Adam 2e-3 for both nets, 16
critic passes of 4 minibatches, target critic alpha 0.2, gradients clipped at norm 1), on [64, 64] tanh
nets with the running observation statistics of ``baselines/ppo_torch.py``, but 16 envs, not 64 (4 times
the actor's steps for the same env steps: on SoftSphere-v0 -5.2 against -13.2 after 123k steps) and a
fixed exploration noise of log std -2 (-13.2 against -15.0 at -1 and -19.0 at -3), tried on seed 0. The learning curve (test-target return against env steps, as SB3's
EvalCallback logs it) is written where ``baselines.curves.learning_curve`` reads it.
"""

from __future__ import annotations

import argparse
import copy
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

import softenv  # noqa: F401  (registers the ids)
from softenv._artifact import atomic_write

from .evaluate import SCENES, evaluate
from .ppo_torch import RunningNorm, TorchPolicy, _mlp, torch_twin, twin_fingerprint

FORMAT_VERSION = 2               # 2: the fingerprint of its simulator


@dataclass
class ShacArgs:
    scene: str = "SoftSphere-v0"             # a benchmark scene (baselines.evaluate.SCENES)
    seed: int = 0
    total_timesteps: int = 200_000
    num_envs: int = 16
    horizon: int = 32                        # steps a window's gradient runs through
    gamma: float = 0.99
    lam: float = 0.95                        # TD(lambda) of the critic's targets
    actor_lr: float = 2e-3
    critic_lr: float = 2e-3
    critic_iterations: int = 16
    critic_minibatches: int = 4
    target_alpha: float = 0.2                # target critic <- alpha * target + (1 - alpha) * critic
    max_grad_norm: float = 1.0
    log_std: float = -2.0                    # the exploration noise's log std (fixed)
    evaluations: int = 10                    # points of the learning curve
    eval_episodes: int = 20
    hidden: list[int] = field(default_factory=lambda: [64, 64])

    def check(self) -> None:
        if self.scene not in SCENES:
            raise ValueError(f"scene={self.scene!r}: valid scenes are {list(SCENES)}")
        for name in ("total_timesteps", "num_envs", "horizon", "critic_iterations", "critic_minibatches",
                     "evaluations", "eval_episodes"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ValueError(f"{name}={getattr(self, name)!r}: give a whole number >= 1")
        for name in ("gamma", "lam", "target_alpha"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name}={getattr(self, name)!r}: give a number in [0, 1]")
        if self.total_timesteps < self.num_envs * self.horizon:
            raise ValueError(f"total_timesteps={self.total_timesteps}: give at least one window, num_envs x horizon "
                             f"= {self.num_envs * self.horizon}")


class ShacAgent(nn.Module):
    """A deterministic tanh actor and a value critic over the normalised observation."""

    def __init__(self, obs_size: int, act_size: int, hidden: list[int]) -> None:
        super().__init__()
        self.norm = RunningNorm(obs_size)
        self.actor = _mlp([obs_size, *hidden, act_size], 0.01)
        self.critic = _mlp([obs_size, *hidden, 1], 1.0)

    def value(self, x: torch.Tensor) -> torch.Tensor:
        return self.critic(x).squeeze(-1)

    def deterministic(self, obs: torch.Tensor) -> torch.Tensor:
        """The action of raw observations, without exploration noise (evaluation)."""
        return torch.tanh(self.actor(self.norm(obs)))


def make_env(args: ShacArgs, split: str = "train", num_envs: int | None = None) -> Any:
    """The scene's differentiable torch twin (:func:`~baselines.ppo_torch.torch_twin`), on its training targets."""
    return torch_twin(args.scene, args.num_envs if num_envs is None else num_envs, split, differentiable=True)


def fingerprint(args: ShacArgs) -> dict[str, Any]:
    """:func:`~baselines.ppo_torch.twin_fingerprint` of the env ``args`` train on."""
    return twin_fingerprint(args.scene, lambda n, split: make_env(args, split, n))


def lambda_returns(rewards: torch.Tensor, values: torch.Tensor, ends: torch.Tensor, gamma: float,
                   lam: float) -> torch.Tensor:
    """TD(lambda) targets of a window ``(horizon, envs)``: ``values[t]`` is the target critic's value of the
    state after step ``t`` (0 where an episode terminated, the final observation's where it was cut), and
    ``ends[t]`` says an episode ended at step ``t`` (no return runs across it)."""
    targets = torch.empty_like(rewards)
    following = values[-1]
    for t in range(rewards.shape[0] - 1, -1, -1):
        following = torch.where(ends[t] | (t == rewards.shape[0] - 1), values[t], (1 - lam) * values[t] + lam * following)
        targets[t] = rewards[t] + gamma * following
        following = targets[t]
    return targets


@dataclass
class Window:
    """One window's actor loss (on autograd's graph) and what the critic learns from (detached)."""

    loss: torch.Tensor
    obs: torch.Tensor                        # where the next window starts
    inputs: torch.Tensor                     # (horizon * envs, obs) normalised observations the critic is fitted on
    rewards: torch.Tensor                    # (horizon, envs)
    ends: torch.Tensor                       # (horizon, envs): an episode ended at that step
    values: torch.Tensor                     # (horizon, envs): the target critic's value after each step


def window(agent: ShacAgent, target: nn.Module, env: Any, obs: torch.Tensor, args: ShacArgs,
           noise: torch.Generator) -> Window:
    """Act ``args.horizon`` steps from ``obs`` with the graph recorded: the loss is minus the discounted rewards
    of each episode's stretch in the window plus the target critic's value where it stops (0 where an episode
    terminated; its final observation's value where its time ran out), averaged over steps and envs."""
    n, horizon = obs.shape[0], args.horizon
    xs, rewards, ends, values = [], [], [], []
    discount = torch.ones(n, dtype=torch.float64)
    acc = torch.zeros(n, dtype=torch.float64)            # discounted rewards since the window or episode began
    loss = torch.zeros((), dtype=torch.float64)
    dtype = next(agent.actor.parameters()).dtype      # the nets' (float32 unless made double)
    for t in range(horizon):
        x = agent.norm(obs).to(dtype)
        xs.append(x.detach())
        explore = torch.randn(n, env.single_action_space.shape[0], generator=noise, dtype=dtype) * np.exp(args.log_std)
        obs, reward, terminated, truncated, info = env.step(torch.tanh(agent.actor(x) + explore))
        done = terminated | truncated
        after = obs.clone()
        if done.any():                                   # a cut episode is worth its final state's value
            after[done] = info["final_obs"][done].to(obs.dtype)
        value = target(agent.norm(after).to(dtype)).squeeze(-1) * (~terminated)
        acc = acc + discount * reward
        last = done if t < horizon - 1 else torch.ones_like(done)
        loss = loss - (acc + args.gamma * discount * value)[last].sum()
        acc, discount = torch.where(done, 0.0, acc), torch.where(done, 1.0, discount * args.gamma)
        rewards.append(reward.detach())
        ends.append(done)
        values.append(value.detach())
    return Window(loss / (horizon * n), obs, torch.cat(xs), torch.stack(rewards), torch.stack(ends), torch.stack(values))


def train(args: ShacArgs, run_dir: Path | None = None, log: Any = print) -> tuple[ShacAgent, dict[str, Any]]:
    """Train one agent; returns it and the run's figures (wall time, env steps per second, learning curve).
    With ``run_dir``, the curve is also written to ``run_dir/eval/evaluations.npz`` (SB3's layout)."""
    args.check()
    torch.manual_seed(args.seed)
    env = make_env(args)
    obs, _ = env.reset(seed=args.seed)
    n, horizon = args.num_envs, args.horizon
    agent = ShacAgent(obs.shape[1], env.single_action_space.shape[0], args.hidden)
    target = copy.deepcopy(agent.critic).requires_grad_(False)
    actor_opt = torch.optim.Adam(agent.actor.parameters(), lr=args.actor_lr)
    critic_opt = torch.optim.Adam(agent.critic.parameters(), lr=args.critic_lr)
    noise = torch.Generator().manual_seed(args.seed)
    windows = args.total_timesteps // (n * horizon)
    eval_at = {max(1, round(windows * (i + 1) / args.evaluations)) for i in range(args.evaluations)}
    curve_steps: list[int] = []
    curve_returns: list[np.ndarray] = []
    started = time.perf_counter()
    for step in range(1, windows + 1):
        agent.norm.update(obs.detach())
        w = window(agent, target, env, obs, args, noise)
        actor_opt.zero_grad()
        w.loss.backward()
        nn.utils.clip_grad_norm_(agent.actor.parameters(), args.max_grad_norm)
        actor_opt.step()
        env.unwrapped.detach()                               # the next window's graph starts here
        obs, inputs = w.obs.detach(), w.inputs
        returns = lambda_returns(w.rewards, w.values, w.ends, args.gamma, args.lam).reshape(-1)
        for _ in range(args.critic_iterations):
            for batch in torch.randperm(len(inputs), generator=noise).chunk(args.critic_minibatches):
                critic_opt.zero_grad()
                ((agent.value(inputs[batch]) - returns[batch]) ** 2).mean().backward()
                nn.utils.clip_grad_norm_(agent.critic.parameters(), args.max_grad_norm)
                critic_opt.step()
        with torch.no_grad():
            for mine, theirs in zip(target.parameters(), agent.critic.parameters()):
                mine.mul_(args.target_alpha).add_((1 - args.target_alpha) * theirs)
        if step in eval_at:
            played = evaluate(as_policy(copy.deepcopy(agent)), args.scene, args.eval_episodes)
            curve_steps.append(step * n * horizon)
            curve_returns.append(played.values["return"])
            log(f"{args.scene} shac seed {args.seed}: {step * n * horizon:,} env steps, test return "
                f"{played.values['return'].mean():.2f}")
    env.close()
    wall = time.perf_counter() - started
    steps = np.array(curve_steps, dtype=np.int64)
    results = np.stack(curve_returns)
    if run_dir is not None:
        (run_dir / "eval").mkdir(parents=True, exist_ok=True)
        atomic_write(run_dir / "eval" / "evaluations.npz", lambda fh: np.savez(fh, timesteps=steps, results=results))
    return agent, {"wall_s": wall, "env_steps": windows * n * horizon, "steps_per_s": windows * n * horizon / wall,
                   "curve": (steps, results.mean(axis=1))}


def as_policy(agent: ShacAgent) -> TorchPolicy:
    """The trained agent behind the baselines' ``predict(obs) -> action`` (deterministic)."""
    return TorchPolicy(agent, "shac")


def save(agent: ShacAgent, args: ShacArgs, path: Path, train_seconds: float | None = None) -> None:
    """Weights and the observation statistics, plain tensors (safe to load), written by rename; with the
    training's wall time when given (a record, not a setting: :func:`load` does not compare it)."""
    payload = {"format_version": FORMAT_VERSION, "args": asdict(args), "fingerprint": fingerprint(args),
               "state_dict": agent.state_dict(), "train_seconds": train_seconds}
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda fh: torch.save(payload, fh))


def load(path: Path, args: ShacArgs) -> ShacAgent:
    """The agent saved at ``path``, refused unless it was trained with exactly ``args`` on the same
    simulator and libraries (:func:`fingerprint`)."""
    data = torch.load(path, weights_only=True, map_location="cpu")
    if data.get("format_version") != FORMAT_VERSION:
        raise ValueError(f"{str(path)!r}: format_version={data.get('format_version')!r}; expected {FORMAT_VERSION}")
    if data.get("args") != asdict(args):
        raise ValueError(f"{str(path)!r} was trained with {data.get('args')!r}, not {asdict(args)!r}")
    if data["fingerprint"] != (now := fingerprint(args)):
        raise ValueError(f"{str(path)!r} was trained on another simulator or other libraries "
                         f"({data['fingerprint']}; now {now})")
    weights = data["state_dict"]
    agent = ShacAgent(weights["norm.mean"].shape[0], weights[f"actor.{len(args.hidden) * 2}.bias"].shape[0], args.hidden)
    agent.load_state_dict(weights)
    return agent


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default=ShacArgs.scene)
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--total-timesteps", type=int, default=ShacArgs.total_timesteps)
    p.add_argument("--episodes", type=int, default=100, help="test episodes a seed is scored on")
    a = p.parse_args(argv)
    torch.set_num_threads(1)
    for seed in a.seeds:
        args = ShacArgs(scene=a.scene, seed=seed, total_timesteps=a.total_timesteps)
        agent, run = train(args)
        played = evaluate(as_policy(agent), a.scene, a.episodes)
        print(f"seed {seed}: mean return {played.values['return'].mean():.2f}, {run['env_steps']:,} env steps in "
              f"{run['wall_s']:.0f} s ({run['steps_per_s']:,.0f} env steps/s)")


if __name__ == "__main__":
    main()


def train_seconds(path: Path) -> float | None:
    """The training wall time the agent saved at ``path`` recorded (None: saved without it)."""
    seconds = torch.load(path, weights_only=True, map_location="cpu").get("train_seconds")
    return None if seconds is None else float(seconds)
