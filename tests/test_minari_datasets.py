"""The Minari datasets: made through Minari's DataCollector, loaded through its public API, replayed bit
for bit from their seeds, and normalized with the benchmark's reference policies."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

minari = pytest.importorskip("minari")           # the offline extra (in dev: CI runs these)

from softenv.baselines import minari_datasets as md  # noqa: E402
from softenv.baselines.evaluate import episode_seeds  # noqa: E402
from softenv.cli import main  # noqa: E402

SCENE = "SoftSphereHaptic-v0"
EPISODES, REFERENCES = 3, 1        # one reference episode: the oracle plans it (a minute on a slow host)


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """Minari's local store, in a folder of this module's own."""
    path = tmp_path_factory.mktemp("minari")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("MINARI_DATASETS_PATH", str(path))
        yield path


@pytest.fixture(scope="module")
def made(store: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    runs = tmp_path_factory.mktemp("runs")
    return {kind: md.make_dataset(SCENE, kind, EPISODES, runs, agent_steps=2048, reference_episodes=REFERENCES,
                                  echo=lambda line: None, show_progress=False) for kind in md.KINDS}


@pytest.mark.slow
def test_every_kind_loads_through_minari_by_its_versioned_id(made: dict[str, Any]) -> None:
    assert {name for name in minari.list_local_datasets() if name.startswith("softenv/")} == \
        {f"softenv/{SCENE}/{kind}-v0" for kind in md.KINDS}
    for kind in md.KINDS:
        dataset = minari.load_dataset(md.dataset_id(SCENE, kind))
        assert dataset.total_episodes == EPISODES and dataset.total_steps == EPISODES * 250
        meta = md.softenv_metadata(dataset)
        assert meta["scene"] == SCENE and meta["kind"] == kind and meta["seeds"] == list(range(EPISODES))
        assert meta["scene_config"]["task"]["split"] == "train"
        assert set(meta["clinical"]) >= {"peak_tongue_force_N", "peak_incisor_force_N", "glottic_view_pct"}
        assert all(len(v) == EPISODES for v in meta["clinical"].values())
        assert [int(m["seed"]) for m in dataset.storage.get_episode_metadata(range(EPISODES))] == list(range(EPISODES))
        returns = [float(np.sum(e.rewards)) for e in dataset.iterate_episodes()]
        np.testing.assert_allclose(returns, meta["returns"], rtol=1e-12)


def test_recovered_envs_are_the_training_and_test_splits(made: dict[str, Any]) -> None:
    dataset = made["expert"]
    assert dataset.recover_environment().unwrapped.world.config["task"]["split"] == "train"
    assert dataset.recover_environment(eval_env=True).unwrapped.world.config["task"]["split"] == "test"


@pytest.mark.parametrize("kind", md.KINDS)
def test_episodes_replay_bit_for_bit_from_their_seeds(made: dict[str, Any], kind: str) -> None:
    dataset = made[kind]
    env = dataset.recover_environment()
    seeds = [int(m["seed"]) for m in dataset.storage.get_episode_metadata(range(EPISODES))]
    for seed, episode in zip(seeds, dataset.iterate_episodes()):
        obs, _ = env.reset(seed=seed)
        observations, rewards = [obs], []
        for action in episode.actions:
            obs, reward, terminated, truncated, _ = env.step(action)
            observations.append(obs)
            rewards.append(reward)
        assert np.array_equal(np.array(observations), episode.observations)
        assert np.array_equal(np.array(rewards), episode.rewards)
        assert truncated and bool(episode.truncations[-1])


def test_minari_normalizes_with_the_benchmarks_reference_policies(made: dict[str, Any]) -> None:
    """ref_min_score is the no-force policy's mean return on the protocol's test episodes: summed here
    again, in single envs, from the scene's own zero action."""
    dataset = made["expert"]
    env = dataset.recover_environment(eval_env=True)
    returns = []
    for seed in episode_seeds(REFERENCES):
        env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            _, reward, terminated, truncated, _ = env.step(np.zeros(4, dtype=np.float32))   # the hand held still
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
    zero, oracle = dataset.storage.metadata["ref_min_score"], dataset.storage.metadata["ref_max_score"]
    assert zero == pytest.approx(np.mean(returns), rel=1e-12)
    assert oracle > zero
    normalized = minari.get_normalized_score(dataset, np.array([zero, oracle, 0.5 * (zero + oracle)]))
    np.testing.assert_allclose(normalized, [0.0, 1.0, 0.5])
    scores = {kind: float(minari.get_normalized_score(made[kind], np.array(md.softenv_metadata(made[kind])["returns"])).mean())
              for kind in ("expert", "random", "novice")}
    assert scores["expert"] > scores["novice"] > scores["random"], scores


