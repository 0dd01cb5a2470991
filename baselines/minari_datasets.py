"""Minari datasets of the laryngoscope scenes: demonstrations for imitation and offline RL.

Each dataset is made here, locally, through Minari's own :class:`minari.DataCollector`, and kept in
Minari's local store (``$MINARI_DATASETS_PATH``, else ``~/.minari/datasets``), so
``minari.load_dataset("softenv/SoftSphereHaptic-v0/expert-v0")`` finds it; nothing is downloaded.
Episode ``i`` is reset with seed ``i`` on the scene's training targets (the benchmark tests on others),
so every episode replays bit for bit through ``dataset.recover_environment()`` from its stored seed.

| kind | demonstrator |
|---|---|
| ``expert`` | the scripted expert (the benchmark's ``expert`` baseline: the device model inverted) |
| ``oracle`` | the trajectory oracle (CEM through the device, planned per episode on its training target, replayed) |
| ``novice`` | the expert's hand path degraded to the published novice profile (:mod:`softenv.training.profiles`) |
| ``mixed`` | a skills lab's day: expert, intermediate and novice episodes in turn |
| ``random`` | uniform actions |
| ``ppo`` | a stable-baselines3 PPO agent's deterministic rollouts, trained at its YAML budget (seed 0) |

Reference scores (``ref_min_score``, ``ref_max_score``) are the mean returns of the benchmark's two
anchor policies, no force and the oracle, on the protocol's test episodes, so
``minari.get_normalized_score`` puts them at 0 and 1. The benchmark's own score scales each episode's
summed shape error between the same two policies (:mod:`softenv.baselines.anchors`); a return also
counts the reward's force and smoothness terms, so the two scales agree at their ends, not between.
"""

from __future__ import annotations

import json
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Protocol

import gymnasium as gym
import numpy as np

import softenv
from softenv._cache import cached
from softenv._progress import progress
from softenv._validation import check_int
from softenv.bench.timing import code_revision
from softenv.envs.config import make_config
from softenv.envs.world import World
from softenv.training import profiles
from softenv.training.hand import action_toward, haptic_config, relative_hand_pose
from softenv.training.scoring import replay_hand
from softenv.training.trainee import degrade, expert_hand_log

from .agents import hyperparams, load_agent, train_agent
from .anchors import compute_anchors, oracle_of, scene_config
from .evaluate import EPISODES, SCENES, TRAIN_SPLIT, device_kind, episode_seeds, evaluate, scene_kwargs
from .fingerprint import PROBE_ENVS, probe_steps, rollout_digest
from .planner import ReplayPolicy, TrajectoryOracle
from .policies import Policy, RandomPolicy, ZeroPolicy, make_baseline

NAMESPACE = "softenv"
VERSION = 0                        # bump when a demonstrator or the collection changes what a dataset holds
KINDS = ("expert", "oracle", "mixed", "novice", "random", "ppo")
DATASET_SCENES = tuple(s for s in SCENES if device_kind(s) == "laryngoscope")
MIXED = ("expert", "intermediate", "novice")        # the mixed dataset's episodes cycle through them
AGENT = "ppo"                      # the ppo dataset's agent, trained at its YAML budget (the benchmark's)
REFERENCE_EPISODES = 100


def dataset_id(scene: str, kind: str) -> str:
    """Minari's id of a dataset: ``softenv/<scene>/<kind>-v0``."""
    _check(scene, kind)
    return f"{NAMESPACE}/{scene}/{kind}-v{VERSION}"


def _check(scene: str, kind: str) -> None:
    if scene not in DATASET_SCENES:
        raise ValueError(f"scene={scene!r}: datasets are made on the laryngoscope scenes {list(DATASET_SCENES)} "
                         "(on the ideal device the planning oracle solves each step in closed form)")
    if kind not in KINDS:
        raise ValueError(f"kind={kind!r}: valid dataset kinds are {list(KINDS)}")


# -- demonstrators: who acts in an episode ----------------------------------------------------------

class Demonstrator(Protocol):
    """Acts in one episode at a time: :meth:`begin` with the episode's seed before its reset, then
    :meth:`act` every step (it may read the env, as a hand on the device feels where it is)."""

    name: str

    def begin(self, seed: int) -> None: ...

    def act(self, env: Any, obs: np.ndarray) -> np.ndarray: ...


