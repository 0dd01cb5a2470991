"""Every way into an env honours every scene setting alike, and bad input of every class is refused by
name with the state left bit for bit as it was (hypothesis; issue: reliability where the device meets
its users). Profiles as in ``test_properties.py``."""

from __future__ import annotations

import copy
import io
import pickle
import zipfile

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import softenv  # noqa: F401
from softenv.envs import ENV_SCENES, HAPTIC_SCENES

IDS = [*ENV_SCENES, *HAPTIC_SCENES]
SMALL = {"mesh": {"resolution": 5}, "shape_model": {"n_contacts": 8, "n_loads": 4, "n_components": 4},
         "response": {"table_nodes": (3, 3, 3, 3)}}
PATHS = ["make", "sync", "vector_entry_point", "torch", "sb3"]


def _episode_length(path: str, env_id: str, limit: int | None, **scene) -> tuple[int, dict]:
    """Steps until the first episode ends through ``path``, and the config the env was built with."""
    kwargs = {**SMALL, **scene} if limit is None else {**SMALL, **scene, "max_episode_steps": limit}
    if path == "make":
        env = gym.make(env_id, **kwargs)
        env.reset(seed=0)
        zero = np.zeros(4, np.float32)
        for t in range(1, 10_000):
            _, _, terminated, truncated, _ = env.step(zero)
            if terminated or truncated:
                return t, env.unwrapped.world.config
    if path == "sb3":
        from softenv.envs.sb3 import SoftSphereSB3VecEnv

        venv = SoftSphereSB3VecEnv(2, env_id=env_id, **kwargs)
        venv.reset()
        config = venv.venv.world.config
        for t in range(1, 10_000):
            if venv.step(np.zeros((2, 4), np.float32))[2][0]:
                return t, config
    mode = "sync" if path == "sync" else "vector_entry_point"
    extra = {"backend": "torch"} if path == "torch" else {}
    venv = gym.make_vec(env_id, num_envs=2, vectorization_mode=mode, **extra, **kwargs)
    venv.reset(seed=0)
    world = venv.envs[0].unwrapped.world if path == "sync" else venv.world
    for t in range(1, 10_000):
        _, _, terminated, truncated, _ = venv.step(np.zeros((2, 4), np.float32))
        if bool(terminated[0] | truncated[0]):
            return t, world.config
    raise AssertionError("no episode ended")


@given(env_id=st.sampled_from(IDS), horizon=st.integers(1, 12) | st.sampled_from([101, 251]),
       limit=st.none() | st.integers(1, 12), tolerance=st.floats(0.01, 0.99), force_weight=st.floats(0.0, 2.0))
def test_every_path_honours_the_horizon_the_limit_and_every_setting_alike(env_id, horizon, limit, tolerance,
                                                                          force_weight, tried):
    """A horizon longer or shorter than the id's, and a max_episode_steps, end episodes at the same step
    on every way in (gym.make, gym.make_vec sync and vector entry point, the torch backend, the SB3
    adapter), which all build the same config."""
    if horizon > 12 and env_id in HAPTIC_SCENES:
        horizon = 13                           # the laryngoscope steps slowly: a horizon beyond its tests' limits
    scene = {"task": {"horizon": horizon, "tolerance": tolerance}, "reward": {"force_weight": force_weight}}
    paths = [p for p in PATHS if p != "torch" or env_id in ENV_SCENES]        # the torch backend: the ideal device
    results = {path: _episode_length(path, env_id, limit, **copy.deepcopy(scene)) for path in paths}
    tried["settings on every path"] += len(paths)
    expected = horizon if limit is None else min(horizon, limit)
    assert {path: length for path, (length, _) in results.items()} == {path: expected for path in paths}
    configs = [config for _, config in results.values()]
    assert all(config == configs[0] for config in configs)
    assert configs[0]["task"]["horizon"] == horizon and configs[0]["task"]["tolerance"] == tolerance


