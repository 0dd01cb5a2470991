"""Bad input is refused whole: a clear ValueError, and nothing changed (issue: reliability)."""

from __future__ import annotations

import io
import tracemalloc
import zipfile

import gymnasium as gym
import numpy as np
import pytest

import softenv  # noqa: F401
from softenv.training.logs import example_log

BAD_TARGETS = [np.full(4, 2.0), np.zeros(4, complex), ["0.1"] * 4, {"a": 1}, np.zeros(3)]


def _single():
    return gym.make("SoftSphere-v0")


def _batched():
    return gym.make_vec("SoftSphere-v0", num_envs=3, vectorization_mode="vector_entry_point")


@pytest.mark.parametrize("make", [_single, _batched], ids=["single", "batched"])
@pytest.mark.parametrize("bad", BAD_TARGETS, ids=["out-of-range", "complex", "strings", "dict", "short"])
def test_a_refused_reset_leaves_the_random_state_as_it_was(make, bad):
    env, twin = make(), make()
    env.reset(seed=1)
    twin.reset(seed=1)
    with pytest.raises(ValueError, match=r"options\['target'\]"):
        env.reset(seed=7, options={"target": bad})
    np.testing.assert_array_equal(env.reset()[0], twin.reset()[0])
    a = np.full((3, 4) if make is _batched else 4, 0.25, np.float32)
    np.testing.assert_array_equal(env.step(a)[0], twin.step(a)[0])


def test_a_refused_reset_of_the_haptic_env_leaves_its_random_state():
    env, twin = gym.make("SoftSphereHaptic-v0"), gym.make("SoftSphereHaptic-v0")
    env.reset(seed=2)
    twin.reset(seed=2)
    with pytest.raises(ValueError):
        env.reset(seed=9, options={"target": np.zeros(4, complex)})
    np.testing.assert_array_equal(env.reset()[0], twin.reset()[0])


BAD_ACTIONS = {
    "numeric strings": ["0.1", "0.2", "0.3", "0.4"],
    "complex": np.array([0.1, 0.2, 0.3, 0.4]) + 1j,
    "object": np.array([0.1, 0.2, 0.3, 0.4], dtype=object),
    "dict": {"a": 0.1},
    "string": "0.1 0.2 0.3 0.4",
    "bool": np.ones(4, bool),
    "ragged": [[0.1, 0.2], [0.3]],
}


@pytest.mark.parametrize("bad", list(BAD_ACTIONS.values()), ids=list(BAD_ACTIONS))
def test_single_and_batched_envs_refuse_the_same_action_types_with_a_value_error(bad):
    env = _single()
    env.reset(seed=0)
    before = env.unwrapped.b.copy()
    with pytest.raises(ValueError, match="action must be a real numeric array"):
        env.step(bad)
    np.testing.assert_array_equal(env.unwrapped.b, before)
    venv = _batched()
    venv.reset(seed=0)
    batch = np.array([bad] * 3, dtype=object) if not isinstance(bad, (dict, str)) else bad
    with pytest.raises(ValueError, match="actions must be"):
        venv.step(batch)


def test_integer_actions_are_real_numbers_and_step_like_floats():
    env, twin = _single(), _single()
    env.reset(seed=0)
    twin.reset(seed=0)
    out_int, out_float = env.step([0, 0, 1, 0]), twin.step([0.0, 0.0, 1.0, 0.0])
    np.testing.assert_array_equal(out_int[0], out_float[0])
    assert out_int[1] == out_float[1] and type(out_int[1]) is float


def test_an_unseeded_reset_continues_each_envs_generator_as_sync_vector_env_does():
    twin = _batched()
    sync = gym.vector.SyncVectorEnv([lambda: gym.make("SoftSphere-v0") for _ in range(3)])
    np.testing.assert_array_equal(twin.reset(seed=4)[0], sync.reset(seed=4)[0])
    for _ in range(2):
        np.testing.assert_array_equal(twin.reset()[0], sync.reset()[0])
    np.testing.assert_array_equal(twin.reset(seed=[None, 8, None])[0], sync.reset(seed=[None, 8, None])[0])


