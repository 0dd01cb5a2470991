"""Scenes on the finite-element tongue (tissue={"model": "fem"}): the shipped data, their checks, the
fitted response against held-out FE solves, the FE contact law, and what such a scene imports."""

import dataclasses
import json
import sys
import zipfile

import gymnasium as gym
import numpy as np
import pytest

import softenv  # noqa: F401  (registers the ids)
from softenv.airway import SETTINGS, airway
from softenv.envs import ENV_SCENES, HAPTIC_SCENES
from softenv.envs.config import make_config, scene_config
from softenv.envs.scene import fe_request
from softenv.fem.params import FEParams
from softenv.fem.scene_data import FERequest, FESceneData
from softenv.fem.store import scene_data, shipped_file

FEM = {"tissue": {"model": "fem"}}
# the ids on the FE tongue: every id but the graded airways, whose 60 N device range indents the tongue beyond
# the FE ramps' verified 40 % of its radius, and is refused (docs/airways.md: analytic tongue only)
FE_IDS = {env_id: scene for env_id, scene in {**ENV_SCENES, **HAPTIC_SCENES}.items() if env_id != "SoftSphereAirway-v0"}


def default_request(**sections) -> FERequest:
    return fe_request(make_config(**{**sections, "tissue": {**FEM["tissue"], **sections.get("tissue", {})}}))


@pytest.fixture(scope="module")
def shipped() -> FESceneData:
    path = shipped_file(default_request())
    assert path is not None, "the default FE scene's data must ship with softenv (scripts/make_fem_data.py)"
    return FESceneData.load(path, default_request())


def test_every_default_scene_id_finds_the_shipped_fe_data():
    for env_id, scene in FE_IDS.items():
        assert shipped_file(fe_request(scene_config(scene, FEM))) is not None, env_id
    assert set(ENV_SCENES) | set(HAPTIC_SCENES) == set(FE_IDS) | {"SoftSphereAirway-v0"}     # it alone left out


def test_shipped_data_hold_the_workspace_the_held_out_solves_and_a_rising_contact_curve(shipped):
    request = shipped.request
    assert shipped.train.n_samples == request.n_contacts * request.n_loads * request.steps == 1024
    assert shipped.test.n_samples == request.n_test_contacts * request.n_loads * request.steps
    # held-out contact points are other points (no train contact within 1e-9 of a test one)
    train_contacts = np.unique(shipped.train.forces[:, :2], axis=0)
    test_contacts = np.unique(shipped.test.forces[:, :2], axis=0)
    gaps = np.abs(train_contacts[:, None, :] - test_contacts[None, :, :]).max(axis=2)
    assert gaps.min() > 1e-9
    # every sample lies in the device's box; each ramp's load steps scale its final load
    assert (shipped.train.forces >= np.array(request.low) - 1e-12).all()
    assert (shipped.train.forces <= np.array(request.high) + 1e-12).all()
    ramp = shipped.train.forces[: request.steps]
    np.testing.assert_allclose(ramp[:, 2:] / ramp[-1, 2:], np.outer(np.arange(1, 5) / 4, [1, 1]), rtol=1e-12)
    assert np.all(np.diff(shipped.curve_depths) > 0) and shipped.curve_loads[-1] == request.high[2]


@pytest.mark.parametrize("change, field", [({"tissue": {"E": 2e5}}, "fe.E"), ({"tissue": {"nu": 0.495, "E": FEParams().E}}, "fe.nu"),
                                           ({"mesh": {"resolution": 15}}, "mesh"),
                                           ({"tissue": {"fe_cells": 4}}, "fe.cells_per_side"),
                                           ({"device": {"max_normal_force": 30.0}, "task": {"target_normal_force": (10.0, 30.0)}}, "high")])
def test_fe_data_of_another_mesh_or_material_are_refused_by_name(shipped, change, field):
    other = default_request(**change)
    with pytest.raises(ValueError, match=rf"holds FE data for another scene: {field}="):
        FESceneData.load(shipped_file(default_request()), other)
    assert shipped_file(other) is None                  # and no scene would pick the file up


def test_fe_data_of_another_format_version_are_refused(shipped, tmp_path):
    path = tmp_path / "old.npz"
    shipped.save(path)
    with zipfile.ZipFile(path) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    meta = np.load(path)["__meta__"][()]
    header = json.loads(str(meta))
    header["format_version"] = 0
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in members.items():
            if name != "__meta__.npy":
                archive.writestr(name, data)
        with archive.open("__meta__.npy", "w") as handle:
            np.lib.format.write_array(handle, np.array(json.dumps(header)))
    with pytest.raises(ValueError, match="format_version=0"):
        FESceneData.load(path, shipped.request)