class PolicyDemonstrator:
    """A benchmark policy (batched ``predict``), one row at a time."""

    def __init__(self, make: Callable[[int], Policy], name: str) -> None:
        self.make, self.name = make, name
        self.policy: Policy | None = None

    def begin(self, seed: int) -> None:
        self.policy = self.make(seed)
        self.policy.reset()

    def act(self, env: Any, obs: np.ndarray) -> np.ndarray:
        assert self.policy is not None, "begin() first"
        return np.asarray(self.policy.predict(obs[None]), dtype=np.float32)[0]


class TraineeDemonstrator:
    """A synthetic trainee: the expert's hand path on this episode's target, degraded by ``amounts``
    (:func:`softenv.training.trainee.degrade`, its tremor drawn from the episode's seed), followed by
    steering the hand toward each next pose, as a replayed device log is."""

    def __init__(self, scene: str, amounts: dict[str, float], name: str) -> None:
        self.scene, self.amounts, self.name = scene, amounts, name
        self.config = haptic_config(_sections(scene))          # made once for every episode's degraded path
        self._poses, self._t = np.zeros((1, 4)), 0

    def begin(self, seed: int) -> None:
        env: Any = make_env(self.scene).unwrapped
        expert = make_baseline("expert", env.world)
        expert.reset()
        obs, _ = env.reset(seed=seed)
        poses, done = [relative_hand_pose(env)], False
        while not done:
            obs, _, terminated, truncated, _ = env.step(np.asarray(expert.predict(obs[None]), np.float32)[0])
            poses.append(relative_hand_pose(env))
            done = terminated or truncated
        dt = env.world.config["dynamics"]["dt"]
        log = np.column_stack([np.arange(len(poses)) * dt, np.array(poses)])
        self._poses = degrade(log, self.config, seed=seed, **self.amounts)[:, 1:]
        self._t = 0

    def act(self, env: Any, obs: np.ndarray) -> np.ndarray:
        self._t += 1
        return action_toward(env, self._poses[min(self._t, len(self._poses) - 1)])


class Cycle:
    """Episode ``i`` by demonstrator ``i mod n`` (the mixed dataset)."""

    def __init__(self, demonstrators: list[Demonstrator], name: str) -> None:
        self.demonstrators, self.name = demonstrators, name
        self._order = 0
        self.current: Demonstrator = demonstrators[0]

    def begin(self, seed: int) -> None:
        self.current = self.demonstrators[self._order % len(self.demonstrators)]
        self._order += 1
        self.current.begin(seed)

    def act(self, env: Any, obs: np.ndarray) -> np.ndarray:
        return self.current.act(env, obs)


def _sections(scene: str) -> dict[str, Any]:
    """The scene's config sections on its training targets (what a hand log's scene is)."""
    _, kwargs = scene_kwargs(scene, split=TRAIN_SPLIT)
    kwargs.pop("obs_mode")
    return kwargs


def simulator_digest(scene: str) -> str:
    """:func:`~baselines.fingerprint.rollout_digest` of the scene's numpy twin (batched, bit for bit the
    single env a dataset is recorded in): a dataset records it, and is made again when it changes."""
    def numpy_twin(split: str) -> Any:
        env_id, kwargs = scene_kwargs(scene, split=split)
        return gym.make_vec(env_id, num_envs=PROBE_ENVS, vectorization_mode="vector_entry_point", **kwargs)

    return rollout_digest(numpy_twin, probe_steps(scene_kwargs(scene)[1]))


def make_env(scene: str, split: str = TRAIN_SPLIT) -> gym.Env:
    """The single env a dataset of ``scene`` is recorded in (training targets), or evaluated in (``split="test"``)."""
    env_id, kwargs = scene_kwargs(scene, split=split)
    return gym.make(env_id, **kwargs)


def trainee_amounts(scene: str) -> dict[str, dict[str, float]]:
    """The published profiles' error amounts (:mod:`softenv.training.profiles`, found at the family's
    centre on the scene's hand scene), by profile name."""
    config = haptic_config(_sections(scene))
    log = expert_hand_log(config)
    expert = replay_hand(log, config)
    out: dict[str, dict[str, float]] = {"expert": {}}
    for name, study, time_ratio, force_ratio, path_ratio in profiles.PROFILES:
        if name in ("intermediate", "novice"):
            out[name] = profiles.build(name, study, (time_ratio, force_ratio, path_ratio), log, expert, config).amounts
    return out


@dataclass
class Source:
    """Who makes a dataset's episodes, and what the metadata says of them."""

    demonstrator: Demonstrator
    algorithm: str
    details: dict[str, Any]