def test_a_time_limit_ends_a_laryngoscope_episode_without_its_clinical_record_on_every_path(tried):
    """max_episode_steps is a time limit from outside (TimeLimit on the single env), so the episode's
    clinical record, which the task writes at its own end, is absent alike through sync and vector."""
    tried["settings on every path"] += 2
    kwargs = {"max_episode_steps": 3, "task": {"horizon": 5}}
    native = gym.make_vec("SoftSphereHaptic-v0", num_envs=2, vectorization_mode="vector_entry_point", **kwargs)
    sync = gym.make_vec("SoftSphereHaptic-v0", num_envs=2, vectorization_mode="sync", **kwargs)
    native.reset(seed=1), sync.reset(seed=1)
    for _ in range(3):
        x, y = native.step(np.zeros((2, 4))), sync.step(np.zeros((2, 4)))
    assert x[3].all() and y[3].all() and set(x[4]) == set(y[4]) and "clinical" not in x[4]
    ended = gym.make_vec("SoftSphereHaptic-v0", num_envs=2, vectorization_mode="vector_entry_point", task={"horizon": 3})
    ended.reset(seed=1)
    for _ in range(3):
        info = ended.step(np.zeros((2, 4)))[4]
    assert "clinical" in info


def test_pickled_envs_keep_their_time_limit(tried):
    tried["settings on every path"] += 2
    venv = gym.make_vec("SoftSphere-v0", num_envs=2, vectorization_mode="vector_entry_point", max_episode_steps=4)
    again = pickle.loads(pickle.dumps(venv))
    assert again.max_episode_steps == 4
    with pytest.raises(ValueError, match=r"max_episode_steps=0 is out of range; allowed range \[1, inf\]"):
        gym.make_vec("SoftSphere-v0", num_envs=2, vectorization_mode="vector_entry_point", max_episode_steps=0)


# -- logs the project writes itself: accepted, and replayed to the recorded shape error ----------------

def _recorded(actions: np.ndarray, offset: float = 0.0) -> tuple[np.ndarray, np.ndarray, bool]:
    """A hand log recorded from an env run (poses at every control period, the clock starting at
    ``offset``), its shape errors, and whether the hand ever stood on a wall of its workspace."""
    from softenv.training.hand import haptic_config, reach_env, relative_box, relative_hand_pose

    env = reach_env(haptic_config(None), len(actions))
    world = env.world
    env.reset(seed=0, options={"target": world.force_box.normalised(world.family.centre)})
    poses, errors = [relative_hand_pose(env)], []
    for a in actions:
        errors.append(env.step(np.asarray(a, np.float32))[4]["shape_error_mm"])
        poses.append(relative_hand_pose(env))
    low, high = relative_box(env.device.laryngoscope.params)
    poses = np.array(poses)
    walls = bool(((poses <= low + 1e-9) | (poses >= high - 1e-9)).any())
    times = offset + np.arange(len(poses)) * world.config["dynamics"]["dt"]
    return np.column_stack([times, poses]), np.array(errors), walls


keys = st.lists(st.lists(st.sampled_from([-1.0, 0.0, 1.0]), min_size=4, max_size=4), min_size=2, max_size=60)
uniform = st.lists(st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4), min_size=2, max_size=60)


@given(actions=keys | uniform, offset=st.sampled_from([0.0, 1000.0, 86_400.0]))
def test_every_log_recorded_from_an_env_run_is_accepted_and_replays_to_its_shape_error(actions, offset, tried):
    """Full-speed moves (keys held together, walls met) are within the device's limits, a clock that
    starts anywhere is fine, and the replay gives the recorded shape error at every step: exactly off the
    walls, within 2 % where a wall stopped the hand within a period (the poses do not say when)."""
    from softenv.training.scoring import replay_hand

    log, errors, walls = _recorded(np.array(actions), offset)
    tried["logs the project writes itself"] += 1
    replayed = replay_hand(log).error_mm
    if walls:
        np.testing.assert_allclose(replayed, errors, rtol=0.02)
    else:
        np.testing.assert_allclose(replayed, errors, rtol=1e-9)


