"""Baseline policies, the evaluation protocol's statistics, agents' files and the compare report."""

import json

import numpy as np
import pytest

from softenv.baselines.agents import (AGENT_FORMAT_VERSION, ALGOS, _literal_dict, dynamics_digest, hyperparams, load_agent,
                                      recorded_train_seconds, train_agent)
from softenv.baselines.benchmark import (ERROR_FLOOR_MM, Plan, _error_plot, _gallery, agent_colours, format_seeds,
                                        run, seed_label)
from softenv.baselines.curves import learning_curve
from softenv.baselines.evaluate import SCENES, evaluate, scene_kwargs
from softenv.baselines.policies import BASELINES, InversionPolicy, PlanningOracle, applies, make_baseline
from softenv.devices.laryngoscope.control import HandController
from softenv.envs.config import make_config
from softenv.envs.world import World


@pytest.fixture(scope="module")
def world() -> World:
    kwargs = scene_kwargs("SoftSphere-v0")[1]
    kwargs.pop("obs_mode")
    return World(make_config(**kwargs))


@pytest.fixture(scope="module")
def haptic_world() -> World:
    kwargs = scene_kwargs("SoftSphereHaptic-v0")[1]
    kwargs.pop("obs_mode")
    return World(make_config(**kwargs))


def test_oracle_reaches_every_test_target_at_once_and_zero_scores_nothing(world):
    oracle = evaluate(make_baseline("oracle", world), "SoftSphere-v0", episodes=20)
    zero = evaluate(make_baseline("zero", world), "SoftSphere-v0", episodes=20)
    assert oracle.values["success"].all() and (oracle.values["steps_to_success"] == 1).all()
    assert oracle.values["final_error_mm"].max() < 1e-3
    np.testing.assert_allclose(oracle.values["normalized_score"], 100.0, atol=1e-6)
    np.testing.assert_allclose(zero.values["normalized_score"], 0.0, atol=1e-9)
    assert not zero.values["success"].any()


def test_better_regressors_make_better_policies(world):
    scores = {name: evaluate(make_baseline(name, world), "SoftSphere-v0", episodes=20).values["final_error_mm"].mean()
              for name in ("zero", "invert-poly1", "invert-poly3")}
    assert scores["invert-poly3"] < scores["invert-poly1"] < scores["zero"]


def test_inversion_recovers_the_least_squares_force_of_a_linear_model(world):
    """An analytic forward model b = M f + c: the inversion must find the least-squares solution."""
    rng = np.random.default_rng(0)
    M = rng.normal(size=(world.k, 4)) / world.force_box.half
    c = rng.normal(size=world.k)
    policy = InversionPolicy(world, lambda f: f @ M.T + c, "linear")
    true_action = np.array([0.3, -0.4, 0.2, 0.6])
    target = world.force_box.features(true_action) @ M.T + c
    obs = np.zeros(2 * world.k + 8)
    obs[world.k:2 * world.k] = target * world.inv_sqrt
    obs[-4:] = world.force_box.rest_action
    np.testing.assert_allclose(policy.predict(obs), true_action, atol=1e-4)


def test_unknown_names_list_the_valid_ones(world):
    with pytest.raises(ValueError, match="valid baselines"):
        make_baseline("invert-gpt", world)
    with pytest.raises(ValueError, match="valid scenes"):
        scene_kwargs("SoftCube-v0")
    with pytest.raises(ValueError, match="valid agents"):
        hyperparams("dqn", "SoftSphere-v0")
    with pytest.raises(ValueError, match="valid baselines"):
        run(Plan(["SoftSphere-v0"], ["nope"], [], {"SoftSphere-v0": 1}), None, None, "", write=False)


def test_yaml_strings_are_parsed_as_literals_only():
    assert _literal_dict("dict(net_arch=[64, 64], log_std_init=-1.0)") == {"net_arch": [64, 64], "log_std_init": -1.0}
    with pytest.raises(ValueError):
        _literal_dict("dict(a=__import__('os').getcwd())")
    assert hyperparams("sac-her", "SoftSphere-v0")["replay_buffer_kwargs"]["goal_selection_strategy"] == "future"