def source(scene: str, kind: str, seeds: list[int], runs_dir: Path, agent_steps: int | None = None,
           echo: Callable[[str], None] = print) -> Source:
    """The demonstrator of ``kind`` on ``scene`` for the episodes seeded ``seeds`` (the oracle plans them
    here; the agent is trained into ``runs_dir`` for ``agent_steps``, default its YAML budget, or read
    back from it)."""
    _check(scene, kind)
    world = World(make_config(**_sections(scene)))
    if kind == "expert":
        return Source(PolicyDemonstrator(lambda seed: make_baseline("expert", world), "expert"),
                      "scripted expert (the device model inverted)", {})
    if kind == "random":
        return Source(PolicyDemonstrator(lambda seed: RandomPolicy(world, seed), "random"),
                      "uniform random actions (seeded by the episode)", {})
    if kind == "oracle":
        planner = TrajectoryOracle(scene)
        echo(f"{dataset_id(scene, kind)}: planning {len(seeds)} episodes with the trajectory oracle")
        planner.plan(make_baseline("expert", world), len(seeds), list(seeds), task={"split": TRAIN_SPLIT})
        plans = dict(zip(seeds, planner.actions))
        return Source(PolicyDemonstrator(lambda seed: ReplayPolicy(plans[seed][None], "oracle"), "oracle"),
                      f"trajectory oracle v{TrajectoryOracle.VERSION} (CEM through the device)",
                      {"oracle": oracle_of(scene)})
    if kind in ("novice", "mixed"):
        amounts = trainee_amounts(scene)
        names = MIXED if kind == "mixed" else ("novice",)
        demonstrators: list[Demonstrator] = [
            PolicyDemonstrator(lambda seed: make_baseline("expert", world), name) if name == "expert"
            else TraineeDemonstrator(scene, amounts[name], name) for name in names]
        what = "expert, intermediate and novice in turn" if kind == "mixed" else "the novice profile"
        return Source(demonstrators[0] if len(demonstrators) == 1 else Cycle(demonstrators, kind),
                      f"synthetic trainees: {what} (published profiles)",
                      {"profiles": {name: amounts[name] for name in names}})
    agent_steps = agent_steps or int(hyperparams(AGENT, scene_kwargs(scene)[0])["n_timesteps"])
    run_dir = runs_dir / scene / f"{AGENT}-{agent_steps}-0"
    echo(f"{dataset_id(scene, kind)}: the {AGENT} agent ({agent_steps:,} steps, seed 0) from {run_dir}")
    agent = load_agent(train_agent(AGENT, scene, 0, run_dir, agent_steps, progress=False), scene)
    return Source(PolicyDemonstrator(lambda seed: agent, AGENT),
                  f"stable-baselines3 {AGENT.upper()}, {agent_steps:,} steps, seed 0, deterministic rollouts",
                  {"agent": AGENT, "agent_steps": agent_steps, "agent_seed": 0})


# -- references: where Minari's normalized score puts 0 and 1 ---------------------------------------

def reference_returns(scene: str, episodes: int = REFERENCE_EPISODES) -> tuple[float, float]:
    """Mean return of no force and of the trajectory oracle on the protocol's first ``episodes`` test
    episodes (cached: the oracle plans every episode)."""
    seeds = episode_seeds(episodes)

    def build() -> tuple[float, float]:
        world = World(scene_config(scene))
        zero = evaluate(ZeroPolicy(world), scene, episodes, seeds).values["return"]
        _, _, planned = compute_anchors(scene, seeds)            # the oracle the anchors plan, with its episodes
        assert planned is not None, "a laryngoscope scene's oracle plans"
        return float(zero.mean()), float(planned.values["return"].mean())

    def load(path: Path) -> tuple[float, float]:
        with np.load(path, allow_pickle=False) as data:
            return float(data["zero"]), float(data["oracle"])

    return cached("references", {"scene": scene, "config": scene_config(scene), "seeds": seeds,
                                 "oracle": TrajectoryOracle.VERSION}, build, load,
                  lambda value, path: np.savez(path, zero=value[0], oracle=value[1]))


# -- making and reading -----------------------------------------------------------------------------