def test_mixed_cycles_expert_intermediate_novice_on_the_same_seeds(made: dict[str, Any]) -> None:
    mixed = list(made["mixed"].iterate_episodes())
    expert = list(made["expert"].iterate_episodes())
    novice = list(made["novice"].iterate_episodes())
    assert np.array_equal(mixed[0].actions, expert[0].actions)           # episode 0: the expert, seed 0
    assert np.array_equal(mixed[2].actions, novice[2].actions)           # episode 2: the novice, seed 2
    assert not np.array_equal(mixed[1].actions, expert[1].actions)       # episode 1: the intermediate trainee
    assert set(md.softenv_metadata(made["mixed"])["profiles"]) == set(md.MIXED)


def test_the_ppo_dataset_names_its_agent(made: dict[str, Any]) -> None:
    meta = md.softenv_metadata(made["ppo"])
    assert (meta["agent"], meta["agent_steps"], meta["agent_seed"]) == ("ppo", 2048, 0)
    assert "PPO, 2,048 steps" in made["ppo"].storage.metadata["algorithm_name"]


def test_load_or_make_reads_a_match_and_remakes_a_mismatch(made: dict[str, Any], tmp_path: Path) -> None:
    lines: list[str] = []
    same = md.load_or_make(SCENE, "random", EPISODES, tmp_path, lines.append, reference_episodes=REFERENCES)
    assert lines == [] and md.softenv_metadata(same)["returns"] == md.softenv_metadata(made["random"])["returns"]
    more = md.load_or_make(SCENE, "random", EPISODES + 1, tmp_path, lines.append, reference_episodes=REFERENCES)
    assert lines == [f"softenv/{SCENE}/random-v0: remade (it holds {EPISODES} episodes, not {EPISODES + 1})"]
    assert more.total_episodes == EPISODES + 1
    # the first episodes are the same episodes: each is seeded by its index alone
    assert np.array_equal(next(more.iterate_episodes()).actions, next(made["random"].iterate_episodes()).actions)
    raw = json.loads(more.storage.metadata["softenv"])
    more.storage.update_metadata({"softenv": json.dumps({**raw, "dynamics": "0" * 64})})
    lines.clear()
    again = md.load_or_make(SCENE, "random", EPISODES + 1, tmp_path, lines.append, reference_episodes=REFERENCES)
    assert lines == [f"softenv/{SCENE}/random-v0: remade (it was recorded on another simulator)"]
    assert md.softenv_metadata(again)["dynamics"] == md.simulator_digest(SCENE) == raw["dynamics"]


@pytest.mark.parametrize(("scene", "kind", "named"), [("SoftSphere-v0", "expert", "scene='SoftSphere-v0'"),
                                                       (SCENE, "medium", "kind='medium'")])
def test_bad_ids_are_refused_naming_the_argument(scene: str, kind: str, named: str) -> None:
    with pytest.raises(ValueError, match=named):
        md.dataset_id(scene, kind)


def test_bad_episode_counts_and_foreign_datasets_are_refused(made: dict[str, Any], store: Path) -> None:
    with pytest.raises(ValueError, match=r"episodes=0 is out of range; allowed range \[1, 100000\]"):
        md.make_dataset(SCENE, "expert", 0)
    with pytest.raises(ValueError, match=r"reference_episodes=101 is out of range; allowed range \[1, 100\]"):
        md.make_dataset(SCENE, "expert", 1, reference_episodes=101)
    dataset = made["random"]
    raw = json.loads(dataset.storage.metadata["softenv"])
    dataset.storage.update_metadata({"softenv": json.dumps({**raw, "format_version": 99})})
    try:
        with pytest.raises(ValueError, match="format_version=99"):
            md.softenv_metadata(minari.load_dataset(md.dataset_id(SCENE, "random")))
    finally:
        dataset.storage.update_metadata({"softenv": json.dumps(raw)})


def test_cli_makes_and_lists(store: Path, made: dict[str, Any], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["datasets", "make", "--kinds", "random", "--episodes", "2", "--reference-episodes", "2"]) == 0
    out = capsys.readouterr().out
    assert "softenv/SoftSphereHaptic-v0/random-v0: 2 episodes, 500 steps" in out
    assert main(["datasets", "list"]) == 0
    listed = capsys.readouterr().out
    assert "softenv/SoftSphereHaptic-v0/random-v0: 2 episodes" in listed and "expert-v0: 3 episodes" in listed
    assert main(["datasets", "make", "--kinds", "nonsense"]) == 2