def test_a_saved_copy_loads_back_bit_for_bit(shipped, tmp_path):
    shipped.save(tmp_path / "copy.npz")
    copy = FESceneData.load(tmp_path / "copy.npz", shipped.request)
    for part in ("train", "test"):
        for name in ("forces", "shapes", "contact_ids"):
            assert np.array_equal(getattr(getattr(copy, part), name), getattr(getattr(shipped, part), name))
    assert copy.lateral_compliance == shipped.lateral_compliance


def test_an_fe_scene_that_needs_generation_without_the_fem_extra_says_how(monkeypatch):
    monkeypatch.setitem(sys.modules, "softenv.fem.data", None)        # as if FElupe were not installed
    with pytest.raises(ImportError, match=r"pip install 'softenv\[fem\]'"):
        scene_data(default_request(shape_model={"n_contacts": 9}))


@pytest.mark.parametrize("sections, name", [({"tissue": {"law": "stiffening"}}, "tissue.law"),
                                            ({"tissue": {"nu": 0.49995}}, "tissue.nu"),
                                            ({"tissue": {"E": 1e10}}, "tissue.E"),
                                            ({"tissue": {"fe_cells": 64}}, "tissue.fe_cells"),
                                            ({"shape_model": {"n_loads": 6}}, "shape_model.n_loads")])
def test_out_of_range_fe_settings_are_refused_by_name(sections, name):
    with pytest.raises(ValueError, match=name):
        make_config(**{"tissue": {**FEM["tissue"], **sections.get("tissue", {})},
                       **{k: v for k, v in sections.items() if k != "tissue"}})


@pytest.mark.parametrize("grade", [1, 4])
def test_a_force_beyond_the_fe_tongues_verified_indentation_is_refused_before_any_solve(grade):
    # 60 N on the normal tongue indents 0.6 of the radius; grade 4's tongue is 1.15 times as stiff: 0.6 / 1.15
    with pytest.raises(ValueError, match=rf"device.max_normal_force=60 N indents the FE tongue by "
                                         rf"{0.6 / airway({'grade': grade, **{k: None for k in SETTINGS}}).tongue_stiffness:.3g} "
                                         r"of its radius .* verified up to 0.4"):
        gym.make("SoftSphereAirway-v0", **FEM, airway={"grade": grade})
    # the same tongue at the largest force its ramps are verified for is accepted
    make_config(tissue=FEM["tissue"], device={"max_normal_force": 40.0})


def test_the_fe_scenes_response_reproduces_held_out_fe_solves_better_than_the_papers_best_regressor():
    scene = gym.make("SoftSphere-v0", **FEM).unwrapped.world.scene
    err = scene.response_error()
    poly3 = gym.make("SoftSphere-v0", **FEM, response={"model": "poly3"}).unwrapped.world.scene.response_error()
    # held-out surfaces move by ~1.5 mm RMS (median); the tabulated RBF misses them by well under 0.1 mm
    assert err["median_mm"] < 0.1 and err["max_mm"] < 1.0
    assert err["median_mm"] < 0.5 * poly3["median_mm"]
    with pytest.raises(ValueError, match="no closed-form response"):
        scene.exact_response()
    assert gym.make("SoftSphereHaptic-v0", **FEM).unwrapped.world.scene is scene     # one scene per process


def test_the_rbf_interpolates_its_samples_and_reproduces_a_linear_field_exactly(tmp_path):
    from softenv.response import RBFResponse, ResponseModel

    rng = np.random.default_rng(0)
    x = rng.uniform(-1, 1, (60, 4))
    y = np.column_stack([np.sin(3 * x[:, 0]) * x[:, 1], x @ [1.0, -2.0, 0.5, 3.0] + 1.0])
    model = RBFResponse().fit(x, y)
    np.testing.assert_allclose(model.predict(x), y, atol=1e-9)            # through every sample
    linear = RBFResponse().fit(x, y[:, 1:])                               # the linear tail holds a linear field
    probe = rng.uniform(-1, 1, (50, 4))
    np.testing.assert_allclose(linear.predict(probe)[:, 0], probe @ [1.0, -2.0, 0.5, 3.0] + 1.0, atol=1e-8)
    model.save(tmp_path / "rbf.npz")
    assert np.array_equal(ResponseModel.load(tmp_path / "rbf.npz").predict(probe), model.predict(probe))
    with pytest.raises(ValueError, match="repeated rows"):
        RBFResponse().fit(np.vstack([x, x[:1]]), np.vstack([y, y[:1]]))


@pytest.mark.parametrize("env_id", sorted(FE_IDS))
def test_every_id_runs_on_fe_tissue_and_single_and_batched_envs_agree(env_id):
    env = gym.make(env_id, **FEM)
    venv = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point", **FEM)
    obs, _ = env.reset(seed=3)
    vobs, _ = venv.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(15):
        action = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        obs, reward, *_ = env.step(action)
        vobs, vreward, *_ = venv.step(np.stack([action, action]))
        assert np.isfinite(obs).all()
    assert np.array_equal(obs, vobs[0]) and reward == vreward[0]