def test_keys_held_together_into_a_wall_replay_bit_for_bit(tried):
    """The session a keyboard makes: full-speed moves, two keys at once, into the walls."""
    tried["logs the project writes itself"] += 1
    from softenv.training.scoring import replay_hand

    actions = np.array([[1, 0, 0, 0]] * 5 + [[1, 1, 0, 0]] * 10 + [[0, 1, 1, 0]] * 10 + [[0, 0, 1, 1]] * 10
                       + [[1, 1, 1, 1]] * 10 + [[-1, -1, 0, 0]] * 10, float)
    log, errors, walls = _recorded(actions)
    assert walls and np.array_equal(replay_hand(log).error_mm, errors)


# -- wrong types: refused by name on every env and backend, the state left as it was -------------------

def _envs() -> dict:
    return {"single": gym.make("SoftSphere-v0", **SMALL).unwrapped,
            "vector": gym.make_vec("SoftSphere-v0", num_envs=2, vectorization_mode="vector_entry_point", **SMALL),
            "torch": gym.make_vec("SoftSphere-v0", num_envs=2, vectorization_mode="vector_entry_point",
                                  backend="torch", **SMALL),
            "haptic": gym.make("SoftSphereHaptic-v0", **SMALL).unwrapped}


ENVS = _envs()
bad_seeds = st.one_of(st.floats(allow_nan=True), st.text(max_size=3), st.integers(max_value=-1),
                      st.integers(min_value=2**64, max_value=2**70), st.booleans(), st.just(object()),
                      st.lists(st.integers(0, 9), min_size=3, max_size=3))
bad_options = st.one_of(st.integers(), st.text(max_size=3), st.lists(st.integers(), max_size=2),
                        st.dictionaries(st.sampled_from(["goal", "targets", "seed"]), st.integers(), min_size=1),
                        st.fixed_dictionaries({"target": st.sampled_from([None, "a", [1, 2], [2.0, 0, 0, 0]])}))
bad_actions = st.one_of(st.none(), st.text(max_size=4), st.just(object()), st.just([[0, 0, 0, 0], [0, 0]]),
                        st.sampled_from([np.array([["1"] * 4] * 2), np.zeros((2, 4), complex),
                                         np.full((2, 4), np.nan), np.full((2, 4), 1.5), np.zeros((3, 4)),
                                         np.array([[object()] * 4] * 2), np.zeros((2, 4), bool)]))


def _after(env, name: str):
    """The next observation after a seeded reset and one step: equal for envs in the same state."""
    action = np.zeros(4) if name in ("single", "haptic") else np.zeros((2, 4))
    out = env.step(action)[0]
    return np.asarray(out.cpu() if hasattr(out, "cpu") else out)


@given(name=st.sampled_from(list(ENVS)), what=st.sampled_from(["seed", "options", "action"]), data=st.data())
def test_wrong_types_are_refused_by_name_and_change_nothing(name, what, data, tried):
    tried["wrong types"] += 1
    env = ENVS[name]
    env.reset(seed=5)
    single = name in ("single", "haptic")
    with pytest.raises(ValueError) as refused:
        if what == "seed":
            bad = data.draw(bad_seeds.filter(lambda s: not (single and isinstance(s, list))))
            env.reset(seed=bad)
        elif what == "options":
            env.reset(options=data.draw(bad_options))
        else:
            env.step(data.draw(bad_actions))                  # (2, 4) arrays have the wrong shape for a single env
    assert {"seed": "seed", "options": "options", "action": "action"}[what] in str(refused.value)
    after = _after(env, name)
    env.reset(seed=5)
    assert np.array_equal(_after(env, name), after)