# -- trainee scoring: every bad file one line naming it, exit 2, before any heavy work ------------

def _score(capsys, *args: str) -> tuple[int, str]:
    from softenv.cli import main

    code = main(["score", *args])
    err = capsys.readouterr().err
    return code, err


def _npy_bytes(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


def _npz(path, **columns):
    np.savez(path, **columns)
    return path


GOOD_COLUMNS = {"time_s": np.array([0.0, 0.5, 1.0]), "insertion_deg": np.full(3, 90.0), "lateral_deg": np.zeros(3),
                "normal_N": np.full(3, 20.0), "sideways_N": np.zeros(3)}


def _bad_files(tmp_path):
    full = _npz(tmp_path / "full.npz", format_version=np.array(1), **GOOD_COLUMNS)
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(full.read_bytes()[:200])
    random_bytes = tmp_path / "random.npz"
    random_bytes.write_bytes(np.random.default_rng(0).bytes(4000))
    utf16 = tmp_path / "utf16.csv"
    utf16.write_text("time_s,insertion_deg,lateral_deg,normal_N,sideways_N\n0,90,0,10,0\n1,90,0,10,0\n", encoding="utf-16")
    binary = tmp_path / "binary.csv"
    binary.write_bytes(bytes(range(256)) * 8)
    long = tmp_path / "long.csv"
    long.write_text("time_s,insertion_deg,lateral_deg,normal_N,sideways_N\n0,90,0,10,0\n1e7,90,0,10,0\n")
    unequal = _npz(tmp_path / "unequal.npz", format_version=np.array(1), **{**GOOD_COLUMNS, "normal_N": np.zeros(2)})
    version = _npz(tmp_path / "version.npz", format_version=np.array([1, 1]), **GOOD_COLUMNS)
    directory = tmp_path / "adir.csv"
    directory.mkdir()
    header = "time_s,insertion_deg,lateral_deg,normal_N,sideways_N"
    twice = tmp_path / "twice.csv"
    twice.write_text(header + ",normal_N\n0,90,0,10,0,12\n1,90,0,10,0,12\n")
    hand = "hand_x_m,hand_z_m,hand_pitch_rad,hand_y_m"
    both = tmp_path / "both.csv"
    both.write_text(f"{header},{hand}\n0,90,0,10,0,0,0,0,0\n1,90,0,10,0,0,0,0,0\n")
    extra = tmp_path / "extra.csv"
    extra.write_text(header + ",button\n0,90,0,10,0,1\n1,90,0,10,0,0\n")
    hand_extra = tmp_path / "hand_extra.csv"
    hand_extra.write_text(f"time_s,{hand},tongue_force_N,button\n0,0,0,0,0,0,1\n0.5,0,0,0,0,0,0\n")
    bad_reading = tmp_path / "bad_reading.npz"
    _npz(bad_reading, format_version=np.array(1), time_s=np.array([0.0, 0.5]),
         **{c: np.zeros(2) for c in hand.split(",")}, tongue_force_N=np.array([0.0, np.nan]))
    gap = tmp_path / "gap.csv"
    gap.write_text(f"time_s,{hand}\n0,0,0,0,0\n0.5,0,0,0,0\n599.5,0,0,0,0\n")
    short_row = tmp_path / "short_row.csv"
    short_row.write_text(header + "\n0,90,0,10,0\n1,90,0\n")
    claims = tmp_path / "claims.npz"                  # a header that declares 1e11 numbers over 24 bytes
    npy = b"\x93NUMPY\x01\x00" + (lambda h: len(h).to_bytes(2, "little") + h)(
        b"{'descr': '<f8', 'fortran_order': False, 'shape': (100000000000,), }".ljust(118) + b"\n")
    with zipfile.ZipFile(claims, "w") as archive:
        archive.writestr("format_version.npy", _npy_bytes(np.array(1)))
        for key in GOOD_COLUMNS:
            archive.writestr(f"{key}.npy", npy + bytes(24))
    bomb = tmp_path / "bomb.npz"                      # 80 MB of zeros, compressed to a few hundred kB
    with zipfile.ZipFile(bomb, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("format_version.npy", _npy_bytes(np.array(1)))
        for key in GOOD_COLUMNS:
            archive.writestr(f"{key}.npy", _npy_bytes(np.zeros(10_000_000)))
    return {"column twice": (twice, r"columns \['normal_N'\] appear more than once"),
            "both schemas": (both, "has the columns of force commands and of hand poses; a log holds one schema"),
            "unknown column": (extra, r"columns \['button'\] are not force commands columns"),
            "unknown hand column": (hand_extra, r"columns \['button'\] are not hand poses columns .* nor their "
                                                r"optional ones \['tongue_force_N', 'blade_z_mm'\]"),
            "NaN reading": (bad_reading, "row 2, column 'tongue_force_N' = nan: a force must be finite and >= 0"),
            "599 s gap": (gap, "row 3, column 'time_s' = 599.5: 599 s after the row before"),
            "short row": (short_row, "row 2 has 3 fields; the header has 5"),
            "1e11 elements": (claims, r"member 'time_s' declares shape \(100000000000,\)"),
            "zip bomb": (bomb, "member 'time_s' inflates to 80,000,128 bytes; at most 8,004,096"),
"truncated npz": (truncated, "cannot be read as NPZ"), "random-bytes npz": (random_bytes, "cannot be read"),
            "utf-16 csv": (utf16, "cannot be read as CSV"), "binary csv": (binary, "cannot be read as CSV"),
            "1e7 s": (long, "row 2, column 'time_s' = 1e\\+07: the log lasts 1e\\+07 s from its first row; at most 600 s"),
            "unequal columns": (unequal, "unequal lengths"), "non-scalar version": (version, r"format_version=\[1, 1\]"),
            "directory": (directory, "is not a file")}


OVERSIZED = ("1e7 s", "1e11 elements", "zip bomb")
AMBIGUOUS = ("column twice", "both schemas", "unknown column", "unknown hand column", "599 s gap", "short row")


def test_score_reports_every_bad_file_in_one_line_naming_it(tmp_path, capsys, tried):
    import re

    for case, (path, message) in _bad_files(tmp_path).items():
        tried["oversized logs" if case in OVERSIZED else "ambiguous logs" if case in AMBIGUOUS else "damaged logs"] += 1
        tracemalloc.start()
        code, err = _score(capsys, str(path))
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert peak < 32 << 20, (case, peak)              # sizes are refused from headers, before allocating
        assert code == 2, case
        assert err.count("\n") == 1 and "Traceback" not in err, (case, err)
        assert str(path) in err and re.search(message, err), (case, err)


def test_score_refuses_an_existing_file_as_out_before_any_work(tmp_path, capsys, monkeypatch):
    import softenv.training.scoring as scoring

    calls = []
    monkeypatch.setattr(scoring, "replay", lambda *a, **k: calls.append(1))
    taken = tmp_path / "taken"
    taken.write_text("x")
    code, err = _score(capsys, str(example_log("trajectories/expert")), "--out", str(taken))
    assert code == 2 and "exists and is not a directory" in err and not calls


def test_replay_and_expert_trajectory_validate_their_arguments():
    from softenv.training.scoring import expert_trajectory, replay

    good = expert_trajectory(duration_s=1.0)
    for table, message in [(good[::-1], "strictly increasing"), (good[:0], "has 0 rows; a log has 2 to 1,000,000"),
                           (good[:, :4], "5 columns"), (good.astype(complex), "real numbers")]:
        with pytest.raises(ValueError, match=message):
            replay(table)
    for duration in (0, -1, float("nan"), 1e9):
        with pytest.raises(ValueError, match="duration_s"):
            expert_trajectory(duration_s=duration)


def test_save_trajectory_is_atomic_and_honours_the_umask(tmp_path, monkeypatch, tried):
    import csv as csv_module
    import os

    from softenv.training.scoring import load_trajectory, save_trajectory, expert_trajectory

    tried["all-or-nothing writes"] += 1

    path = tmp_path / "t.csv"
    table = expert_trajectory(duration_s=1.0)
    save_trajectory(table, path)
    before = path.read_bytes()
    old = os.umask(0o027)
    try:
        save_trajectory(table, tmp_path / "mode.csv")
    finally:
        os.umask(old)
    assert (tmp_path / "mode.csv").stat().st_mode & 0o777 == 0o640

    class Broken:
        def __init__(self, *args, **kwargs):
            self.rows = 0

        def writerow(self, row):
            self.rows += 1
            if self.rows > 10:
                raise OSError("disk full")

    monkeypatch.setattr(csv_module, "writer", lambda fh: Broken())
    with pytest.raises(OSError, match="disk full"):
        save_trajectory(table[::-1][::-1] * 1, path)
    assert path.read_bytes() == before                       # the old file, whole
    assert [p.name for p in tmp_path.iterdir() if p.suffix == ".tmp"] == []
    np.testing.assert_allclose(load_trajectory(path), table, rtol=1e-5)


def test_saved_artifacts_honour_the_umask(tmp_path):
    import os

    from softenv._artifact import save_artifact

    old = os.umask(0o002)
    try:
        save_artifact(tmp_path / "a.npz", "test", 1, {"x": np.zeros(2)}, {})
    finally:
        os.umask(old)
    assert (tmp_path / "a.npz").stat().st_mode & 0o777 == 0o664


# -- files: every artifact checked on load, every cache entry against what it was built from ------

def _rewrite(path, meta=None, **arrays):
    """Copy an artifact with its header replaced (``meta``: a function of the old header) or arrays changed."""
    import json

    with np.load(path, allow_pickle=False) as data:
        contents = {name: data[name] for name in data.files if name != "built_from.txt"}
    header = json.loads(str(contents["__meta__"][()]))
    if meta is not None:
        contents["__meta__"] = np.array(json.dumps(meta(header)))
    contents.update(arrays)
    np.savez(path, **contents)


@pytest.fixture
def fitted(tmp_path):
    from softenv import ShapeModel, paper_dataset
    from softenv.response import PolynomialResponse

    data = paper_dataset(441, 4, 3)
    model = ShapeModel(4).fit(data.shapes, data.mesh)
    model.save(tmp_path / "model.npz")
    response = PolynomialResponse(order=1).fit(data.forces, model.encode(data.shapes))
    response.save(tmp_path / "response.npz")
    return tmp_path / "model.npz", tmp_path / "response.npz"


def test_loaders_refuse_damaged_headers_and_arrays(fitted):
    import shutil

    from softenv import ShapeModel
    from softenv.response import ResponseModel

    model_path, response_path = fitted
    cases = [
        (model_path, dict(meta=lambda h: {k: v for k, v in h.items() if k != "n_samples"}), ShapeModel.load, "n_samples"),
        (model_path, dict(meta=lambda h: [h]), ShapeModel.load, "header of type list"),
        (model_path, {"components": lambda a: np.where(np.arange(a.size).reshape(a.shape) == 5, np.nan, a)},
         ShapeModel.load, "array 'components' has nan"),
        (response_path, {"state_coef": lambda a: np.full_like(a, np.nan)}, ResponseModel.load, "array 'state_coef' has nan"),
        (response_path, {"output_scale": lambda a: a[:-1]}, ResponseModel.load, "array 'output_scale' has shape"),
        (response_path, dict(meta=lambda h: {**h, "n_features": "four"}), ResponseModel.load, "invalid"),
    ]
    for i, (source, change, load, message) in enumerate(cases):
        path = source.with_name(f"case{i}.npz")
        shutil.copy(source, path)
        if "meta" in change:
            _rewrite(path, meta=change["meta"])
        else:
            (name, fn), = change.items()
            with np.load(source, allow_pickle=False) as data:
                _rewrite(path, **{name: fn(data[name])})
        with pytest.raises(ValueError, match=message):
            load(path)


SMALL = {"mesh": {"resolution": 9}, "shape_model": {"n_contacts": 8, "n_loads": 4, "n_components": 4}}


def _scene(**sections):
    from softenv.envs.config import make_config
    from softenv.envs.scene import _SCENES, build_scene

    _SCENES.clear()                                  # the in-process memo would hide the disk cache
    return build_scene(make_config(**{**SMALL, **sections}))


@pytest.mark.parametrize("kind, a, b", [
    ("table", {"response": {"table_nodes": (5, 3, 3, 3)}}, {"response": {"table_nodes": (6, 3, 3, 3)}}),
    ("shape-model", {"tissue": {"E": 1e5}}, {"tissue": {"E": 2e5}}),
    ("workspace", {"tissue": {"E": 1e5}}, {"tissue": {"E": 2e5}}),
])
def test_a_cache_entry_swapped_in_from_another_config_is_rebuilt_not_used(tmp_path, monkeypatch, kind, a, b):
    import shutil

    monkeypatch.setenv("SOFTENV_CACHE_DIR", str(tmp_path))
    _scene(**a)
    file_a = set(tmp_path.glob(f"{kind}-*.npz"))
    expected = _scene(**b)
    (file_b,) = set(tmp_path.glob(f"{kind}-*.npz")) - file_a
    shutil.copy(*file_a, file_b)                     # another config's entry under this config's name
    with pytest.warns(RuntimeWarning, match="was built from config"):
        again = _scene(**b)
    features = expected.workspace.low + 0.3 * (np.asarray(expected.workspace.high) - expected.workspace.low)
    np.testing.assert_array_equal(again.response.predict(features[None]), expected.response.predict(features[None]))
    np.testing.assert_array_equal(again.data.shapes, expected.data.shapes)


def test_a_cache_entry_whose_header_lacks_a_key_is_rebuilt(tmp_path, monkeypatch):
    import zipfile

    monkeypatch.setenv("SOFTENV_CACHE_DIR", str(tmp_path))
    expected = _scene()
    (entry,) = tmp_path.glob("shape-model-*.npz")
    with zipfile.ZipFile(entry) as archive:
        stamp = archive.read("built_from.txt")
    _rewrite(entry, meta=lambda h: {k: v for k, v in h.items() if k != "total_variance"})
    with zipfile.ZipFile(entry, "a") as archive:      # keep its (right) stamp: only the header is damaged
        archive.writestr("built_from.txt", stamp)
    with pytest.warns(RuntimeWarning, match="total_variance"):
        again = _scene()
    np.testing.assert_array_equal(again.shape_model.components_, expected.shape_model.components_)


# -- settings: a documented range that works, the same verdict single and batched -----------------

@pytest.mark.parametrize("sections, message", [
    ({"tissue": {"E": 1e25}}, r"tissue.E=1e\+25 is out of range; allowed range \[0.001, 1e\+12\]"),
    ({"tissue": {"E": 5e-324}}, "tissue.E=4.94066e-324 is out of range"),
    ({"tissue": {"E": 10 ** 400}}, r"tissue.E=1e\+400 \(about\) is out of range"),
    ({"tissue": {"radius": 1e-300, "patch_radius": 1e-300}}, "tissue.radius=1e-300 is out of range"),
    ({"tissue": {"patch_radius": 1e-5}}, r"tissue.patch_radius=1e-05 m must lie within \[radius / 1000, radius\]"),
    ({"tissue": {"E": 1e12}, "device": {"max_normal_force": 1e-6}}, "at least 1e-09 is needed"),
    ({"task": {"target_normal_force": (0.0, 0.0), "target_sideways_force": (0.0, 0.0)}}, "every target"),
])
def test_settings_outside_what_works_are_refused_alike_by_single_and_batched(sections, message):
    with pytest.raises(ValueError, match=message):
        gym.make("SoftSphere-v0", **sections)
    with pytest.raises(ValueError, match=message):
        gym.make_vec("SoftSphere-v0", 2, vectorization_mode="vector_entry_point", **sections)


@pytest.mark.parametrize("tissue", [
    {"E": 1e-3}, {"E": 1e12}, {"E": 1e-3, "law": "stiffening"}, {"E": 1e12, "law": "stiffening"},
    {"radius": 1e-4, "patch_radius": 1e-7}, {"radius": 1.0, "patch_radius": 1.0},
], ids=["E-min", "E-max", "stiff-E-min", "stiff-E-max", "radius-min", "radius-max"])
def test_the_corners_of_the_documented_ranges_step_finite_and_agree(tissue):
    small = {"mesh": {"resolution": 9}, "shape_model": {"n_contacts": 8, "n_loads": 4, "n_components": 4}}
    single = gym.make("SoftSphere-v0", tissue=tissue, **small)
    batched = gym.make_vec("SoftSphere-v0", 2, vectorization_mode="vector_entry_point", tissue=tissue, **small)
    obs, _ = single.reset(seed=0)
    obs_b, _ = batched.reset(seed=0)
    np.testing.assert_array_equal(obs, obs_b[0])
    for a in (np.array([1.0, 1.0, 1.0, 1.0]), np.array([-1.0, -1.0, 0.0, -1.0]), np.zeros(4)):
        obs, reward, *_ = single.step(a)
        obs_b, rewards, *_ = batched.step(np.stack([a, a]))
        assert np.isfinite(obs).all() and np.isfinite(reward) and single.observation_space.contains(obs)
        np.testing.assert_array_equal(obs, obs_b[0])
        assert reward == rewards[0]


# -- the laryngoscope at the corners of its documented ranges ------------------------------------

DEVICE_CORNERS = {
    "stiffest coupling, lightest blade": {"device": {"coupling_stiffness": 1e7, "blade_mass": 0.005}},
    "stiffest wrist": {"device": {"rotational_stiffness": 1e5, "blade_mass": 0.005}},
    "most damping, lightest blade": {"device": {"coupling_damping": 1e5, "rotational_damping": 1e3, "blade_mass": 0.005}},
    "softest coupling": {"device": {"coupling_stiffness": 1e-6, "rotational_stiffness": 1e-6, "coupling_damping": 0.0}},
    "fastest hand, most friction": {"device": {"max_hand_speed": 5, "max_sweep_speed": 5, "max_pitch_rate": 20,
                                               "friction": 5}},
    "heaviest": {"device": {"blade_mass": 10, "handle_mass": 10}},
    "finest substep": {"device": {"max_substep": 1e-6}},
    "longest control period": {"dynamics": {"dt": 10.0}},
    "softest tissue": {"tissue": {"E": 1e-3}},
    "stiffest tissue": {"tissue": {"E": 1e12, "law": "stiffening"}},
    "largest forces": {"device": {"max_normal_force": 1e6, "max_sideways_force": 1e6}},
}


@pytest.mark.parametrize("sections", list(DEVICE_CORNERS.values()), ids=list(DEVICE_CORNERS))
def test_the_laryngoscope_stays_finite_at_the_corners_of_its_ranges(sections):
    single = gym.make("SoftSphereHaptic-v0", **sections)
    batched = gym.make_vec("SoftSphereHaptic-v0", 2, vectorization_mode="vector_entry_point", **sections)
    obs, _ = single.reset(seed=1)
    batched.reset(seed=1)
    space = single.observation_space
    for a in (np.array([1.0, 1.0, -1.0, 1.0]), np.array([-1.0, 1.0, 1.0, -1.0])):   # bang-bang, into the teeth
        obs, reward, _, _, info = single.step(a)
        obs_b, rewards, _, _, info_b = batched.step(np.stack([a, -a]))
        assert space.contains(obs) and np.isfinite(reward)
        assert all(np.isfinite(v).all() for v in info.values() if not isinstance(v, bool))
        assert np.isfinite(obs_b).all() and np.isfinite(rewards).all()
        np.testing.assert_array_equal(obs_b[0], obs)           # env 0 of the twin is the single env, bit for bit
        assert rewards[0] == reward
