import numpy as np
import pytest

from softenv.datasets import paper_dataset
from softenv.geometry import interpolate_latlong, latlong_mesh
from softenv.scree import cattell_scree, kneedle, noise_floor, variance_fraction
from softenv.shape_model import ShapeModel


@pytest.mark.parametrize("n_points", [441, 961])
@pytest.mark.parametrize("n_def", list(range(1, 11)))
def test_scree_keeps_one_component_per_deformation(n_points, n_def):
    """Paper 4.3: the number of components equals the number of deformations, at 441 and 961 points."""
    d = paper_dataset(n_points, n_deformations=n_def, noise=1e-5)
    model = ShapeModel("scree").fit(d.shapes, d.mesh)
    assert model.n_components_ == n_def
    assert ShapeModel("noise", noise_std=d.noise_std).fit(d.shapes).n_components_ == n_def


@pytest.mark.parametrize("n_def", [4, 10])
def test_components_move_the_surface_the_same_way_at_441_and_961_points(n_def):
    """Paper 4.3: each component of the 441-point model controls the shape as at 961 points (up to sign)."""
    a, b = paper_dataset(441, n_deformations=n_def), paper_dataset(961, n_deformations=n_def)
    ma = ShapeModel("scree").fit(a.shapes, a.mesh)
    mb = ShapeModel("scree").fit(b.shapes, b.mesh)
    for i in range(n_def):
        field_b_on_a = interpolate_latlong(mb.components_[i], 31, a.mesh.vertices).ravel()
        assert abs(np.corrcoef(ma.components_[i], field_b_on_a)[0, 1]) >= 0.99
    # eigenvalues are sums over points: they scale with the point count
    np.testing.assert_allclose(ma.explained_variance_ / mb.explained_variance_, 441 / 961, rtol=0.01)


@pytest.mark.parametrize("sigma", [1e-5, 1e-4])
def test_reconstruction_error_is_of_the_order_of_the_noise(sigma):
    d = paper_dataset(961, noise=sigma)
    clean = paper_dataset(961, noise=0.0)
    model = ShapeModel("scree").fit(d.shapes)
    rmse_vs_data = np.sqrt(np.mean((model.reconstruct(d.shapes) - d.shapes) ** 2))
    rmse_vs_truth = np.sqrt(np.mean((model.reconstruct(d.shapes) - clean.shapes) ** 2))
    noise = sigma * d.tissue.radius
    assert 0.8 * noise < rmse_vs_data < 1.05 * noise      # what is left is the noise itself
    # what remains of the noise is its projection on the mean and the k components: sigma sqrt((k + 1) / n)
    k, n = model.n_components_, d.n_samples
    assert rmse_vs_truth == pytest.approx(noise * np.sqrt((k + 1) / n), rel=0.15)


def test_solvers_agree():
    d = paper_dataset(441, noise=1e-5)
    gram = ShapeModel(10, solver="gram").fit(d.shapes)
    svd = ShapeModel(10, solver="svd").fit(d.shapes)
    rnd = ShapeModel(10, solver="randomized", random_state=1).fit(d.shapes)
    for other in (svd, rnd):
        np.testing.assert_allclose(other.explained_variance_, gram.explained_variance_, rtol=1e-6)
        # same subspace and, with the sign rule, the same vectors
        np.testing.assert_allclose(other.components_, gram.components_, atol=1e-5)
    np.testing.assert_allclose(rnd.total_variance_, gram.total_variance_, rtol=1e-12)


def test_components_are_orthonormal_and_b_distance_is_surface_distance():
    d = paper_dataset(961)
    model = ShapeModel("scree").fit(d.shapes)
    np.testing.assert_allclose(model.components_ @ model.components_.T, np.eye(model.n_components_), atol=1e-12)
    rng = np.random.default_rng(0)
    b1, b2 = rng.standard_normal((2, model.n_components_)) * model.sqrt_variance_
    x1, x2 = model.decode(b1), model.decode(b2)
    assert np.linalg.norm(x1 - x2) == pytest.approx(np.linalg.norm(b1 - b2), rel=1e-12)
    rms = np.sqrt(np.mean(np.sum((x1 - x2).reshape(-1, 3) ** 2, axis=1)))
    assert model.rms_distance(b1, b2) == pytest.approx(rms, rel=1e-12)


