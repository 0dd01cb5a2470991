"""The public evaluation API (softenv.evaluation) and the shipped anchors it scales by."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from softenv import stats
from softenv.baselines import anchors as anchors_module
from softenv.baselines.anchors import compute_anchors, load_anchors, read_anchors, scene_config
from softenv.baselines.evaluate import GRADED_SCENES, SCENES, device_kind, episode_seeds, evaluate, normalized_scores
from softenv.baselines.policies import RandomPolicy, SB3Policy, ZeroPolicy
from softenv.envs.world import World
from softenv.evaluation import Evaluation, aggregate, evaluate_policy

# a sample of each scene's shipped episodes, recomputed: (scene, seeds); the laryngoscope's take half a minute
# each, so of the graded airways the normal one and the one with every setting changed
SAMPLE = [(scene, [1000, 1063]) for scene in SCENES if device_kind(scene) == "ideal"] + \
         [("SoftSphereHaptic-v0", [1037]), ("SoftSphereHapticProcedure-v0", [1081])] + \
         [(GRADED_SCENES[grade], [1000 + 23 * grade]) for grade in (1, 4)]


@pytest.mark.slow
@pytest.mark.parametrize("scene, seeds", SAMPLE)
def test_shipped_anchors_are_what_the_scene_computes(scene, seeds):
    shipped = load_anchors(scene, seeds, echo=pytest.fail)          # every benchmark scene ships all 100 episodes
    assert shipped.source.endswith(".json")
    zero, oracle, _ = compute_anchors(scene, seeds)
    np.testing.assert_allclose(shipped.zero, zero, rtol=1e-9)
    np.testing.assert_allclose(shipped.oracle, oracle, rtol=1e-6, atol=1e-9)
    assert (shipped.oracle < shipped.zero).all()


def test_another_scenes_file_is_never_used(tmp_path, monkeypatch):
    """The stiffening scene's file replaced by the linear one's: refused by its scene hash, the anchors computed
    (and cached, one line) instead; a damaged shipped file is refused by name."""
    linear_file = anchors_module.anchors_file("SoftSphere-v0")
    monkeypatch.setattr(anchors_module, "SHIPPED", tmp_path)
    shutil.copy(linear_file, tmp_path / "SoftSphere-v0_stiffening.json")
    said: list[str] = []
    got = load_anchors("SoftSphere-v0/stiffening", [1000, 1001], echo=said.append)
    assert len(said) == 1 and "made for another scene 'SoftSphere-v0'" in said[0] and "scene_hash" in said[0]
    shutil.copy(linear_file, tmp_path / "SoftSphere-v0.json")
    linear = load_anchors("SoftSphere-v0", [1000, 1001], echo=pytest.fail)
    assert not np.allclose(got.zero, linear.zero)
    np.testing.assert_array_equal(got.zero, compute_anchors("SoftSphere-v0/stiffening", [1000, 1001])[0])
    again = load_anchors("SoftSphere-v0/stiffening", [1001, 1000], echo=pytest.fail)      # from the cache now
    np.testing.assert_array_equal(again.zero, got.zero[::-1])
    (tmp_path / "SoftSphere-v0.json").write_text("{not json")
    with pytest.raises(ValueError, match="anchor file .*SoftSphere-v0.json.* is not usable"):
        load_anchors("SoftSphere-v0", [1000])
    record = json.loads(linear_file.read_text())
    (tmp_path / "SoftSphere-v0.json").write_text(json.dumps({**record, "zero": record["zero"][:3]}))
    with pytest.raises(ValueError, match="100 seeds, 3 zero"):
        read_anchors(tmp_path / "SoftSphere-v0.json", "SoftSphere-v0")


def test_the_anchors_script_resumes_a_stopped_run_to_the_shipped_numbers(tmp_path):
    """``scripts/make_anchors.py --runs``: 12 episodes as two jobs (10 and 2), one of them kept in the
    run store and the other lost; the second run takes the kept one from the store, runs the other, and
    both runs write the shipped anchors of those episodes."""
    script = Path(__file__).parent.parent / "scripts" / "make_anchors.py"

    def run(out: str) -> str:
        done = subprocess.run([sys.executable, str(script), "--scenes", "SoftSphere-v0", "--episodes", "12", "--jobs",
                               "1", "--runs", str(tmp_path / "runs"), "--out", str(tmp_path / out)],
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-3000:]
        return done.stdout

    assert "resuming" not in run("first")
    entries = sorted((tmp_path / "runs" / "jobs").iterdir())
    assert len(entries) == 2
    entries[1].unlink()
    assert "resuming: 1 of 2 jobs" in run("second")
    first, second = (json.loads((tmp_path / out / "SoftSphere-v0.json").read_text()) for out in ("first", "second"))
    shipped = json.loads(anchors_module.anchors_file("SoftSphere-v0").read_text())
    for record in (first, second):
        assert record["seeds"] == episode_seeds(12)
        assert record["zero"] == shipped["zero"][:12] and record["oracle_error_sum"] == shipped["oracle_error_sum"][:12]


@pytest.fixture(scope="module")
def haptic_world() -> World:
    return World(scene_config("SoftSphereHaptic-v0"))


def test_no_force_scores_zero_on_every_shipped_episode(haptic_world):
    """The zero policy replays the anchors' own rollouts: 0 on every episode (to the last bits, which another
    CPU's BLAS kernels may move)."""
    result = evaluate_policy(ZeroPolicy(haptic_world), "SoftSphereHaptic-v0", 100, echo=pytest.fail)
    assert result.normalized_score.shape == (1, 100)
    np.testing.assert_allclose(result.normalized_score, 0.0, atol=1e-9)
    np.testing.assert_allclose(result.score, 0.0, atol=1e-9)
    assert set(result.metrics) >= {"final_error_mm", "success", "peak_incisor_force_N", "lever_share"}


