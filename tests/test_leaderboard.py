"""Leaderboard results: a file round-trips through check; tampered ones are refused, each in one line that
names what differs; softenv evaluate and softenv leaderboard on the command line."""

import json
import sys

import numpy as np
import pytest

from softenv import leaderboard
from softenv.baselines.anchors import load_anchors, scene_config
from softenv.baselines.evaluate import episode_seeds, normalized_scores
from softenv.baselines.policies import RandomPolicy
from softenv.cli import main
from softenv.envs.world import World
from softenv.evaluation import evaluate_policy, score_aggregates


@pytest.fixture(scope="module")
def record() -> dict:
    world = World(scene_config("SoftSphere-v0"))
    result = evaluate_policy([RandomPolicy(world, s) for s in (0, 1)], "SoftSphere-v0", name="random")
    return leaderboard.result_record(result, "baseline", "pytest", training_seeds=[0, 1])


def test_a_result_round_trips_through_check(record, tmp_path):
    path = leaderboard.save_result(record, tmp_path / "random.json")
    again = leaderboard.read_result(path)
    assert again == json.loads(json.dumps(record))
    got = leaderboard.check_result(again)
    assert got["mean"] == pytest.approx(record["aggregates"]["mean"], rel=1e-12)
    assert len(again["normalized_score"]) == 2 and len(again["normalized_score"][0]) == 100
    assert {"cpu", "numpy"} <= set(again["hardware"])
    assert leaderboard.load_results(tmp_path) == [again]


def tampered(record: dict, **changes) -> dict:
    out = json.loads(json.dumps(record))
    for key, value in changes.items():
        if value is None:
            del out[key]
        else:
            out[key] = value
    return out


def _scores_off(record: dict) -> dict:
    out = json.loads(json.dumps(record))
    out["normalized_score"][1][7] += 5.0
    return out


def _aggregate_off(record: dict) -> dict:
    out = json.loads(json.dumps(record))
    for run in out["normalized_score"]:         # scores and error sums consistent, the aggregate not
        run[3] += 0.0
    out["aggregates"]["iqm"] += 1.0
    return out


def _other_scene(record: dict) -> dict:
    """The scene renamed: its hash is the linear scene's, not the stiffening scene's."""
    return tampered(record, scene="SoftSphere-v0/stiffening")


def _other_anchors(record: dict) -> dict:
    """Scores rescaled by another scene's anchors, their aggregates consistent with them: the digest gives it away."""
    other = load_anchors("SoftSphere-v0/stiffening", episode_seeds())
    scores = normalized_scores(np.array(record["error_sum"]), other.zero, other.oracle)
    return tampered(record, normalized_score=scores.tolist(), aggregates=score_aggregates(scores),
                    anchors={**record["anchors"], "digest": other.digest()})


@pytest.mark.parametrize("make, match", [
    (lambda r: tampered(r, split="train"), "split 'train': results are made on the 'test' targets"),
    (_other_scene, "scene_hash '[0-9a-f]+' is not SoftSphere-v0/stiffening's .*another scene config"),
    (lambda r: tampered(r, scene_hash="ffffffffffffffff"), "scene_hash 'ffffffffffffffff' is not SoftSphere-v0's"),
    (_other_anchors, "anchors digest '[0-9a-f]{16}' is not SoftSphere-v0's shipped anchors' .*another scene's"),
    (_scores_off, "normalized_score of run 1, episode 7 is .*; its error sum with the shipped anchors gives"),
    (_aggregate_off, r"aggregates\['iqm'\] = .*, but the scores give"),
    (lambda r: tampered(r, hardware=None, command=None), "missing fields: command, hardware"),
    (lambda r: tampered(r, episodes=50), "episodes 50 with seeds 1000..1099; the protocol's are 100 episodes"),
    (lambda r: tampered(r, seeds=list(range(2000, 2100))), "seeds 2000..2099; the protocol's are 100 episodes seeded 1000..1099"),
    (lambda r: tampered(r, protocol=0), "protocol version 0; this softenv's is 1"),
    (lambda r: tampered(r, format_version=9), "format 'softenv-result' version 9"),
    (lambda r: tampered(r, episodes="100"), r"fields of the wrong type: episodes \(str, expected int\)"),
    (lambda r: tampered(r, training_seeds=[0]), "2 run\\(s\\) of scores for 1 training_seeds labels"),
    (lambda r: tampered(r, error_sum=[[1.0] * 100]), r"error_sum has shape \(1, 100\)"),
    (lambda r: tampered(r, scene="SoftCube-v0"), "scene 'SoftCube-v0' is not a benchmark scene"),
])
def test_tampered_results_are_refused_in_one_line(record, make, match):
    with pytest.raises(ValueError, match=match) as refused:
        leaderboard.check_result(make(record))
    assert "\n" not in str(refused.value)


def test_a_refused_result_is_not_written(record, tmp_path):
    with pytest.raises(ValueError, match="split"):
        leaderboard.save_result(tampered(record, split="train"), tmp_path / "x.json")
    assert not (tmp_path / "x.json").exists()