def test_fit_is_deterministic_including_signs():
    d = paper_dataset(441)
    m1 = ShapeModel("scree").fit(d.shapes)
    m2 = ShapeModel("scree").fit(d.shapes[::-1].copy())
    np.testing.assert_allclose(m1.components_, m2.components_, atol=1e-12)
    for c in m1.components_:
        assert c[np.argmax(np.abs(c))] > 0


def test_decode_single_batched_float32_out_and_subset():
    d = paper_dataset(961)
    model = ShapeModel(10).fit(d.shapes)
    b = model.encode(d.shapes[:5])
    np.testing.assert_allclose(model.decode(b), model.mean_ + b @ model.components_, rtol=0, atol=1e-15)
    for i in range(5):
        np.testing.assert_allclose(model.decode(b[i]), model.decode(b)[i], atol=1e-15)
    b32 = b.astype(np.float32)
    out = np.empty(2883, np.float32)
    res = model.decode(b32[0], out=out)
    assert res is out and res.dtype == np.float32
    np.testing.assert_allclose(out, model.decode(b[0]), atol=1e-7)
    verts = np.array([3, 500, 960])
    cols = (3 * verts[:, None] + np.arange(3)).ravel()
    np.testing.assert_allclose(model.decode(b, vertices=verts), model.decode(b)[:, cols], atol=1e-15)
    np.testing.assert_allclose(model.decode(b32[1], vertices=verts), model.decode(b32[1])[cols], atol=1e-7)


def test_batched_decode_spans_row_blocks():
    """Batched decode writes its output in row blocks; a batch over many blocks, ending in a partial
    one, must equal the one-product formula in both precisions and with a caller's ``out``."""
    d = paper_dataset(961)
    model = ShapeModel(10).fit(d.shapes)
    rng = np.random.default_rng(3)
    b = rng.normal(size=(101, 10)) * np.sqrt(model.explained_variance_)
    expected = model.mean_ + b @ model.components_
    np.testing.assert_allclose(model.decode(b), expected, rtol=0, atol=1e-15)
    out = np.full((101, 2883), np.nan, np.float32)
    model.decode(b.astype(np.float32), out=out)
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-6)


def test_decode_blocks_fit_the_blas_kernels(monkeypatch):
    from softenv import shape_model

    monkeypatch.setattr(shape_model, "has_small_gemm", lambda: True)  # each block within the small-GEMM path
    rows = shape_model.decode_block_rows(2883, 11, 4)
    assert rows * 2883 * 11 <= shape_model.SMALL_GEMM_MAX_MNK < (rows + 1) * 2883 * 11
    monkeypatch.setattr(shape_model, "has_small_gemm", lambda: False)  # each block's output within 768 KiB
    rows = shape_model.decode_block_rows(2883, 11, 4)
    assert rows * 2883 * 4 <= 768 * 1024 < (rows + 1) * 2883 * 4
    assert shape_model.decode_block_rows(10**7, 11, 8) == 4  # never fewer than a few shapes per product


def test_decode_and_encode_refuse_bad_input():
    d = paper_dataset(441, n_deformations=3)
    model = ShapeModel("scree").fit(d.shapes)
    with pytest.raises(ValueError, match=r"b must have shape \(3,\) or \(N, 3\), got \(4,\)"):
        model.decode(np.zeros(4))
    with pytest.raises(ValueError, match="b must be finite; found nan at index \\(1,\\)"):
        model.decode(np.array([0.0, np.nan, 0.0]))
    with pytest.raises(ValueError, match="out must be a C-contiguous float64 array of shape \\(1323,\\)"):
        model.decode(np.zeros(3), out=np.empty(1323, np.float32))
    with pytest.raises(ValueError, match="shapes must have trailing shape \\(1323\\)"):
        model.encode(np.zeros(10))
    with pytest.raises(ValueError, match="vertices must be indices in \\[0, 440\\]"):
        model.decode(np.zeros(3), vertices=np.array([441]))
    with pytest.raises(RuntimeError, match="not fitted"):
        ShapeModel().decode(np.zeros(3))