def test_actions_of_any_real_dtype_leave_python_floats_in_the_state_and_the_reward(tried):
    tried["wrong types"] += 2
    env = gym.make("SoftSphereHaptic-v0", **SMALL).unwrapped
    env.reset(seed=0)
    _, reward, *_ = env.step(np.full(4, 0.5, np.longdouble))
    assert type(reward) is float and all(type(x) is float for x in env._prev)
    venv = ENVS["vector"]
    venv.reset(seed=0)
    assert venv.step(np.zeros((2, 4), np.longdouble))[1].dtype == np.float64


# -- command lines: every option checked before any work, one line, exit 2, nothing written -------------

BAD_COMMANDS = [
    ("compare --episodes 0", "argument --episodes: 0 is out of range; allowed range [1, 100000]"),
    ("compare --episodes -5", "argument --episodes: -5 is out of range"),
    ("compare --jobs 0", "argument --jobs: 0 is out of range"),
    ("compare --retries -1", "argument --retries: -1 is out of range"),
    ("compare --scenes Nope-v0", "argument --scenes: invalid choice: 'Nope-v0'"),
    ("compare --agents dqn", "argument --agents: invalid choice: 'dqn'"),
    ("bench --only envs", "argument --only: invalid choice: 'envs'"),
    ("play --seconds nan", "argument --seconds: must be finite, got nan; allowed range (0, 600]"),
    ("play --seconds inf", "argument --seconds: must be finite"),
    ("play --seconds 0", "argument --seconds: 0 is out of range; allowed range (0, 600]"),
    ("play --seconds -1", "argument --seconds: -1 is out of range"),
    ("play --seconds 1e9", "argument --seconds: 1e+09 is out of range"),
    ("play --seconds 601", "argument --seconds: 601 is out of range"),
    ("play --headless --seconds 1 --out taken", "--out 'taken' exists and is not a directory"),
    ("data --points 3", "argument --points: 3 is out of range; allowed range [9, 40000]"),
    ("data --seed 1.5", "argument --seed: '1.5' is not an integer"),
    ("fit --noise-std -1", "argument --noise-std: -1 is out of range"),
    ("score missing.csv --out taken", "out directory 'taken' exists and is not a directory"),
]
if not __import__("softenv.bench", fromlist=["cuda_available"]).cuda_available():
    BAD_COMMANDS.append(("bench --device cuda", "--device cuda: no CUDA device is usable here"))


@pytest.mark.parametrize("command,message", BAD_COMMANDS, ids=[c for c, _ in BAD_COMMANDS])
def test_bad_options_are_refused_in_one_line_before_any_work(command, message, tmp_path, monkeypatch, capsys, tried):
    tried["command lines"] += 1
    from softenv.cli import main

    monkeypatch.chdir(tmp_path)
    (tmp_path / "taken").write_text("a file, not a directory")
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(command.split()) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and "Traceback" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before            # nothing written


