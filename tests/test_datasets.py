import os
import time

import numpy as np
import pytest

from softenv._artifact import save_artifact
from softenv.datasets import ForceShapeData, paper_dataset, split_by_contact, split_rows, workspace_dataset
from softenv.forces import DorsumLayout, PaperLayout, Workspace, sample_workspace, unit_samples
from softenv.geometry import latlong_mesh
from softenv.tissue import AnalyticTissue


def test_paper_dataset_protocol():
    d = paper_dataset(441, n_deformations=4, n_magnitudes=11, noise=0.0)
    assert d.forces.shape == (44, 4) and d.shapes.shape == (44, 1323)
    assert d.n_contacts == 4
    np.testing.assert_allclose(np.linalg.norm(d.forces[:, :3], axis=1), d.tissue.radius, rtol=1e-12)
    assert (d.forces[:, 2] > 0).all()                       # contacts on the dorsum (upper cap)
    mags = d.forces[d.contact_ids == 0, 3]
    np.testing.assert_allclose(mags, 8.0 * np.arange(1, 12) / 11)
    # noise-free rows equal the tissue model's surfaces for the recorded force vectors
    expected = AnalyticTissue(d.mesh, d.tissue).surfaces(*d.layout.to_loads(d.forces))
    np.testing.assert_array_equal(d.shapes, expected)


def test_paper_dataset_noise_has_the_requested_level_and_is_seeded():
    clean = paper_dataset(441, noise=0.0, seed=3)
    noisy = paper_dataset(441, noise=1e-4, seed=3)
    again = paper_dataset(441, noise=1e-4, seed=3, cache=False)
    np.testing.assert_array_equal(noisy.shapes, again.shapes)
    resid = noisy.shapes - clean.shapes
    assert resid.std() == pytest.approx(1e-4 * 0.03, rel=0.02)
    other = paper_dataset(441, noise=1e-4, seed=4)
    assert not np.array_equal(other.forces, noisy.forces)


def test_cache_makes_a_repeat_instant_and_survives_corruption(tmp_path, monkeypatch):
    monkeypatch.setenv("SOFTENV_CACHE_DIR", str(tmp_path))
    t0 = time.perf_counter()
    first = paper_dataset(961, n_deformations=10)
    t1 = time.perf_counter()
    second = paper_dataset(961, n_deformations=10)
    t2 = time.perf_counter()
    np.testing.assert_array_equal(first.shapes, second.shapes)
    files = list(tmp_path.glob("paper-*.npz"))
    assert len(files) == 1
    files[0].write_bytes(b"not a zip file")
    with pytest.warns(RuntimeWarning, match="rebuilding unreadable cache entry"):
        third = paper_dataset(961, n_deformations=10)
    np.testing.assert_array_equal(first.shapes, third.shapes)
    assert (t2 - t1) < (t1 - t0) or (t2 - t1) < 0.05


def test_a_cache_entry_is_built_on_one_thread_whatever_threads_the_caller_runs(tmp_path, monkeypatch):
    from threadpoolctl import threadpool_info, threadpool_limits

    from softenv._cache import cached

    monkeypatch.setenv("SOFTENV_CACHE_DIR", str(tmp_path))
    with threadpool_limits(limits=2):
        assert max(pool["num_threads"] for pool in threadpool_info()) == 2       # the caller's: two
        seen = cached("threads", {}, lambda: [pool["num_threads"] for pool in threadpool_info()],
                      load=lambda path: None, save=lambda value, path: np.savez(path, seen=value))
        assert max(pool["num_threads"] for pool in threadpool_info()) == 2       # given back after the build
    assert seen and set(seen) == {1}