def test_a_callable_an_object_and_runs(haptic_world):
    """A batched callable scores as the policy object it wraps; a list of policies is one run each, its
    interval the two-level bootstrap of softenv.stats; the scores follow from the error sums and anchors."""
    zero = ZeroPolicy(haptic_world)
    as_callable = evaluate_policy(lambda obs: zero.predict(obs), "SoftSphereHaptic-v0", 8, name="zero")
    assert np.array_equal(as_callable.error_sum, evaluate_policy(zero, "SoftSphereHaptic-v0", 8).error_sum)
    runs = evaluate_policy([RandomPolicy(haptic_world, s) for s in (0, 1)], "SoftSphereHaptic-v0", 8, name="random")
    assert runs.normalized_score.shape == (2, 8) and runs.policy == "random"
    anchors = load_anchors("SoftSphereHaptic-v0", episode_seeds(8))
    np.testing.assert_array_equal(runs.normalized_score, normalized_scores(runs.error_sum, anchors.zero, anchors.oracle))
    assert runs.score == stats.nested_interval(runs.normalized_score)
    assert runs.per_run == pytest.approx(list(runs.normalized_score.mean(axis=1)))
    assert "random on SoftSphereHaptic-v0: normalized score" in str(runs)
    both = aggregate([runs, runs])
    matrix = np.stack([runs.normalized_score.mean(axis=1)] * 2, axis=1)
    assert both == stats.interval_estimates(matrix)


def test_an_sb3_model_scores_as_the_benchmark_scores_it():
    sb3 = pytest.importorskip("stable_baselines3")
    import torch

    from softenv.envs.sb3 import SoftSphereSB3VecEnv

    torch.set_num_threads(1)
    model = sb3.PPO("MlpPolicy", SoftSphereSB3VecEnv(4, "SoftSphere-v0"), n_steps=16, batch_size=64, seed=0,
                    device="cpu")
    model.learn(64)
    result = evaluate_policy(model, "SoftSphere-v0", 10)
    assert result.policy == "ppo"
    direct = evaluate(SB3Policy(model, "ppo"), "SoftSphere-v0", 10)
    np.testing.assert_array_equal(result.error_sum[0], direct.values["error_sum_mm"])


def test_bad_input_is_refused_by_name(haptic_world):
    with pytest.raises(ValueError, match="scene='SoftCube-v0' is not a benchmark scene; valid scenes"):
        evaluate_policy(lambda obs: obs, "SoftCube-v0")
    with pytest.raises(ValueError, match=r"episodes=0 must be an int in \[1, 100000\]"):
        evaluate_policy(lambda obs: obs, "SoftSphere-v0", 0)
    with pytest.raises(ValueError, match="policy=None is neither"):
        evaluate_policy(None, "SoftSphere-v0", 2)
    with pytest.raises(ValueError, match="policy=\\[\\]"):
        evaluate_policy([], "SoftSphere-v0", 2)
    with pytest.raises(ValueError, match=r"returned actions of shape \(3,\) for a batch of 2 observations; expected \(2, 4\)"):
        evaluate_policy(lambda obs: np.zeros(3), "SoftSphere-v0", 2, name="short")
    with pytest.raises(ValueError, match=r"actions\[0, 0\] = 2.0: actions must be finite and within \[-1, 1\]"):
        evaluate_policy(lambda obs: np.full((len(obs), 4), 2.0), "SoftSphere-v0", 2)
    with pytest.raises(ValueError, match="same number of runs"):
        one = Evaluation("a", "SoftSphere-v0", [1000], np.zeros((1, 1)), np.zeros((1, 1)), {}, None, 0.0, "")  # type: ignore[arg-type]
        two = Evaluation("a", "SoftSphere-v0", [1000], np.zeros((2, 1)), np.zeros((2, 1)), {}, None, 0.0, "")  # type: ignore[arg-type]
        aggregate([one, two])