def test_a_file_name_that_is_not_utf8_is_shown_escaped(tmp_path, capsys, tried):
    tried["command lines"] += 1
    from softenv.cli import main

    name = str(tmp_path) + "/" + b"\xff\xfe.csv".decode("utf-8", "surrogateescape")
    assert main(["score", name]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "does not exist" in err


def test_a_score_report_is_written_all_or_nothing(tmp_path, monkeypatch, tried):
    """A failed write of the report's last file (the PNG) leaves none of the three, and no temporary file."""
    tried["all-or-nothing writes"] += 1
    from softenv.training import scoring

    log = tmp_path / "expert.csv"
    scoring.save_trajectory(scoring.expert_trajectory(duration_s=1.0), log)

    def failing(*args, **kwargs):
        def write(fh):
            raise OSError("disk full")
        return write

    monkeypatch.setattr(scoring, "_plot", failing)
    with pytest.raises(OSError, match="disk full"):
        scoring.score_file(log, out_dir=tmp_path / "report")
    assert not (tmp_path / "report").exists() or list((tmp_path / "report").iterdir()) == []
    monkeypatch.undo()
    scoring.score_file(log, out_dir=tmp_path / "report")
    assert sorted(p.name for p in (tmp_path / "report").iterdir()) == ["expert_score.json", "expert_score.md",
                                                                         "expert_score.png"]


def test_a_long_valid_log_is_read_in_bounded_memory(tmp_path, tried):
    """A CSV is parsed row by row into one float table: the memory it takes is that of the table (here
    200,000 rows, 8 MB), not of the text's rows as Python lists (about ten times more)."""
    import tracemalloc

    from softenv.training.logs import read_log

    tried["oversized logs"] += 1
    rows = 200_000
    t = np.arange(rows) * 1e-3
    table = np.column_stack([t, np.full(rows, 90.0), np.zeros(rows), np.full(rows, 10.0), np.zeros(rows)])
    path = tmp_path / "long.csv"
    np.savetxt(path, table, delimiter=",", header="time_s,insertion_deg,lateral_deg,normal_N,sideways_N", comments="")
    tracemalloc.start()
    _, read = read_log(path)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert np.array_equal(read, table) and peak < 3 * table.nbytes, peak


def test_a_benchmark_report_is_written_all_or_nothing(tmp_path, monkeypatch, tried):
    """softenv compare's report set (tables and figures): a failing figure leaves no file, not even the tables."""
    from softenv.baselines import benchmark

    tried["all-or-nothing writes"] += 1
    plan = benchmark.Plan(["SoftSphere-v0"], ["zero"], [], {"SoftSphere-v0": 1}, episodes=2)
    drawn = benchmark._gallery

    def broken_gallery(*args):
        fig = drawn(*args)
        monkeypatch.setattr(fig, "savefig", lambda *a, **k: (_ for _ in ()).throw(OSError("disk full")))
        return fig

    monkeypatch.setattr(benchmark, "_gallery", broken_gallery)
    with pytest.raises(OSError, match="disk full"):
        benchmark.run(plan, tmp_path / "report", tmp_path / "runs", "test", echo=lambda s: None)
    assert not (tmp_path / "report").exists() or list((tmp_path / "report").iterdir()) == []
    monkeypatch.undo()
    said: list[str] = []
    benchmark.run(plan, tmp_path / "report", tmp_path / "runs", "test", echo=said.append)
    assert len(list((tmp_path / "report").iterdir())) == 6
    assert said[-1].startswith(f"wrote {tmp_path / 'report' / 'benchmark'}.md, .csv and .json")   # says where
    lines = [line for text in said[:-1] for line in text.splitlines()          # the terminal's table: compact
             if str(tmp_path) not in line]                # (a line naming a folder is as long as the folder's name)
    assert max(len(line) for line in lines) <= 120 and not any("{" in line for line in lines)
    assert any(line.startswith("SoftSphere-v0") and "zero" in line for line in lines)


def _training_calls():
    from softenv.haptics import HapticLoop
    from softenv.training import hand, scoring, trainee

    log = trainee.expert_hand_log(duration_s=1.0)
    nan, back = log.copy(), log.copy()
    nan[3, 1] = np.nan
    back[5, 0] = back[2, 0]
    loop = HapticLoop()
    loop.reset()
    return {
        "score_hand_log(config=5)": (lambda: scoring.score_hand_log(log, 5), "config must be a scene config made by make_config()"),
        "score_hand_log(sections as config)": (lambda: scoring.score_hand_log(log, {"tissue": {}}),
                                               "got ['tissue']; make one from sections with haptic_config(sections)"),
        "haptic_config(scene={'tisue': ...})": (lambda: hand.haptic_config({"tisue": {}}), "'tisue'"),
        "degrade(NaN)": (lambda: trainee.degrade(nan, tremor=0.1), "row 4, column 'hand_x_m' = nan is not finite"),
        "degrade(times back)": (lambda: trainee.degrade(back), "row 6, column 'time_s'"),
        "degrade(seed=1.5)": (lambda: trainee.degrade(log, seed=1.5), "seed must be an integer"),
        "replay_hand(ragged)": (lambda: scoring.replay_hand([[0, 0, 0, 0, 0], [1, 0, 0]]), "must be a table"),
        "tick(numeric strings)": (lambda: loop.tick(["0.1", "0", "0", "0"]), "hand_pose must be a real numeric"),
        "tick(None)": (lambda: loop.tick(None), "hand_pose must be a real numeric"),
        "tick(NaN)": (lambda: loop.tick([np.nan, 0.0, 0.0, 0.0]), "hand_pose must be 4 finite numbers"),
    }


TRAINING_CALLS = _training_calls()


@pytest.mark.parametrize("call", list(TRAINING_CALLS))
def test_training_functions_refuse_wrong_types_by_name(call, tried):
    tried["wrong types"] += 1
    run, message = TRAINING_CALLS[call]
    with pytest.raises(ValueError) as refused:
        run()
    assert message in str(refused.value), str(refused.value)


# -- property tests of the rules themselves ----------------------------------------------------------

@given(actions=st.lists(st.lists(st.sampled_from([-1.0, -0.3, 0.0, 0.5, 1.0]), min_size=4, max_size=4),
                        min_size=1, max_size=40),
       weights=st.fixed_dictionaries({"force_weight": st.floats(0.0, 3.0), "smoothness_weight": st.floats(0.0, 3.0),
                                      "incisor_weight": st.floats(0.0, 3.0)}))
def test_compute_reward_of_a_steps_own_goals_is_its_reward(actions, weights, tried):
    env = gym.make("SoftSphereHaptic-v0", obs_mode="dict", reward=weights, **SMALL).unwrapped
    env.reset(seed=1)
    for a in actions:
        obs, reward, _, _, info = env.step(np.array(a))
        tried["goal reward (HER's compute_reward)"] += 1
        assert env.compute_reward(obs["achieved_goal"], obs["desired_goal"], info) == reward


FORCE_COLUMNS = ["time_s", "insertion_deg", "lateral_deg", "normal_N", "sideways_N"]
HAND_COLUMNS = ["time_s", "hand_x_m", "hand_z_m", "hand_pitch_rad", "hand_y_m"]


@given(columns=st.lists(st.sampled_from(sorted(set(FORCE_COLUMNS + HAND_COLUMNS)) + ["button", "force_N"]),
                        min_size=1, max_size=9))
def test_a_log_is_read_only_with_exactly_one_schemas_columns(columns, tmp_path_factory, tried):
    """Any header: read when it holds one schema's columns, each once, in any order; otherwise refused
    naming the column that is twice, of the other schema, of neither, or missing."""
    from softenv.training.logs import read_log

    tried["ambiguous logs"] += 1
    path = tmp_path_factory.mktemp("log") / "log.csv"
    values = {"time_s": [0.0, 0.5], "insertion_deg": [90.0, 90.0], "normal_N": [10.0, 10.0]}
    rows = [[values.get(c, [0.0, 0.0])[i] for c in columns] for i in range(2)]
    path.write_text(",".join(columns) + "\n" + "\n".join(",".join(map(str, r)) for r in rows) + "\n")
    exact = sorted(columns) in (sorted(FORCE_COLUMNS), sorted(HAND_COLUMNS))
    if exact:
        schema, table = read_log(path)
        assert list(schema.columns) in (FORCE_COLUMNS, HAND_COLUMNS) and table.shape == (2, 5)
        return
    with pytest.raises(ValueError) as refused:
        read_log(path)
    message = str(refused.value)
    assert "log.csv" in message and ("more than once" in message or "are not" in message or "missing" in message
                                     or "one schema" in message), message


@given(shape=st.lists(st.integers(0, 10**12), min_size=1, max_size=3), dtype=st.sampled_from(["<f8", "<f4", "<i8",
                                                                                              "<c16", "<f16"]))
def test_npz_members_are_judged_by_their_headers_before_anything_is_read(shape, dtype, tmp_path_factory, tried):
    """A member's header may claim any shape: beyond MAX_ROWS numbers, or 1-D arrays of more than 8
    bytes a number, it is refused from the header alone (its data here is 16 bytes)."""
    from softenv.training.logs import MAX_ROWS, read_log

    tried["oversized logs"] += 1
    header = repr({"descr": dtype, "fortran_order": False, "shape": tuple(shape)}).encode()
    header = header.ljust(118) + b"\n"
    member = b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header + bytes(16)
    path = tmp_path_factory.mktemp("npz") / "claims.npz"
    with zipfile.ZipFile(path, "w") as archive:
        buffer = io.BytesIO()
        np.save(buffer, np.array(1))
        archive.writestr("format_version.npy", buffer.getvalue())
        for column in FORCE_COLUMNS:
            archive.writestr(f"{column}.npy", member)
    with pytest.raises(ValueError) as refused:
        read_log(path)
    message = str(refused.value)
    count = int(np.prod(shape, dtype=object))
    if count > MAX_ROWS or np.dtype(dtype).itemsize > 8:
        assert "declares shape" in message, message
    else:                               # a plausible header over too little data: the reader says so
        assert "claims.npz" in message, message


OPTION_RANGES = [("compare", "--episodes", int, 1, 100_000), ("compare", "--jobs", int, 1, 4096),
                 ("compare", "--retries", int, 0, 100), ("play", "--seconds", float, 0.0, 600.0),
                 ("data", "--points", int, 9, 40_000), ("data", "--noise", float, 0.0, 1.0),
                 ("fit", "--noise-std", float, 0.0, None)]


@given(option=st.sampled_from(OPTION_RANGES), value=st.one_of(
    st.integers(-10**6, 10**6).map(str), st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["", "1e400", "-0", "0x10", "1_000", " 5", "five", "nan", "inf", "1.0"])))