def test_fit_refuses_bad_data():
    d = paper_dataset(441, n_deformations=2, n_magnitudes=5)
    with pytest.raises(ValueError, match="n_components=12 needs at least 13 samples"):
        ShapeModel(12).fit(d.shapes)
    with pytest.raises(ValueError, match="exceeds the numerical rank"):
        ShapeModel(5).fit(paper_dataset(441, n_deformations=2, n_magnitudes=5, noise=0.0).shapes)
    bad = d.shapes.copy()
    bad[2, 7] = np.inf
    with pytest.raises(ValueError, match="shapes must be finite; found inf at index \\(2, 7\\)"):
        ShapeModel().fit(bad)
    with pytest.raises(ValueError, match="shapes have 1323 coordinates but the mesh has 961 vertices"):
        ShapeModel().fit(d.shapes, latlong_mesh(31))
    with pytest.raises(ValueError, match="needs noise_std"):
        ShapeModel("noise").fit(d.shapes)
    with pytest.raises(ValueError, match="n_components='elbow' is not a rule"):
        ShapeModel("elbow").fit(d.shapes)
    with pytest.raises(ValueError, match="solver='qr' is not allowed"):
        ShapeModel(solver="qr")


def test_plausibility_regions():
    from scipy.stats import chi2

    d = paper_dataset(961)
    model = ShapeModel("scree").fit(d.shapes)
    k = model.n_components_
    assert model.mahalanobis_bound() == pytest.approx(chi2.ppf(0.9973002039367398, k), rel=0.01)
    assert model.mahalanobis_bound(0.5) == pytest.approx(chi2.ppf(0.5, k), rel=0.01)
    b = model.encode(d.shapes)
    assert model.is_plausible(b, "data").all()
    far = 10 * model.b_max_
    assert not model.is_plausible(far, "data")
    clipped = model.clip_plausible(far, "ellipsoid")
    assert model.mahalanobis_squared(clipped) == pytest.approx(model.mahalanobis_bound())
    np.testing.assert_allclose(clipped / np.linalg.norm(clipped), far / np.linalg.norm(far))  # radial
    lo, hi = model.plausible_box(3.0)
    np.testing.assert_allclose(model.clip_plausible(far, "box"), np.clip(far, lo, hi))
    np.testing.assert_allclose(hi, 3 * np.sqrt(model.explained_variance_))
    inside = b[5]
    np.testing.assert_array_equal(model.clip_plausible(inside, "data"), inside)


def test_save_load_round_trip_and_mesh_check(tmp_path):
    d = paper_dataset(441)
    model = ShapeModel("scree", noise_std=d.noise_std).fit(d.shapes, d.mesh)
    path = tmp_path / "m.npz"
    model.save(path)
    back = ShapeModel.load(path, mesh=d.mesh)
    np.testing.assert_array_equal(back.components_, model.components_)
    np.testing.assert_array_equal(back.b_min_, model.b_min_)
    assert back.picks_ == model.picks_ and back.rule_ == "scree" and back.fingerprint() == model.fingerprint()
    with pytest.raises(ValueError, match="was fitted on mesh 'latlong-21-.*not on the given mesh 'latlong-31-"):
        ShapeModel.load(path, mesh=latlong_mesh(31))
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["components"] = arrays["components"][:, :-3]
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(ValueError, match="inconsistent arrays"):
        ShapeModel.load(tmp_path / "bad.npz")


def test_scree_rules_on_synthetic_spectra():
    rng = np.random.default_rng(0)
    signal = 10.0 ** -np.arange(7)                      # 7 components above a noise floor
    noise = 1e-9 * (1 + 0.1 * rng.standard_normal(50))
    lam = np.sort(np.concatenate([signal, np.abs(noise)]))[::-1]
    assert cattell_scree(lam) == 7
    assert noise_floor(lam * 0 + np.r_[np.full(3, 10.0), np.full(54, 0.5)], 1.0, 100, 50) == 3
    assert variance_fraction(np.array([6.0, 3.0, 1.0]), 0.9) == 2
    assert kneedle(np.array([100.0, 50.0, 1.0, 1.0, 1.0])) == 2
    assert cattell_scree(np.r_[np.full(4, 1.0), np.zeros(30)]) == 4   # noise-free rank 4