def test_her_starts_learning_only_after_every_env_finished_an_episode():
    """SB3's HER buffer samples only finished episodes (it raises before the first one ends)."""
    import gymnasium as gym

    for env_id in sorted({env_id for env_id, _ in SCENES.values()}):
        params = hyperparams("sac-her", env_id)
        horizon = gym.make(env_id).unwrapped.world.horizon
        assert params["learning_starts"] >= params["n_envs"] * horizon, env_id


def test_agent_file_is_checked_against_the_scene(tmp_path):
    path = train_agent("ppo", "SoftSphere-v0", 0, tmp_path / "ppo", timesteps=512, progress=False)
    # a budget under one rollout (16 envs x 128 steps) takes one: evaluated ten times over it, not at every step
    with np.load(tmp_path / "ppo" / "eval" / "evaluations.npz") as log:
        assert log["timesteps"].tolist() == [16 * 12 * k for k in range(1, 11)]
    policy = load_agent(path, "SoftSphere-v0")
    obs_size = policy.model.observation_space.shape[0]
    assert policy.predict(np.zeros((3, obs_size), np.float32)).shape == (3, 4)
    with pytest.raises(ValueError, match="trained for scene 'SoftSphere-v0'.*asked for scene 'SoftSphereViscoelastic-v0'"):
        load_agent(path, "SoftSphereViscoelastic-v0")
    meta = json.loads((tmp_path / "ppo" / "agent.json").read_text())
    meta["format_version"] = 99
    (tmp_path / "ppo" / "agent.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="format_version=99"):
        load_agent(path, "SoftSphere-v0")
    meta["format_version"] = AGENT_FORMAT_VERSION
    (tmp_path / "ppo" / "agent.json").write_text(json.dumps(meta))
    with path.open("ab") as fh:                   # a model that is not the one trained: refused
        fh.write(b"\0")
    with pytest.raises(ValueError, match="does not match model_sha256"):
        load_agent(path, "SoftSphere-v0")


def test_a_finished_run_is_reused_only_on_the_simulator_it_was_trained_on(tmp_path, monkeypatch):
    """A run directory kept across code changes: the agent is trained again when its envs would return
    other floats (its recorded dynamics digest differs), or when another library version would train it."""
    path = train_agent("ppo", "SoftSphere-v0", 0, tmp_path / "ppo", timesteps=512, progress=False)
    meta_path = tmp_path / "ppo" / "agent.json"
    meta = json.loads(meta_path.read_text())
    assert meta["dynamics"] == dynamics_digest("ppo", "SoftSphere-v0") and meta["libraries"]["stable-baselines3"]
    stamp = path.stat().st_mtime_ns
    assert train_agent("ppo", "SoftSphere-v0", 0, tmp_path / "ppo", timesteps=512, progress=False) == path
    assert path.stat().st_mtime_ns == stamp                      # the same simulator: reused
    for key, other in (("dynamics", "0" * 64), ("libraries", {**meta["libraries"], "torch": "0.0"})):
        meta_path.write_text(json.dumps({**meta, key: other}))
        train_agent("ppo", "SoftSphere-v0", 0, tmp_path / "ppo", timesteps=512, progress=False)
        assert json.loads(meta_path.read_text())[key] == meta[key]    # trained again, on this one
    # the digest follows the simulator's code, not only its settings: a reward computed otherwise (by a part in a
    # million: the adapter's float32 rewards, what SB3 learns from, see it)
    import softenv.envs.vector as vector

    terms = vector.reward_terms
    monkeypatch.setattr(vector, "reward_terms", lambda *args: (terms(*args)[0] * (1 + 1e-6), *terms(*args)[1:]))
    assert dynamics_digest("ppo", "SoftSphere-v0") != meta["dynamics"]


def _weights(path) -> list[np.ndarray]:
    policy = load_agent(path, "SoftSphere-v0")
    return [p.detach().numpy().copy() for p in policy.model.policy.parameters()]


def test_a_stopped_training_starts_again_from_its_seed_and_gives_the_same_agent(tmp_path, monkeypatch):
    whole = train_agent("sac", "SoftSphere-v0", 0, tmp_path / "whole", timesteps=1100, progress=False)
    out = tmp_path / "stopped"
    partial = tmp_path / "stopped.partial"           # what a run killed mid-training leaves
    (partial / "eval").mkdir(parents=True)
    (partial / "model.zip").write_bytes(b"PK\3\4 truncated")
    out.mkdir()
    (out / "model.zip").write_bytes(b"not a model")  # and a foreign entry where the run goes: no agent.json
    path = train_agent("sac", "SoftSphere-v0", 0, out, timesteps=1100, progress=False)
    assert not partial.exists() and sorted(p.name for p in out.iterdir()) == [
        "agent.json", "best", "eval", "logs", "model.zip"]
    for a, b in zip(_weights(whole), _weights(path), strict=True):
        np.testing.assert_array_equal(a, b)          # bit for bit the run that was never stopped
    curves = [np.load(run / "eval" / "evaluations.npz")["results"] for run in (tmp_path / "whole", out)]
    assert curves[0].size >= 2 and np.ptp(curves[0]) > 0
    np.testing.assert_array_equal(*curves)           # its learning curve too: the evaluation env is seeded
    # a finished run is reused; one of another budget is replaced by a fresh run
    stamp = path.stat().st_mtime_ns
    assert train_agent("sac", "SoftSphere-v0", 0, out, timesteps=1100, progress=False) == path
    assert path.stat().st_mtime_ns == stamp
    train_agent("sac", "SoftSphere-v0", 0, out, timesteps=1200, progress=False)
    assert json.loads((out / "agent.json").read_text())["timesteps"] == 1200
    # a tuner's overrides are settings too: a run made with them is not the YAML's, and the other way round
    tuned = train_agent("sac", "SoftSphere-v0", 0, out, timesteps=1200, progress=False, overrides={"gamma": 0.9})
    assert json.loads((out / "agent.json").read_text())["overrides"] == {"gamma": 0.9}
    assert load_agent(tuned, "SoftSphere-v0").model.gamma == 0.9
    train_agent("sac", "SoftSphere-v0", 0, out, timesteps=1200, progress=False)
    assert json.loads((out / "agent.json").read_text())["overrides"] == {}
    # and so is the YAML itself: a run kept while its entry changes (a tuned value adopted) is trained again
    import softenv.baselines.agents as agents

    meta = json.loads((out / "agent.json").read_text())
    assert meta["hyperparams"]["gamma"] == hyperparams("sac", "SoftSphere-v0")["gamma"]
    stamp = (out / "model.zip").stat().st_mtime_ns
    yaml_entry = agents.hyperparams
    monkeypatch.setattr(agents, "hyperparams", lambda algo, env_id: {**yaml_entry(algo, env_id), "gamma": 0.5})
    train_agent("sac", "SoftSphere-v0", 0, out, timesteps=1200, progress=False)
    assert json.loads((out / "agent.json").read_text())["hyperparams"]["gamma"] == 0.5
    assert (out / "model.zip").stat().st_mtime_ns != stamp
    with pytest.raises(ValueError, match=r"overrides \['gama'\] are not hyper-parameters of sac"):
        train_agent("sac", "SoftSphere-v0", 0, out, timesteps=1200, progress=False, overrides={"gama": 0.9})


def test_a_cell_of_several_seeds_resamples_the_seeds_then_their_episodes():
    """Two seeds that learned apart (74.7 and 96.1 on their episodes): the cell's interval is the two-level
    bootstrap of softenv.stats (wide), not the pooled episodes' (narrow); one run keeps the episode bootstrap."""
    from softenv import stats
    from softenv.baselines.evaluate import Episodes

    rng = np.random.default_rng(0)
    scores = np.stack([rng.normal(74.7, 3, 50), rng.normal(96.1, 3, 50)])
    values = {name: np.zeros(100) for name in ("final_error_mm", "success", "steps_to_success", "peak_force_N")}
    values["normalized_score"] = scores.ravel()
    cell = Episodes("ppo", "SoftSphere-v0", values, 1.0, runs=2).summary()["normalized_score"]
    assert (cell["mean"], cell["ci_low"], cell["ci_high"]) == stats.nested_interval(scores)
    pooled = stats.bootstrap_ci(scores.ravel())
    assert cell["ci_high"] - cell["ci_low"] > 4 * (pooled[2] - pooled[1])
    one = Episodes("ppo", "SoftSphere-v0", values, 1.0).summary()["normalized_score"]
    assert (one["mean"], one["ci_low"], one["ci_high"]) == pooled


def test_compare_resumes_a_stopped_run_and_prints_the_same_table(tmp_path, monkeypatch):
    from softenv.baselines.run_store import RunStore
    from softenv.parallel import Interrupted

    plan = Plan(["SoftSphere-v0"], ["zero", "direct-poly3"], ["sac"], {"SoftSphere-v0": 2}, {"sac": 1100}, episodes=4)
    quiet = lambda s: None  # noqa: E731
    whole = run(plan, tmp_path, tmp_path / "whole", "test", echo=quiet, write=False)
    assert whole[2]["kind"] == "agent (1,100 steps)"
    # each seed's mean score beside the pooled one: 4 episodes a seed, so the pooled mean is their mean
    seeds = whole[2]["seed_scores"]
    assert len(seeds) == 2 and seeds[0]["mean"] != seeds[1]["mean"] and all(s["n"] == 4 for s in seeds)
    assert np.mean([s["mean"] for s in seeds]) == pytest.approx(whole[2]["normalized_score"]["mean"], rel=1e-12)
    assert all(s["ci_low"] <= s["mean"] <= s["ci_high"] for s in seeds)
    assert whole[2]["runs"] == 2 and whole[0]["runs"] == 1          # the agent's cell knows its seeds
    # every episode's score by run, so anyone can recount the cell, and the share above the planning oracle
    by_run = np.array(whole[2]["episode_scores"])
    assert by_run.shape == (2, 4) and [np.mean(r) for r in by_run] == pytest.approx([s["mean"] for s in seeds], abs=1e-4)
    assert whole[2]["above_100"] == np.mean(by_run > 100 + 1e-6) and whole[0]["above_100"] == 0.0
    table = format_seeds(whole).splitlines()
    assert table[0] == "| scene | policy | seed 0 | seed 1 |" and table[2].startswith("| SoftSphere-v0 | sac | ")
    save = RunStore.save

    def stop_after_two(self, job, result):        # SIGTERM arrives as the third job finishes, before it is kept
        if len(list(self.dir.glob("*.npz"))) == 2:
            raise Interrupted(15)
        save(self, job, result)

    monkeypatch.setattr(RunStore, "save", stop_after_two)
    with pytest.raises(Interrupted) as stopped:
        run(plan, tmp_path, tmp_path / "runs", "test", echo=quiet, write=False)
    assert "2 of 5 jobs are finished and kept" in stopped.value.kept and stopped.value.exit_status == 143
    monkeypatch.setattr(RunStore, "save", save)
    lines: list[str] = []
    again = run(plan, tmp_path, tmp_path / "runs", "test", echo=lines.append, write=False)
    assert "resuming: 2 of 5 jobs" in "\n".join(lines)
    assert _cells(again) == _cells(whole)
    # a damaged entry and one made by other settings are redone, never read
    entries = sorted((tmp_path / "runs" / "jobs").glob("*.npz"))
    assert len(entries) == 5
    entries[0].write_bytes(entries[0].read_bytes()[:100])
    lines.clear()
    third = run(plan, tmp_path, tmp_path / "runs", "test", echo=lines.append, write=False)
    assert sum("is not used (unreadable" in line for line in lines) == 1 and "resuming: 4 of 5 jobs" in "\n".join(lines)
    assert _cells(third) == _cells(whole)
    plan.episodes = 5
    lines.clear()
    run(plan, tmp_path, tmp_path / "runs", "test", echo=lines.append, write=False)
    assert sum("made by other settings, other code or other BLAS kernels" in line for line in lines) == 5
    # ... and so is one made under other BLAS kernels (they change the last bits of every product)
    lines.clear()
    monkeypatch.setattr("softenv.baselines.run_store.openblas_kernels", lambda: "SomeOtherCPU")
    run(plan, tmp_path, tmp_path / "runs", "test", echo=lines.append, write=False)
    assert sum("made by other settings, other code or other BLAS kernels" in line for line in lines) == 5


def _cells(summaries: list[dict]) -> str:
    """Every number but the measured decision times, as text (NaN equals NaN there, bit for bit otherwise)."""
    return json.dumps([{k: v for k, v in s.items() if k != "decision_us"} for s in summaries], sort_keys=True)


def test_compare_writes_the_report_with_its_command(tmp_path):
    scenes = ["SoftSphere-v0", "SoftSphereHaptic-v0"]
    plan = Plan(scenes, ["zero", "oracle", "expert", "direct-poly3"], [], {s: 1 for s in scenes}, episodes=6,
                oracle={"candidates": 4, "iterations": 2, "elites": 2})
    summaries = run(plan, tmp_path, tmp_path / "runs", "softenv compare --test", echo=lambda s: None)
    assert [(s["scene"], s["policy"]) for s in summaries] == [
        ("SoftSphere-v0", "zero"), ("SoftSphere-v0", "oracle"), ("SoftSphere-v0", "direct-poly3"),
        ("SoftSphereHaptic-v0", "oracle"), ("SoftSphereHaptic-v0", "zero"), ("SoftSphereHaptic-v0", "expert"),
        ("SoftSphereHaptic-v0", "direct-poly3")]
    # on the laryngoscope the oracle's row is the trajectory planner's own episodes, which define 100
    device_oracle = summaries[3]
    assert device_oracle["normalized_score"]["mean"] == pytest.approx(100.0) and "CEM" in device_oracle["kind"]
    md = (tmp_path / "benchmark.md").read_text()
    assert "softenv compare --test" in md and "| SoftSphere-v0 | oracle |" in md
    assert "candidates 4, iterations 2, elites 2" in md           # the device oracle's search, as it ran
    protocol = next(line for line in md.splitlines() if line.startswith("Protocol:"))
    assert "seeds per agent: SoftSphere-v0 1, SoftSphereHaptic-v0 1; agent budgets (env steps): none." in protocol
    assert "{" not in protocol                                     # prose, not a dict's repr
    # the laryngoscope's clinical metrics: in their own table, and in the CSV (empty on the ideal scene)
    oracle, expert = summaries[1], summaries[5]
    assert oracle["normalized_score"]["mean"] == pytest.approx(100.0)
    assert expert["normalized_score"]["ci_high"] <= 100 + 1e-6          # the planner starts from the expert's actions
    assert expert["peak_incisor_force_N"]["mean"] == 0.0 and expert["glottic_view_pct"]["mean"] > 19.0
    assert "| SoftSphereHaptic-v0 | expert | 3" in md and "glottic view (%)" in md
    rows = (tmp_path / "benchmark.csv").read_text().splitlines()
    header, ideal = rows[1].split(","), rows[2].split(",")
    assert ideal[header.index("glottic_view_pct_mean")] == "" and ideal[header.index("success_mean")] != ""
    csv_text = (tmp_path / "benchmark.csv").read_text()
    assert csv_text.startswith("# made by: softenv compare --test")
    from softenv.bench.timing import code_revision
    assert f"at {code_revision()} (" in csv_text.splitlines()[0]        # the code that made it, by commit
    for name in ("policy_error_vs_runtime.png", "benchmark_learning_curves.png", "benchmark_gallery.png"):
        assert (tmp_path / name).stat().st_size > 1000


def test_the_gallery_shows_the_reports_first_scene_with_its_devices_baselines():
    """A laryngoscope report's gallery draws its scene (the expert, no oracle) in two rows of wide frames;
    each panel's error is the one its policy's episode reached."""
    import matplotlib.pyplot as plt

    fig = _gallery("SoftSphereHaptic-v0", "softenv compare --test", plt)
    panels = [ax.get_title() for ax in fig.axes if ax.get_title()]
    assert [t.split("\n")[0] for t in panels] == ["zero", "invert-poly1", "invert-poly3", "invert-anfis", "direct-mlp",
                                                   "expert"]
    errors = [float(t.split("\n")[1].removesuffix(" mm")) for t in panels]
    assert errors[-1] < 0.5 < errors[0]                          # the expert near its target, no force far from it
    assert "of SoftSphereHaptic-v0" in fig.get_suptitle()
    plt.close(fig)


def test_the_error_axis_reaches_the_floor_only_where_a_policy_does():
    """A panel whose errors are all far above 1 um starts just below its lowest interval; one with the
    oracle's near-zero error starts below the floor, where that point is drawn."""
    import matplotlib.pyplot as plt

    def row(scene: str, policy: str, mean: float) -> dict:
        return {"scene": scene, "policy": policy, "decision_us": 100.0,
                "final_error_mm": {"mean": mean, "ci_low": 0.8 * mean, "ci_high": 1.2 * mean}}

    summaries = [row("A", "oracle", 1e-7), row("A", "zero", 2.8), row("B", "expert", 0.1), row("B", "zero", 2.8)]
    fig = _error_plot(summaries, ["A", "B"], "softenv compare --test", plt)
    (a, b) = fig.axes[:2]
    assert a.get_ylim()[0] == pytest.approx(0.7 * ERROR_FLOOR_MM)
    assert b.get_ylim()[0] == pytest.approx(0.7 * 0.08)
    plt.close(fig)


def test_an_agent_keeps_its_colour_in_every_report():
    import matplotlib.pyplot as plt

    four, three = agent_colours(["ppo", "sac", "td3", "sac-her"], plt), agent_colours(["sac", "td3", "sac-her"], plt)
    assert all(three[algo] == four[algo] for algo in three)
    assert len({four[algo] for algo in four}) == 4


def test_every_baseline_acts_within_the_box(world):
    obs = np.random.default_rng(0).uniform(-1, 1, (3, 2 * world.k + 8)).astype(np.float32)
    obs[:, -4:] = world.force_box.rest_action
    for name in BASELINES:
        if name.endswith("mlp") or not applies(name, "ideal"):
            continue                                   # slow to train; the compare test runs direct-poly3 end to end
        actions = make_baseline(name, world).predict(obs)
        assert actions.shape == (3, 4) and np.all(np.abs(actions) <= 1.0)


def test_hand_controller_realises_the_target_force_through_the_laryngoscope():
    """The force the controller is asked for arises in the tongue: after the lift and sweep the normal
    and sideways forces hold the target's within 2 % and 5 %, no force reaches the incisors, and the
    shape is the target's (success)."""
    import gymnasium as gym

    env = gym.make("SoftSphereHaptic-v0").unwrapped
    world = env.world
    controller = HandController(world.config)
    target = (world.family.low + world.family.high) / 2
    obs, _ = env.reset(seed=0, options={"target": world.force_box.normalised(target)})
    device = slice(2 * world.k, 2 * world.k + world.device_obs_size)
    incisor = []
    for _ in range(150):
        obs, _, _, _, info = env.step(controller.act(obs[None, device], target[None])[0].astype(np.float32))
        incisor.append(info["incisor_force_N"])
    assert env.device.laryngoscope.normal_force == pytest.approx(target[2], rel=0.02)
    assert env.device.laryngoscope.sideways_force == pytest.approx(target[3], rel=0.05)
    assert max(incisor) == 0.0 and info["is_success"]


def test_baselines_on_the_laryngoscope_rank_as_expected(haptic_world):
    """The scripted expert reaches most test targets through the device; a regressor's force helps less,
    no motion scores 0; the ideal device's oracle is not offered on the device (and vice versa)."""
    scores = {name: evaluate(make_baseline(name, haptic_world), "SoftSphereHaptic-v0", episodes=10)
              for name in ("zero", "expert", "invert-poly2")}
    assert scores["expert"].values["success"].mean() >= 0.8
    assert scores["expert"].values["normalized_score"].mean() > 80
    np.testing.assert_allclose(scores["zero"].values["normalized_score"], 0.0, atol=1e-9)
    assert 20 < scores["invert-poly2"].values["normalized_score"].mean() < scores["expert"].values["normalized_score"].mean()
    with pytest.raises(ValueError, match="'oracle' does not apply to device.kind='laryngoscope'"):
        make_baseline("oracle", haptic_world)


def test_planning_oracle_matches_a_three_step_search_where_the_force_saturates():
    """Under creep the oracle overshoots the target's force, saturating at the device's limit for the
    first steps; there its greedy plan must be as good as the best 3-step force sequence found by
    bounded quasi-Newton search from its own plan and from random starts."""
    import gymnasium as gym
    from scipy.optimize import minimize

    env_id, kwargs = scene_kwargs("SoftSphereViscoelastic-v0")
    kwargs.pop("obs_mode")
    env = gym.make(env_id, **kwargs).unwrapped
    world, dyn = env.world, env.world.dynamics
    oracle = PlanningOracle(world)
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        for _ in range(5):
            obs, *_ = env.step(oracle.predict(obs))
        z0, target = env._z.copy(), env._targets[0]

        def cost(seq: np.ndarray) -> float:
            z, total = z0.copy(), 0.0
            for a in seq.reshape(3, 4):
                b = dyn.step(z, world.response(world.force_box.features(a)[None])[0])
                total += float(np.sqrt(np.sum((b - target) ** 2)))
            return total

        plan = []
        for _ in range(3):
            plan.append(oracle.predict(obs).astype(np.float64))
            obs, *_ = env.step(plan[-1].astype(np.float32))
        starts = [np.ravel(plan), *np.random.default_rng(seed).uniform(-1, 1, (4, 12))]
        best = min(minimize(cost, x0, bounds=[(-1, 1)] * 12, method="L-BFGS-B").fun for x0 in starts)
        assert np.abs(np.ravel(plan)).max() == pytest.approx(1.0)          # saturated: a real constraint
        assert cost(np.ravel(plan)) <= best * (1 + 1e-3)


def test_planning_oracle_beats_holding_the_target_force_under_creep():
    """The old anchor (hold the target's force) is what agents beat; the planning oracle beats it."""
    kwargs = scene_kwargs("SoftSphereViscoelastic-v0")[1]
    kwargs.pop("obs_mode")
    world = World(make_config(**kwargs))
    oracle = evaluate(PlanningOracle(world), "SoftSphereViscoelastic-v0", episodes=10)
    hold = evaluate(InversionPolicy(world, world.response, "hold"), "SoftSphereViscoelastic-v0", episodes=10)
    assert (oracle.values["error_sum_mm"] < hold.values["error_sum_mm"]).all()
    assert oracle.values["normalized_score"].mean() > 105                 # on the env's hold-the-force scale


def test_the_baselines_load_without_pymunk(heavy_modules_after):
    """``softenv[rl]`` without the device extra: the baselines import neither pymunk (the laryngoscope's
    observation scales live outside its module) nor torch; the torch PPO's driver (baselines/ppo_torch.py)
    imports them, and on a machine without pymunk failed."""
    code = "import softenv.baselines.benchmark, softenv.baselines.policies, softenv.baselines.evaluate, softenv.devices.laryngoscope.control\n"
    assert heavy_modules_after(code) == []


def test_compare_profiles_name_their_scenes_seeds_budgets_and_report():
    """`softenv compare`'s profiles: quick, the laryngoscope scenes alone (--haptic) and the full run (with
    the gradient planner and SHAC); the two named profiles exclude each other, and --scenes narrows a
    profile keeping its seed rule."""
    from softenv.cli import build_parser, compare_plan

    parser = build_parser()
    haptic, stem = compare_plan(parser.parse_args(["compare", "--haptic"]))
    assert stem == "benchmark_haptic"
    assert haptic.scenes == ["SoftSphereHaptic-v0", "SoftSphereHapticProcedure-v0"]
    assert haptic.seeds == {s: 10 for s in haptic.scenes} and haptic.timesteps == {}     # the YAML budgets
    assert {"expert", "oracle", "zero"} <= set(haptic.baselines) and haptic.agents == ["ppo", "sac", "td3", "sac-her"]
    full, stem = compare_plan(parser.parse_args(["compare", "--scenes", "SoftSphereHapticProcedure-v0", "--agents"]))
    assert stem == "benchmark" and full.scenes == ["SoftSphereHapticProcedure-v0"] and full.agents == []
    assert full.seeds == {"SoftSphereHapticProcedure-v0": 10}
    whole = compare_plan(parser.parse_args(["compare"]))[0]
    assert whole.seeds["SoftSphere-v0/stiffening"] == 5
    # the gradient methods beside the sampled ones, in the full profile only
    assert "gradient" in whole.baselines and whole.agents == ["ppo", "sac", "td3", "sac-her", "shac"]
    assert "gradient" not in haptic.baselines and "shac" not in haptic.agents
    quick, stem = compare_plan(parser.parse_args(["compare", "--quick", "--episodes", "7"]))
    assert stem == "benchmark_quick" and quick.episodes == 7 and quick.timesteps["ppo"] == 50_000
    with pytest.raises(SystemExit):
        parser.parse_args(["compare", "--quick", "--haptic"])


def test_the_learning_curves_legend_counts_each_agents_seeds_as_its_panels_draw_them():
    """The full plan trains 5 seeds on two scenes and 3 on the others: the legend says 3-5, not 5."""
    assert seed_label("ppo", [5, 3, 3]) == "ppo (3-5 seeds)"
    assert seed_label("sac", [3, 3]) == "sac (3 seeds)"
    assert seed_label("td3", [1]) == "td3 (1 seed)"


def test_the_report_carries_every_episode_and_the_learning_curves(tmp_path):
    """The JSON holds each cell's per-episode scores by run and each agent's learning-curve points (the
    markdown table counts the episodes above the planning oracle), so a reader can recount a cell or read a
    curve without the figure."""
    plan = Plan(["SoftSphere-v0"], ["zero", "oracle"], ["sac"], {"SoftSphere-v0": 1}, {"sac": 1100}, episodes=3)
    run(plan, tmp_path, tmp_path / "runs", "test", echo=lambda s: None)
    report = json.loads((tmp_path / "benchmark.json").read_text())
    cells = {s["policy"]: s for s in report["summaries"]}
    assert np.array(cells["sac"]["episode_scores"]).shape == (1, 3)
    assert np.mean(cells["sac"]["episode_scores"]) == pytest.approx(cells["sac"]["normalized_score"]["mean"], abs=1e-4)
    assert cells["oracle"]["episode_scores"] == [[100.0] * 3] and cells["oracle"]["above_100"] == 0.0
    [curve] = report["learning_curves"]["SoftSphere-v0 sac"]
    steps, returns = learning_curve(tmp_path / "runs" / "SoftSphere-v0" / "sac-0")
    assert curve["env_steps"] == steps.tolist() and curve["test_return"] == np.round(returns, 4).tolist()
    md = (tmp_path / "benchmark.md").read_text()
    assert "| episodes above 100 (%) |" in md
    [row] = report["convergence"]                        # one seed: the rule has no interval to apply
    assert row["agent"] == "sac" and row["seeds"] == 1 and row["converged"] is None
    assert row["final"] == pytest.approx(returns[-1]) and row["equal_steps"] == int(steps[-1])
    # the training's time as its run recorded it, not the job's (a job that re-reads the run takes ~1 s)
    assert row["train_s_per_seed"] == recorded_train_seconds(tmp_path / "runs" / "SoftSphere-v0" / "sac-0") > 0
    assert "| SoftSphere-v0 | sac | 1 |" in md and "- (one seed, or under 2 evaluations in the last half)" in md


def test_every_policy_keeps_one_style_in_every_figure():
    """A policy's colour and marker come from its name alone (they changed from figure to figure when each
    figure numbered the policies it drew); no two policies a report can draw share both."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from softenv.baselines.benchmark import POLICIES, policy_style

    names = [*POLICIES, *ALGOS]
    styles = [(tuple(policy_style(n, plt)["color"]), policy_style(n, plt)["marker"]) for n in names]
    assert len(set(styles)) == len(names)
    assert policy_style("ppo", plt)["color"] == agent_colours(["ppo"], plt)["ppo"]
    moved = policy_style("ppo (trained on grade2)", plt)
    assert moved["color"] == policy_style("ppo", plt)["color"] and moved["marker"] != policy_style("ppo", plt)["marker"]


def test_a_first_evaluation_far_below_does_not_flatten_the_learning_curves():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from softenv.baselines.benchmark import _learning_curves

    steps = np.arange(1, 11) * 1000.0
    runs = [(steps, np.r_[-1700.0, np.linspace(-50, -10, 9) + s]) for s in (0.0, 2.0, -2.0)]
    plan = Plan(["SoftSphere-v0"], [], ["ppo"], {"SoftSphere-v0": 3}, {"ppo": 10_000})
    fig = _learning_curves(plan, {("SoftSphere-v0", "ppo"): runs}, "test", plt)
    ax = fig.axes[0]
    assert -80 < ax.get_ylim()[0] < -50 and any("below the axis" in t.get_text() for t in ax.texts)
    plt.close(fig)
