"""The offline learners (BC and TD3+BC from TorchRL's losses): their data, that they learn, that they are
reproducible, that their files load safely, and that softenv compare runs them."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

minari = pytest.importorskip("minari")           # the offline extra (in dev: CI runs these)
torch = pytest.importorskip("torchrl") and pytest.importorskip("torch")

from softenv.baselines import benchmark, offline  # noqa: E402
from softenv.baselines import minari_datasets as md  # noqa: E402

SCENE = "SoftSphereHaptic-v0"


@pytest.fixture(scope="module")
def expert(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("MINARI_DATASETS_PATH", str(tmp_path_factory.mktemp("minari")))
        yield md.make_dataset(SCENE, "expert", 4, reference_episodes=2, echo=lambda line: None, show_progress=False)


def test_transitions_follow_the_episodes(expert: Any) -> None:
    data = offline.transitions(expert)
    episodes = list(expert.iterate_episodes())
    assert len(data) == sum(len(e.actions) for e in episodes) == 1000
    first = episodes[0]
    np.testing.assert_array_equal(data["observation"][:250].numpy(), first.observations[:-1])
    np.testing.assert_array_equal(data["next", "observation"][:250].numpy(), first.observations[1:])
    np.testing.assert_array_equal(data["action"][:250].numpy(), first.actions)
    done = data["next", "done"][:, 0].numpy()
    assert np.flatnonzero(done).tolist() == [249, 499, 749, 999]         # truncated at each episode's end
    assert not data["next", "terminated"].any()


def _actions(actor: Any, obs: np.ndarray) -> np.ndarray:
    return offline.OfflinePolicy(actor, "probe").predict(obs)


def test_bc_imitates_the_expert_better_than_its_untrained_net(expert: Any) -> None:
    data = offline.transitions(expert)
    obs, target = data["observation"].numpy(), data["action"].numpy()
    torch.manual_seed(0)
    untrained = offline.make_actor(obs.shape[1], 4, 256)
    actor = offline.train(expert, offline.OfflineArgs(method="bc", steps=600), seed=0, log=lambda line: None)
    before = float(np.mean((_actions(untrained, obs) - target) ** 2))
    after = float(np.mean((_actions(actor, obs) - target) ** 2))
    assert after < 0.2 * before, (before, after)


@pytest.mark.parametrize("method", offline.METHODS)
def test_training_is_reproducible_from_its_seed(expert: Any, method: str) -> None:
    args = offline.OfflineArgs(method=method, steps=30)
    obs = offline.transitions(expert)["observation"][:64].numpy()
    a = _actions(offline.train(expert, args, seed=3, log=lambda line: None), obs)
    b = _actions(offline.train(expert, args, seed=3, log=lambda line: None), obs)
    c = _actions(offline.train(expert, args, seed=4, log=lambda line: None), obs)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert np.all(np.abs(a) <= 1.0)


def test_saved_actors_load_with_weights_only_and_check_what_they_are(expert: Any, tmp_path: Path) -> None:
    args = offline.OfflineArgs(method="td3bc", steps=10)
    actor = offline.train(expert, args, seed=0, log=lambda line: None)
    path = tmp_path / "actor.pt"
    meta = {"scene": SCENE, "dataset": md.dataset_id(SCENE, "expert"), "seed": 0}
    offline.save(actor, args, meta, path)
    loaded, record = offline.load(path, meta)
    obs = offline.transitions(expert)["observation"][:8].numpy()
    assert np.array_equal(_actions(loaded, obs), _actions(actor, obs)) and record["args"]["method"] == "td3bc"
    with pytest.raises(ValueError, match="scene='SoftSphereHaptic-v0', not 'SoftSphereHapticProcedure-v0'"):
        offline.load(path, {**meta, "scene": "SoftSphereHapticProcedure-v0"})
    path.write_bytes(b"not a torch file")
    with pytest.raises(ValueError, match="not a readable softenv offline model"):
        offline.load(path, meta)
    torch.save({"format": offline.MODEL_FORMAT, "format_version": 99}, path)
    with pytest.raises(ValueError, match="format_version=99"):
        offline.load(path, meta)


@pytest.mark.parametrize(("field", "value"), [("method", "cql"), ("steps", 0), ("policy_delay", 1.5), ("lr", -0.001),
                                             ("gamma", 1.5), ("alpha", float("nan"))])
def test_bad_settings_are_refused_naming_them(expert: Any, field: str, value: Any) -> None:
    with pytest.raises(ValueError, match=f"{field}.*{value}"):
        offline.train(expert, offline.OfflineArgs(**{field: value}), seed=0)


def test_compare_offline_trains_evaluates_and_reports(expert: Any, tmp_path: Path) -> None:
    plan = benchmark.offline_plan()
    plan.agents, plan.baselines = ["bc-expert"], ["expert"]
    plan.seeds, plan.episodes, plan.dataset_episodes = {SCENE: 2}, 4, 4
    plan.timesteps = {"bc-expert": 50}
    lines: list[str] = []
    summaries = benchmark.run(plan, tmp_path / "out", tmp_path / "runs", "test", echo=lines.append,
                              stem="benchmark_offline")
    row = next(s for s in summaries if s["policy"] == "bc-expert")
    assert row["kind"] == "offline (50 gradient steps on expert-v0, 4 episodes)" and row["seeds"] == 2
    assert len(row["seed_scores"]) == 2 and row["seed_scores"][0] != row["seed_scores"][1]
    assert (tmp_path / "runs" / SCENE / "bc-expert-0" / "actor.pt").exists()
    assert (tmp_path / "out" / "benchmark_offline.md").exists()
    # a second run reads every job back from the run store
    again = benchmark.run(plan, tmp_path / "out", tmp_path / "runs", "test", echo=lines.append, write=False)
    assert [s["normalized_score"]["mean"] for s in again] == [s["normalized_score"]["mean"] for s in summaries]