def test_the_table_ranks_by_mean(record):
    better = json.loads(json.dumps(record))
    better["method"] = "better"
    better["aggregates"]["mean"] = 99.0
    text = leaderboard.table([record, better], highlight="random")
    assert text.index("| 1 | better |") < text.index("| 2 | **random** |")


POLICY = """import numpy as np

def policy(obs):
    return np.zeros((len(obs), 4), np.float32)
"""


def test_the_command_line_evaluates_checks_and_shows(tmp_path, monkeypatch, capsys):
    (tmp_path / "my_policy.py").write_text(POLICY)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    assert main(["evaluate", "my_policy:policy", "--scene", "SoftSphere-v0", "--out", "mine.json"]) == 0
    out = capsys.readouterr().out
    assert "my_policy:policy on SoftSphere-v0: normalized score" in out and "wrote mine.json" in out
    assert main(["leaderboard", "check", "mine.json"]) == 0
    assert "mine.json: ok" in capsys.readouterr().out
    assert main(["leaderboard", "show", "mine.json", "--dir", str(tmp_path / "none")]) == 0
    assert "| 1 | **my_policy:policy** | submission |" in capsys.readouterr().out
    bad = json.loads((tmp_path / "mine.json").read_text())
    bad["split"] = "train"
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    assert main(["leaderboard", "check", "mine.json", "bad.json"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["softenv leaderboard: error: bad.json: split 'train': results are made on the 'test' targets, "
                   "never the ones agents train on"]
    for argv, match in [(["evaluate", "my_policy:nothing"], "my_policy has no attribute 'nothing'"),
                        (["evaluate", "no_such_module:policy"], "module 'no_such_module' does not import"),
                        (["evaluate", "my_policy"], "must be MODULE:ATTRIBUTE"),
                        (["evaluate", "my_policy:policy", "--episodes", "5", "--out", "x.json"], "takes the protocol's 100")]:
        assert main(argv) == 2
        assert match in capsys.readouterr().err
    assert not (tmp_path / "x.json").exists()


def test_the_shipped_leaderboard_checks():
    """Every result under results/leaderboard passes check (the docs page is built from them)."""
    from pathlib import Path

    folder = Path(__file__).resolve().parents[1] / "results" / "leaderboard"
    records = leaderboard.load_results(folder)
    assert {r["scene"] for r in records} >= {"SoftSphere-v0", "SoftSphereHaptic-v0"}
    assert all(np.isfinite(r["aggregates"]["mean"]) for r in records)


def synthetic(scenes: list[str]) -> list[dict]:
    """Two methods on every scene, two runs of five episodes each: a's runs at 80 + i and 90 + i (plus 0-4)
    on scene i, b's at 70 + i and 60 + i."""
    def runs(levels: tuple[float, float], i: int) -> list[list[float]]:
        return [[level + i + e for e in range(5)] for level in levels]
    return [{"scene": scene, "method": method, "normalized_score": runs(levels, i)}
            for i, scene in enumerate(scenes) for method, levels in (("a", (80.0, 90.0)), ("b", (70.0, 60.0)))]


def test_across_scenes_gives_each_method_its_scores_by_scene_and_the_table_their_intervals(record):
    """Methods are compared across the scenes of one device, each by its (runs, episodes) scores on every
    scene; a method missing a scene, or with another number of runs on one, is left out."""
    from softenv import stats

    scenes = leaderboard.scene_groups()["ideal"]
    records = synthetic(scenes)
    records.append({"scene": scenes[0], "method": "partial", "normalized_score": [[99.0] * 5]})
    scores = leaderboard.across_scenes(records, scenes)
    assert set(scores) == {"a", "b"}
    np.testing.assert_array_equal(scores["a"][2], [[82.0, 83, 84, 85, 86], [92.0, 93, 94, 95, 96]])
    text = leaderboard.aggregates_table(records, resamples=500)
    iqm = stats.interval_estimates(scores["a"], resamples=500)["iqm"]
    assert iqm[1] < iqm[0] < iqm[2]               # the episodes' spread shows, though each run is one number
    assert f"| a | 2 | {iqm[0]:.1f} [{iqm[1]:.1f}, {iqm[2]:.1f}] |" in text
    assert "P(a > method)" in text and "| b | 2 |" in text and "1.00 [1.00, 1.00] |" in text   # a beats b everywhere
    assert "partial" not in text


def test_the_aggregates_figure_is_drawn(record, tmp_path):
    pytest.importorskip("matplotlib")
    records = synthetic(leaderboard.scene_groups()["laryngoscope"]) + [record]
    path = leaderboard.aggregates_figure(records, tmp_path / "aggregates.png", resamples=200)
    assert path.stat().st_size > 10_000
    with pytest.raises(ValueError, match="no method has results on every scene"):
        leaderboard.aggregates_figure([], tmp_path / "none.png")


def test_a_reader_that_stops_early_is_no_error():
    """`softenv leaderboard show | true`: the reader is gone before the command writes (the pipe breaks on its
    first write, whatever the pipe's buffer holds), and the command exits 0, silently."""
    import subprocess
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    done = subprocess.run(["bash", "-o", "pipefail", "-c", f"{sys.executable} -m softenv leaderboard show | true"],
                          cwd=root, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stderr == ""