def test_a_build_runs_a_loaded_torch_and_its_mkl_on_one_thread_and_gives_its_threads_back(tmp_path, monkeypatch):
    import torch

    from softenv._cache import cached

    monkeypatch.setenv("SOFTENV_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("MKL_NUM_THREADS", "2")
    caller = torch.get_num_threads()
    torch.set_num_threads(2)                    # torch's MKL is linked into it: threadpoolctl cannot see it
    try:
        info = cached("torch-threads", {}, torch.__config__.parallel_info, load=lambda path: None,
                      save=lambda value, path: np.savez(path, info=value))
        assert "at::get_num_threads() : 1" in info and "mkl_get_max_threads() : 1" in info
        assert torch.get_num_threads() == 2 and "mkl_get_max_threads() : 2" in torch.__config__.parallel_info()
        assert os.environ["MKL_NUM_THREADS"] == "2"                              # the variables given back too
    finally:
        torch.set_num_threads(caller)


# a process that first imports torch inside a build: torch loads on one thread there, and afterwards takes
# the threads its variables ask for
_IMPORT_TORCH_IN_A_BUILD = """
import sys, numpy as np
from softenv._cache import cached
inside = cached("torch-import", {}, lambda: __import__("torch").__config__.parallel_info(), load=lambda path: None,
                save=lambda value, path: np.savez(path, info=value))
print("at::get_num_threads() : 1" in inside and "mkl_get_max_threads() : 1" in inside,
      sys.modules["torch"].get_num_threads())
"""


def test_a_torch_first_imported_in_a_build_runs_on_one_thread_there_and_on_the_asked_threads_after(tmp_path):
    import subprocess
    import sys

    env = {**os.environ, "SOFTENV_CACHE_DIR": str(tmp_path), "OMP_NUM_THREADS": "2", "MKL_NUM_THREADS": "2"}
    done = subprocess.run([sys.executable, "-c", _IMPORT_TORCH_IN_A_BUILD], env=env, check=True,
                          capture_output=True, text=True)
    assert done.stdout.split() == ["True", str(min(2, os.cpu_count() or 1))]


def test_without_threadpoolctl_an_unpinned_build_warns_and_a_pinned_one_does_not(tmp_path, monkeypatch):
    import warnings

    import softenv._cache as cache

    monkeypatch.setenv("SOFTENV_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(cache, "threadpool_limits", None)       # a core install: numpy and gymnasium only
    save = lambda value, path: np.savez(path, value=value)      # noqa: E731
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
    with pytest.warns(RuntimeWarning, match="OPENBLAS_NUM_THREADS"):
        assert cache.cached("unpinned", {}, lambda: 1, load=lambda path: None, save=save) == 1
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert cache.cached("pinned", {}, lambda: 2, load=lambda path: None, save=save) == 2


# a default-size scene whose PCA and L-BFGS-trained MLP are large enough for two BLAS / OpenMP threads to
# change their bits when the build runs on them (before builds were pinned: the MLP's weights by up to 0.1)
_BUILD_MLP_SCENE = """
import sys, numpy as np, gymnasium as gym, softenv
scene = gym.make("SoftSphere-v0", response={"model": "mlp"}).unwrapped.world.scene
np.savez(sys.argv[1], components=scene.shape_model.components_,
         **{f"p{i}": p for i, p in enumerate(scene.response.params_)})
"""


@pytest.mark.slow
def test_a_scene_built_by_a_two_thread_process_is_the_one_thread_scene_bit_for_bit(tmp_path):
    import subprocess
    import sys

    built = []
    for threads in ("2", "1"):
        env = {**os.environ, "SOFTENV_CACHE_DIR": str(tmp_path / threads), "OMP_NUM_THREADS": threads,
               "OPENBLAS_NUM_THREADS": threads, "MKL_NUM_THREADS": threads}
        out = tmp_path / f"scene-{threads}.npz"
        subprocess.run([sys.executable, "-c", _BUILD_MLP_SCENE, str(out)], env=env, check=True)
        built.append(np.load(out))
    assert len(built[0].files) > 2
    for name in built[0].files:
        np.testing.assert_array_equal(built[0][name], built[1][name], err_msg=name)


def test_save_load_round_trip(tmp_path):
    d = paper_dataset(441, n_deformations=3)
    path = tmp_path / "d.npz"
    d.save(path)
    e = ForceShapeData.load(path)
    np.testing.assert_array_equal(d.forces, e.forces)
    np.testing.assert_array_equal(d.shapes, e.shapes)
    assert e.mesh.fingerprint == d.mesh.fingerprint and e.tissue == d.tissue and e.layout == d.layout
    assert not list(tmp_path.glob("*.tmp"))               # atomic write leaves no temporary


def test_loading_refuses_foreign_stale_and_corrupt_files(tmp_path):
    d = paper_dataset(441, n_deformations=2)
    good = tmp_path / "good.npz"
    d.save(good)
    stale = tmp_path / "stale.npz"
    with np.load(good, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files if k != "__meta__"}
    save_artifact(stale, "softenv.ForceShapeData", 99, arrays, {})
    with pytest.raises(ValueError, match="format_version=99"):
        ForceShapeData.load(stale)
    other = tmp_path / "other.npz"
    save_artifact(other, "softenv.ShapeModel", 1, {"x": np.zeros(2)}, {})
    with pytest.raises(ValueError, match="holds a 'softenv.ShapeModel' artifact; expected 'softenv.ForceShapeData'"):
        ForceShapeData.load(other)
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(good.read_bytes()[:200])
    with pytest.raises(ValueError, match="corrupt"):
        ForceShapeData.load(corrupt)
    plain = tmp_path / "plain.npz"
    np.savez(plain, forces=np.zeros((2, 4)))
    with pytest.raises(ValueError, match="not a softenv artifact"):
        ForceShapeData.load(plain)
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, __meta__=np.array([{"kind": "x"}], dtype=object))
    with pytest.raises(ValueError, match="without pickle"):
        ForceShapeData.load(pickled)
    with pytest.raises(ValueError, match="does not exist"):
        ForceShapeData.load(tmp_path / "missing.npz")


def test_splits_partition_rows_and_hold_out_whole_contacts():
    d = paper_dataset(441)
    rows = split_rows(d.n_samples, seed=1)
    allrows = np.concatenate(rows)
    assert sorted(allrows.tolist()) == list(range(110))
    assert len(rows.train) == 77 and sorted([len(rows.validation), len(rows.test)]) == [16, 17]
    by = split_by_contact(d.contact_ids, seed=1)
    assert sorted(np.concatenate(by).tolist()) == list(range(110))
    parts = [set(d.contact_ids[p]) for p in by]
    assert not (parts[0] & parts[1]) and not (parts[0] & parts[2]) and not (parts[1] & parts[2])
    assert [len(p) for p in parts] == [7, 2, 1]
    with pytest.raises(ValueError, match="cannot split 2 items into 3 non-empty parts"):
        split_by_contact(np.array([0, 0, 1]))
    with pytest.raises(ValueError, match="summing to 1"):
        split_rows(10, (0.5, 0.5, 0.5))


def test_latin_hypercube_hits_every_stratum_once():
    u = unit_samples(50, 3, "lhs", seed=2)
    for j in range(3):
        assert sorted(np.floor(u[:, j] * 50).astype(int).tolist()) == list(range(50))
    s = unit_samples(64, 3, "sobol", seed=2)
    assert s.shape == (64, 3) and (s >= 0).all() and (s < 1).all()
    # scrambled Sobol points are balanced: each half of each axis holds exactly half of 2^m points
    assert ((s < 0.5).sum(axis=0) == 32).all()


def test_workspace_sampling_stays_in_the_box_and_groups_contacts():
    ws = Workspace(low=(0.03, -0.005, 0.0, -5.0), high=(0.06, 0.005, 40.0, 5.0))
    forces, ids = sample_workspace(ws, n_contacts=8, n_loads=5, seed=0)
    assert forces.shape == (40, 4)
    assert (forces >= np.array(ws.low)).all() and (forces <= np.array(ws.high)).all()
    for i in range(8):
        rows = forces[ids == i]
        assert (rows[:, :2] == rows[0, :2]).all()          # one contact point per group
    mesh = latlong_mesh(15)
    data = workspace_dataset(ws, DorsumLayout(0.03), mesh, n_contacts=8, n_loads=5)
    assert data.shapes.shape == (40, 675)
    with pytest.raises(ValueError, match="workspace high\\[0\\]=0 is below low\\[0\\]=1"):
        Workspace(low=(1.0,), high=(0.0,), n_contact=1)


def test_layouts_convert_force_vectors_to_loads():
    R = 0.03
    lay = DorsumLayout(R)
    c, f = lay.to_loads([[R * np.pi / 2, 0.0, 10.0, 0.0], [0.0, 0.0, 0.0, 3.0]])
    np.testing.assert_allclose(c[0], [0, 0, R], atol=1e-15)            # top of the sphere
    np.testing.assert_allclose(f[0], [0, 0, -10.0], atol=1e-12)        # pressing straight down
    np.testing.assert_allclose(c[1], [R, 0, 0], atol=1e-15)            # front of the sphere
    np.testing.assert_allclose(f[1], [0, 3.0, 0], atol=1e-15)          # sideways is +y
    with pytest.raises(ValueError, match=r"normal\) = -1 N is negative"):
        lay.to_loads([[0.01, 0.0, -1.0, 0.0]])
    with pytest.raises(ValueError, match=r"magnitude F\) = -2 N is negative"):
        PaperLayout().to_loads([[0, 0, R, -2.0]])
    with pytest.raises(ValueError, match=r"forces must have trailing shape \(4\)"):
        PaperLayout().to_loads([[0, 0, R]])


def test_bad_dataset_arguments():
    with pytest.raises(ValueError, match="n_deformations=0 is out of range"):
        paper_dataset(441, n_deformations=0)
    with pytest.raises(ValueError, match="noise=-1 is out of range"):
        paper_dataset(441, noise=-1.0)
    with pytest.raises(ValueError, match="law='elastic' is not allowed"):
        paper_dataset(441, law="elastic")
    with pytest.raises(ValueError, match="n_points=440 is not a square"):
        paper_dataset(440)