def test_a_held_press_on_fe_tissue_reaches_the_fe_curves_indentation():
    from softenv.devices.laryngoscope.part import laryngoscope_parts
    from softenv.devices.laryngoscope.single import Laryngoscope
    from softenv.envs.world import World

    world = World(scene_config(HAPTIC_SCENES["SoftSphereHaptic-v0"], FEM))
    dev = Laryngoscope(*laryngoscope_parts(world.scene, world.config))
    press, hold = np.array([0.0, 1.0, 0.0, 0.0]), np.zeros(4)
    for _ in range(6):
        dev.control_step(press)
    for _ in range(100):                                      # 2 s held: settled
        dev.control_step(hold)
    P = dev.normal_force
    fe = world.scene.fe
    assert 5.0 < P < fe.curve_loads[-1]
    # the FE solves' indentation for that force (their curve between its solved load steps)
    want = np.interp(P, np.r_[0.0, fe.curve_loads], np.r_[0.0, fe.curve_depths])
    assert dev.penetration() == pytest.approx(want, rel=0.02)


def test_a_scene_reading_shipped_fe_data_imports_no_fe_code_or_library(heavy_modules_after):
    code = ("import sys, gymnasium as gym\n"
            "env = gym.make('softenv:SoftSphere-v0', tissue={'model': 'fem'})\n"
            "env.reset(seed=0)\n"
            "for _ in range(10): env.step(env.action_space.sample())\n"
            "fe = [m for m in ('softenv.fem.tongue', 'softenv.fem.data', 'softenv.fem.mesh') if m in sys.modules]\n"
            "assert not fe, fe\n")
    assert heavy_modules_after(code) == []


def test_fe_request_follows_the_scene_config():
    request = default_request(tissue={"fe_cells": 6}, shape_model={"n_loads": 8, "seed": 2})
    assert request.fe.cells_per_side == 6 and request.n_loads == 2 and request.seed == 2
    assert dataclasses.replace(request, seed=0).difference(request) == "seed=2 where this scene needs seed=0"


def test_an_analytic_scene_is_keyed_as_before_the_fem_model():
    """Caches and saved agents made before tissue.model existed keep their keys: an analytic tissue is
    keyed by its resolved E and nu without the FE keys, so leaving E at its default or giving that value
    is the same scene; an FE tissue keeps its own keys."""
    from softenv.envs.config import config_key, material

    sections = ("tissue", "mesh", "device", "task")
    default = make_config()
    E, nu = material(default["tissue"])
    key = config_key(default, sections)
    assert key == config_key(make_config(tissue={"E": E, "nu": nu}), sections)
    assert "fe_cells" not in key and "'model'" not in key and f"('E', {E!r})" in key
    assert key != config_key(make_config(tissue={"E": 2 * E}), sections)
    fem = config_key(make_config(tissue={"model": "fem"}), sections)
    assert "('fe_cells', 8)" in fem and fem != key


def test_the_fem_data_check_compares_the_arrays_bit_for_bit_then_by_their_largest_difference(tmp_path):
    """``scripts/make_fem_data.py --check``'s comparison: 0.0 for equal arrays (the metadata aside), else the
    largest difference of an array over its own largest magnitude, and a refusal naming the array when the
    two files do not hold the same arrays."""
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location(
        "make_fem_data", Path(__file__).resolve().parent.parent / "scripts" / "make_fem_data.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    shapes = np.arange(12.0).reshape(3, 4) - 4.0                       # largest magnitude 7
    loads = np.array([10.0, 40.0])                                    # largest magnitude 40
    np.savez(tmp_path / "a.npz", shapes=shapes, loads=loads, __meta__=np.array("one"))
    np.savez(tmp_path / "b.npz", shapes=shapes.copy(), loads=loads.copy(), __meta__=np.array("another"))
    assert script.largest_difference(tmp_path / "a.npz", tmp_path / "b.npz") == 0.0
    moved = shapes.copy()
    moved[1, 2] += 3.5e-9                                             # 0.5e-9 of the shapes' 7
    np.savez(tmp_path / "c.npz", shapes=moved, loads=loads + [0.0, 4e-9], __meta__=np.array("one"))   # 1e-10 of 40
    assert script.largest_difference(tmp_path / "a.npz", tmp_path / "c.npz") == pytest.approx(0.5e-9, rel=1e-6)
    np.savez(tmp_path / "d.npz", shapes=shapes[:2], loads=loads, __meta__=np.array("one"))
    with pytest.raises(ValueError, match=r"shapes: .*d\.npz has float64\[2, 4\]"):
        script.largest_difference(tmp_path / "a.npz", tmp_path / "d.npz")
    np.savez(tmp_path / "e.npz", shapes=shapes, __meta__=np.array("one"))
    with pytest.raises(ValueError, match="holds arrays"):
        script.largest_difference(tmp_path / "a.npz", tmp_path / "e.npz")