def test_every_numeric_option_is_accepted_exactly_within_its_range(option, value, tried):
    """The parser's types are the whole check: a value parses iff it is a number of the option's kind
    inside its documented range (play's seconds and fit's noise std exclude 0), else one line, exit 2."""
    import contextlib

    from softenv.cli import build_parser

    command, flag, kind, low, high = option
    tried["command lines"] += 1
    try:
        number = kind(value)
    except ValueError:
        number = None
    fine = number is not None and np.isfinite(number) and number >= low and (high is None or number <= high) and not (
        flag in ("--seconds", "--noise-std") and number == 0)
    with contextlib.redirect_stderr(io.StringIO()) as err:
        try:
            args = build_parser().parse_args([command, flag, value] + (["x.csv"] if command == "score" else []))
            parsed = True
        except SystemExit as exit_:
            parsed = False
            assert exit_.code == 2
    assert parsed == fine, (option, value, err.getvalue())
    if parsed:
        assert getattr(args, flag[2:].replace("-", "_")) in (number, [number])
    else:
        assert err.getvalue().count("\n") == 1 and f"argument {flag}" in err.getvalue()


def test_a_log_whose_name_is_not_utf8_scores_and_its_report_shows_the_name_escaped(tmp_path, capsys, tried):
    """The name reaches the report's Markdown, JSON and figure title: escaped, so none of them fails."""
    from softenv.cli import main
    from softenv.training import scoring

    tried["command lines"] += 1
    name = tmp_path / b"\xfe.csv".decode("utf-8", "surrogateescape")
    scoring.save_trajectory(scoring.expert_trajectory(duration_s=1.0), name)
    assert main(["score", str(name), "--out", str(tmp_path / "report")]) == 0
    written = sorted((tmp_path / "report").iterdir())
    assert len(written) == 3 and "\\xfe.csv" in next(p for p in written if p.suffix == ".md").read_text()
