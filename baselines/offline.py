"""Offline baselines trained on the Minari datasets (:mod:`softenv.baselines.minari_datasets`): behaviour
cloning and TD3+BC (Fujimoto & Gu 2021), both TorchRL's loss modules (``BCLoss``, ``TD3BCLoss``) with
its replay buffer and target updater; this file only wires them to a dataset, trains, and saves.

d3rlpy, the offline-RL library, pins ``gymnasium==1.0`` (2.8) and the imitation library ``gymnasium
0.29`` and stable-baselines3 2.2; softenv needs gymnasium 1.1 or newer (autoreset modes), so TorchRL,
which installs beside it, supplies the losses.

The actor is a 256-256 tanh-bounded MLP on the vector observation (TD3+BC's), the critics the same
size; the batch 256, Adam at 3e-4, TD3+BC's alpha 2.5, policy noise 0.2 (clip 0.5), target rate 0.005,
actor update every second step, gamma 0.99: the paper's settings.
"""

from __future__ import annotations

import time
import warnings
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import torch
from tensordict import TensorDict
from torch import nn
from torchrl.data import Bounded, LazyTensorStorage, ReplayBuffer
from torchrl.modules import MLP, Actor, ValueOperator
from torchrl.objectives import BCLoss, SoftUpdate, TD3BCLoss

from softenv._artifact import atomic_write
from softenv._validation import check_choice, check_int, check_real

METHODS = ("bc", "td3bc")
MODEL_FORMAT = "softenv-offline"
MODEL_VERSION = 1


@dataclass
class OfflineArgs:
    """An offline learner's settings: ``method`` (``bc`` or ``td3bc``), its gradient ``steps``, and the
    networks' and TD3+BC's settings (the module docstring gives their sources)."""

    method: str = "bc"
    steps: int = 20_000                 # gradient steps
    batch_size: int = 256
    lr: float = 3e-4
    hidden: int = 256
    gamma: float = 0.99
    alpha: float = 2.5
    policy_noise: float = 0.2
    noise_clip: float = 0.5
    tau: float = 0.005
    policy_delay: int = 2

    def check(self) -> None:
        check_choice(self.method, "method", METHODS)
        for name in ("steps", "batch_size", "hidden", "policy_delay"):
            check_int(getattr(self, name), name, 1)
        check_real(self.lr, "lr", 0.0, 1.0, low_open=True)
        check_real(self.gamma, "gamma", 0.0, 1.0)
        check_real(self.tau, "tau", 0.0, 1.0, low_open=True)
        for name in ("alpha", "policy_noise", "noise_clip"):
            check_real(getattr(self, name), name, 0.0)


def transitions(dataset: Any) -> TensorDict:
    """Every step of a Minari dataset as TorchRL's transition layout (``observation``, ``action``,
    ``("next", "observation" | "reward" | "done" | "terminated")``)."""
    obs, act, nxt, rew, term, trunc = [], [], [], [], [], []
    for episode in dataset.iterate_episodes():
        obs.append(episode.observations[:-1])
        nxt.append(episode.observations[1:])
        act.append(episode.actions)
        rew.append(episode.rewards)
        term.append(episode.terminations)
        trunc.append(episode.truncations)
    cat = lambda parts, dtype: torch.as_tensor(np.concatenate(parts), dtype=dtype)  # noqa: E731
    terminated = cat(term, torch.bool)[:, None]
    n = len(terminated)
    return TensorDict({"observation": cat(obs, torch.float32), "action": cat(act, torch.float32),
                       "next": {"observation": cat(nxt, torch.float32), "reward": cat(rew, torch.float32)[:, None],
                                "terminated": terminated, "done": terminated | cat(trunc, torch.bool)[:, None]}},
                      batch_size=[n])


def make_actor(obs_size: int, action_size: int, hidden: int) -> Actor:
    net = nn.Sequential(MLP(in_features=obs_size, out_features=action_size, num_cells=[hidden, hidden]), nn.Tanh())
    return Actor(net, in_keys=["observation"], spec=Bounded(-1.0, 1.0, (action_size,)))