def make_dataset(scene: str, kind: str, episodes: int = 100, runs_dir: str | Path = "runs",
                 agent_steps: int | None = None, reference_episodes: int = REFERENCE_EPISODES,
                 echo: Callable[[str], None] = print, show_progress: bool = True) -> Any:
    """Record ``episodes`` episodes of ``kind`` on ``scene`` into Minari's local store (replacing a
    dataset of the same id) and return the :class:`minari.MinariDataset`."""
    import minari                                           # the offline extra

    episodes = check_int(episodes, "episodes", 1, 100_000)
    reference_episodes = check_int(reference_episodes, "reference_episodes", 1, EPISODES)
    name = dataset_id(scene, kind)
    seeds = list(range(episodes))
    started = time.perf_counter()
    src = source(scene, kind, seeds, Path(runs_dir), agent_steps, echo)
    zero, oracle = reference_returns(scene, reference_episodes)
    env = minari.DataCollector(make_env(scene), record_infos=False)
    clinical: dict[str, list[float]] = {}
    returns = []
    for seed in progress(seeds, name, enabled=show_progress):
        src.demonstrator.begin(seed)
        obs, _ = env.reset(seed=seed)
        done, total = False, 0.0
        while not done:
            obs, reward, terminated, truncated, info = env.step(src.demonstrator.act(env.unwrapped, obs))
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
        for key, value in info["clinical"].items():
            clinical.setdefault(key, []).append(float(value))
    if name in minari.list_local_datasets():
        minari.delete_dataset(name)
    with warnings.catch_warnings():              # Minari asks for an author's email address; softenv has none to give
        warnings.filterwarnings("ignore", message=".*author_email.*")
        dataset = env.create_dataset(
            dataset_id=name, eval_env=make_env(scene, "test").spec, algorithm_name=src.algorithm, author="softenv",
            code_permalink="softenv/baselines/minari_datasets.py",
            ref_min_score=zero, ref_max_score=oracle, requirements=[f"softenv=={softenv.__version__}"],
            description=f"{src.algorithm} on {scene}'s training targets, episode i seeded i; reference scores: mean return "
                        f"of no force (0) and of the trajectory oracle (1) over the benchmark's first {reference_episodes} "
                        "test episodes")
    env.close()
    dataset.storage.update_metadata({"softenv": json.dumps({
        "format_version": VERSION, "scene": scene, "kind": kind, "demonstrator": src.algorithm, **src.details,
        "scene_config": make_config(**_sections(scene)), "dynamics": simulator_digest(scene), "episodes": episodes, "seeds": seeds,
        "reference_episodes": reference_episodes, "returns": returns, "clinical": clinical,
        "softenv": softenv.__version__, "commit": code_revision(), "seconds": time.perf_counter() - started})})
    return minari.load_dataset(name)


def size_bytes(dataset: Any) -> int:
    """The dataset's size on disk."""
    return sum(f.stat().st_size for f in Path(dataset.spec.data_path).rglob("*") if f.is_file())


def softenv_metadata(dataset: Any) -> dict[str, Any]:
    """What softenv records of a dataset (see :func:`make_dataset`); a dataset softenv did not make, or
    made under another version, is refused."""
    raw = dataset.storage.metadata.get("softenv")
    if raw is None:
        raise ValueError(f"dataset {dataset.spec.dataset_id!r} records no softenv metadata (softenv did not make it)")
    meta = json.loads(raw)
    if meta.get("format_version") != VERSION:
        raise ValueError(f"dataset {dataset.spec.dataset_id!r}: format_version={meta.get('format_version')!r}; this "
                         f"softenv reads {VERSION} (make it again: softenv datasets make)")
    return dict(meta)


def load_or_make(scene: str, kind: str, episodes: int = 100, runs_dir: str | Path = "runs",
                 echo: Callable[[str], None] | None = None, reference_episodes: int | None = None) -> Any:
    """The dataset from Minari's local store when it holds ``episodes`` episodes made by this softenv's
    version of it on this simulator (:func:`simulator_digest`; and, where given, its references average
    ``reference_episodes`` test episodes), else
    made now, saying so in one line (its references over ``reference_episodes``, default the protocol's)."""
    import minari                                           # the offline extra

    say = echo if echo is not None else (lambda line: print(line, file=sys.stderr))
    name = dataset_id(scene, kind)
    if name in minari.list_local_datasets():
        dataset = minari.load_dataset(name)
        try:
            meta = softenv_metadata(dataset)
            if meta["episodes"] != episodes:
                why = f"it holds {meta['episodes']} episodes, not {episodes}"
            elif reference_episodes not in (None, meta["reference_episodes"]):
                why = f"its references average {meta['reference_episodes']} test episodes, not {reference_episodes}"
            elif meta.get("dynamics") != simulator_digest(scene):
                why = "it was recorded on another simulator"
            else:
                return dataset
        except ValueError as exc:
            why = str(exc)
        say(f"{name}: remade ({why})")
    else:
        say(f"{name}: not in Minari's local store; making it")
    return make_dataset(scene, kind, episodes, runs_dir, reference_episodes=reference_episodes or REFERENCE_EPISODES,
                        echo=say, show_progress=False)