def train(dataset: Any, args: OfflineArgs, seed: int, log: Callable[[str], None] = print) -> Actor:
    """Train ``args.method`` on ``dataset`` from ``seed`` (the draw of the networks and of every batch)."""
    args.check()
    torch.manual_seed(seed)
    data = transitions(dataset)
    obs_size, action_size = data["observation"].shape[-1], data["action"].shape[-1]
    actor = make_actor(obs_size, action_size, args.hidden)
    buffer = ReplayBuffer(storage=LazyTensorStorage(len(data)), batch_size=args.batch_size)
    buffer.extend(data)
    started = time.perf_counter()
    if args.method == "bc":
        with _quiet_annotations():
            loss = BCLoss(actor, loss_function="mse")
        optimizer = torch.optim.Adam(actor.parameters(), lr=args.lr)
        for step in range(args.steps):
            value = loss(buffer.sample())["loss_bc"]
            optimizer.zero_grad()
            value.backward()
            optimizer.step()
            _report(log, step, args.steps, started, bc=value)
        return actor
    critic = ValueOperator(MLP(in_features=obs_size + action_size, out_features=1, num_cells=[args.hidden] * 2),
                           in_keys=["observation", "action"])
    with _quiet_annotations():
        loss = TD3BCLoss(actor, critic, action_spec=actor.spec, alpha=args.alpha, policy_noise=args.policy_noise,
                         noise_clip=args.noise_clip)
    loss.make_value_estimator(gamma=args.gamma)
    target = SoftUpdate(loss, tau=args.tau)
    actor_opt = torch.optim.Adam(loss.actor_network_params.values(True, True), lr=args.lr)
    critic_opt = torch.optim.Adam(loss.qvalue_network_params.values(True, True), lr=args.lr)
    for step in range(args.steps):
        batch = buffer.sample()
        q_loss, _ = loss.qvalue_loss(batch)
        critic_opt.zero_grad()
        q_loss.backward()
        critic_opt.step()
        if step % args.policy_delay == 0:
            a_loss, _ = loss.actor_loss(batch)
            actor_opt.zero_grad()
            a_loss.backward()
            actor_opt.step()
            target.step()
            _report(log, step, args.steps, started, q=q_loss, actor=a_loss)
    return actor


@contextmanager
def _quiet_annotations() -> Iterator[None]:
    """TorchRL 0.14's loss modules warn, as they are built, that their own target parameters are not
    annotated: a note to TorchRL's developers, not to a softenv user."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="The name target_.* wasn't part of the annotations", category=UserWarning)
        yield


def _report(log: Callable[[str], None], step: int, steps: int, started: float, **losses: torch.Tensor) -> None:
    if (step + 1) % max(1, steps // 5) == 0 or step == 0:
        text = ", ".join(f"{name} loss {float(v.detach()):.4g}" for name, v in losses.items())
        log(f"step {step + 1:,}/{steps:,}: {text} ({time.perf_counter() - started:.0f} s)")


class OfflinePolicy:
    """A trained actor as a benchmark policy: batched vector observations in, actions out."""

    def __init__(self, actor: Actor, name: str) -> None:
        self.actor, self.name = actor, name
        self.actor.eval()

    def reset(self) -> None:
        pass

    def predict(self, obs: Any) -> np.ndarray:
        with torch.no_grad():
            rows = torch.as_tensor(np.asarray(obs, dtype=np.float32))
            return self.actor.module(rows).numpy()


def save(actor: Actor, args: OfflineArgs, meta: dict[str, Any], path: str | Path) -> None:
    """Save the actor's weights with what it is (loadable with ``weights_only=True``)."""
    layers = [m for m in actor.module.modules() if isinstance(m, nn.Linear)]
    record = {"format": MODEL_FORMAT, "format_version": MODEL_VERSION, "args": asdict(args), **meta,
              "obs_size": int(layers[0].in_features), "action_size": int(layers[-1].out_features),
              "state_dict": actor.state_dict()}
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda handle: torch.save(record, handle))


def load(path: str | Path, expect: dict[str, Any]) -> tuple[Actor, dict[str, Any]]:
    """Load an actor saved by :func:`save`; its format, version and each of ``expect``'s entries (the
    scene, the dataset, the method) must match, or it is refused naming the entry."""
    try:
        record = torch.load(Path(path), map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - torch's errors for damaged files vary
        raise ValueError(f"{str(path)!r} is not a readable softenv offline model ({exc})") from exc
    if not isinstance(record, dict) or record.get("format") != MODEL_FORMAT:
        raise ValueError(f"{str(path)!r} is not a softenv offline model")
    if record.get("format_version") != MODEL_VERSION:
        raise ValueError(f"{str(path)!r}: format_version={record.get('format_version')!r}; this softenv reads "
                         f"{MODEL_VERSION}")
    for key, value in expect.items():
        if record.get(key) != value:
            raise ValueError(f"{str(path)!r} was trained with {key}={record.get(key)!r}, not {value!r}")
    args = OfflineArgs(**record["args"])
    actor = make_actor(record["obs_size"], record["action_size"], args.hidden)
    actor.load_state_dict(record["state_dict"])
    return actor, record
