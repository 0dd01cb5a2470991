import subprocess
import sys
from math import comb

import numpy as np
import pytest

from softenv.datasets import paper_dataset, split_rows
from softenv.forces import Workspace
from softenv.response import (AnfisResponse, ExactResponse, MinMaxScaler, MLPResponse, PolynomialResponse,
                              ResponseModel, TabulatedResponse, tabulate)
from softenv.response.anfis import subtractive_clustering
from softenv.response.mlp import mlp_forward, nguyen_widrow
from softenv.response.polynomial import monomial_exponents
from softenv.shape_model import ShapeModel
from softenv.tissue import AnalyticTissue


@pytest.fixture(scope="module")
def paper():
    d = paper_dataset(441, n_deformations=4)
    sm = ShapeModel("scree").fit(d.shapes, d.mesh)
    return d, sm, sm.encode(d.shapes), split_rows(d.n_samples, seed=0)


def quick_models():
    return [PolynomialResponse(2), AnfisResponse(epochs=5), MLPResponse(restarts=1, max_epochs=30)]


def test_minmax_scaler_is_mapminmax():
    X = np.array([[1.0, 5.0, 2.0], [3.0, 5.0, -2.0], [2.0, 5.0, 0.0]])
    s = MinMaxScaler.fit(X)
    np.testing.assert_allclose(s.transform(X), [[-1, 0, 1], [1, 0, -1], [0, 0, 0]], atol=1e-15)
    np.testing.assert_allclose(s.inverse(s.transform(X)), X, atol=1e-15)


def test_polynomial_recovers_a_known_cubic_exactly():
    rng = np.random.default_rng(0)
    X = rng.uniform(-2, 3, (200, 4))
    x0, x1, x2, x3 = X.T
    Y = np.stack([1 + 2 * x0 - x1 * x2 + 0.5 * x3 ** 3, x0 * x1 * x3 - x2 ** 2 + 4], axis=1)
    model = PolynomialResponse(order=3).fit(X, Y)
    assert model.exponents_.shape == (comb(4 + 3, 3), 4) == (35, 4)
    Xt = rng.uniform(-2, 3, (50, 4))
    t0, t1, t2, t3 = Xt.T
    expected = np.stack([1 + 2 * t0 - t1 * t2 + 0.5 * t3 ** 3, t0 * t1 * t3 - t2 ** 2 + 4], axis=1)
    np.testing.assert_allclose(model.predict(Xt), expected, rtol=1e-9, atol=1e-9)
    assert len(monomial_exponents(4, 1)) == 5 and len(monomial_exponents(4, 2)) == 15


def test_polynomial_needs_enough_samples_without_ridge():
    X = np.random.default_rng(1).standard_normal((20, 4))
    with pytest.raises(ValueError, match="has 35 coefficients per output but only 20 training samples"):
        PolynomialResponse(3).fit(X, X[:, :2])
    PolynomialResponse(3, ridge=1e-6).fit(X, X[:, :2])


@pytest.mark.parametrize("mf", ["gbell", "gaussian"])
def test_anfis_premise_gradient_matches_finite_differences(mf):
    rng = np.random.default_rng(2)
    x = rng.uniform(-1, 1, (40, 3))
    y = np.sin(2 * x[:, :1]) + x[:, 1:2] * x[:, 2:3]
    model = AnfisResponse(n_mfs=2, mf=mf, epochs=1)
    model.fit(x, y)
    premise = model.premise_ + rng.normal(0, 0.05, model.premise_.shape)
    consequent = model.consequent_
    xs = model.input_scaler_.transform(x)
    ys = model.output_scaler_.transform(y)[:, :1].T[:, :, None]

    def error(p):
        logmu, _ = model._log_memberships(xs, p)
        _, out = model._outputs(xs, model._weights(logmu), consequent)
        return float(((out - ys) ** 2).mean())

    logmu, dlogmu = model._log_memberships(xs, premise, with_grad=True)
    w = model._weights(logmu)
    f, out = model._outputs(xs, w, consequent)
    resid = 2.0 * (out - ys) / xs.shape[0]
    G = w * np.einsum("knq,knrq->knr", resid, f - out[:, :, None, :])
    onehot = (model.rule_mf_[:, :, None] == np.arange(premise.shape[2])).astype(float)
    grad = np.einsum("knim,knimp->kimp", np.einsum("knr,rim->knim", G, onehot), dlogmu)
    eps = 1e-6
    numeric = np.zeros_like(premise)
    for idx in np.ndindex(premise.shape):
        hi, lo = premise.copy(), premise.copy()
        hi[idx] += eps
        lo[idx] -= eps
        numeric[idx] = (error(hi) - error(lo)) / (2 * eps)
    np.testing.assert_allclose(grad, numeric, rtol=1e-5, atol=1e-9)


def test_anfis_least_squares_recovers_a_takagi_sugeno_model():
    """Data made by a TS model with the initial grid premise: one LSE step recovers it exactly."""
    rng = np.random.default_rng(3)
    x = np.vstack([[-1.0, -1.0], [1.0, 1.0], rng.uniform(-1, 1, (300, 2))])   # spans [-1, 1]^2: identity scaling
    truth = AnfisResponse(n_mfs=2, epochs=1, ridge=0.0).fit(x, np.zeros((len(x), 1)))
    consequent = rng.normal(0, 1, truth.consequent_.shape)
    logmu, _ = truth._log_memberships(x, truth.premise_)
    _, y = truth._outputs(x, truth._weights(logmu), consequent)
    model = AnfisResponse(n_mfs=2, epochs=1, ridge=0.0).fit(x, y[0])
    np.testing.assert_allclose(model.predict(x), y[0], atol=1e-8)


def test_anfis_far_inputs_give_defined_bounded_outputs(paper):
    d, sm, b, sp = paper
    model = AnfisResponse(epochs=20).fit(d.forces[sp.train], b[sp.train])
    far = np.array([[1e3, -1e3, 1e3, 1e4], [1e8, 1e8, -1e8, 0.0]])
    y = model.predict(far)
    assert np.isfinite(y).all()
    # a convex combination of the rules' linear consequents at that input
    xs = model.input_scaler_.transform(far)
    x1 = np.concatenate([np.ones((2, 1)), xs], axis=1)
    f = np.einsum("ni,kriq->knrq", x1, model.consequent_)[..., 0]            # (K, N, R)
    ys = model.output_scaler_.transform(y).T
    assert (ys >= f.min(axis=2) - 1e-9).all() and (ys <= f.max(axis=2) + 1e-9).all()


def test_anfis_hybrid_learning_improves_and_keeps_the_best_epoch(paper):
    d, sm, b, sp = paper
    model = AnfisResponse(epochs=40).fit(d.forces[sp.train], b[sp.train],
                                         validation=(d.forces[sp.validation], b[sp.validation]))
    val = model.history_[:, 1, :]                       # (epochs, K)
    np.testing.assert_array_equal(model.best_epoch_, val.argmin(axis=0))
    assert (val.min(axis=0) <= val[0]).all() and (val.min(axis=0) < val[0]).any()
    train = model.history_[:, 0, :]
    assert (train[-1] < train[0]).all()


def test_anfis_step_size_rules():
    step = np.array([1.0, 1.0, 1.0])
    errs = [np.array(e) for e in ([5, 5, 1], [4, 6, 1], [3, 5, 1], [2, 6, 1], [1, 5, 1])]
    np.testing.assert_allclose(AnfisResponse._adapt_step(step, errs), [1.1, 0.9, 1.0])


def test_subtractive_clustering_finds_separated_clusters():
    rng = np.random.default_rng(4)
    means = np.array([[0.2, 0.2], [0.8, 0.25], [0.5, 0.8]])
    u = np.concatenate([m + rng.normal(0, 0.03, (40, 2)) for m in means])
    centres = subtractive_clustering(u, radius=0.5)
    assert len(centres) == 3
    assert np.abs(np.sort(centres[:, 0]) - np.sort(means[:, 0])).max() < 0.08


def test_anfis_cluster_rules_and_shared_premise(paper):
    d, sm, b, sp = paper
    clustered = AnfisResponse(rules="cluster", mf="gaussian", epochs=5).fit(d.forces[sp.train], b[sp.train])
    assert 1 <= clustered.n_rules_ < 16
    shared = AnfisResponse(multi_output=True, epochs=5).fit(d.forces[sp.train], b[sp.train])
    assert shared.premise_.shape[0] == 1 and shared.predict(d.forces[:3]).shape == (3, b.shape[1])


def test_mlp_numpy_forward_matches_torch():
    import torch

    from softenv.response._torch_train import _forward

    rng = np.random.default_rng(5)
    params = nguyen_widrow([4, 7, 9, 3], rng)
    x = rng.uniform(-1, 1, (20, 4))
    theta = torch.tensor(np.concatenate([p.ravel() for p in params]))
    expected = _forward(theta, [p.shape for p in params], torch.tensor(x)).numpy()
    np.testing.assert_allclose(mlp_forward(params, x), expected, rtol=1e-13, atol=1e-14)


@pytest.mark.parametrize("trainer", ["lm", "lbfgs", "adam"])
def test_mlp_trainers_learn_a_smooth_map(trainer):
    rng = np.random.default_rng(6)
    x = rng.uniform(-1, 1, (200, 2))
    y = np.stack([np.sin(2 * x[:, 0]) + x[:, 1] ** 2, x[:, 0] * x[:, 1]], axis=1)
    model = MLPResponse(hidden=(8, 8), trainer=trainer, restarts=2, max_epochs=400 if trainer == "lm" else 2000,
                        max_fail=20, seed=1).fit(x[:150], y[:150], validation=(x[150:], y[150:]))
    err = np.mean((model.predict(x[150:]) - y[150:]) ** 2) / y.var()
    assert err < (1e-3 if trainer == "lm" else 2e-2)


def test_mlp_is_deterministic_and_bounded(paper):
    d, sm, b, sp = paper
    m1 = MLPResponse(restarts=2, max_epochs=50, seed=3).fit(d.forces[sp.train], b[sp.train])
    m2 = MLPResponse(restarts=2, max_epochs=50, seed=3).fit(d.forces[sp.train], b[sp.train])
    for p, q in zip(m1.params_, m2.params_):
        np.testing.assert_array_equal(p, q)
    lo, hi = m1.output_bound()
    far = np.random.default_rng(0).normal(0, 1e6, (100, 4))
    y = m1.predict(far)
    assert (y >= lo - 1e-9).all() and (y <= hi + 1e-9).all()


@pytest.mark.parametrize("model", quick_models(), ids=lambda m: m.kind)
def test_save_load_predicts_the_same_and_checks_the_shape_model(model, paper, tmp_path):
    d, sm, b, sp = paper
    model.fit(d.forces[sp.train], b[sp.train], shape_model=sm)
    path = tmp_path / f"{model.kind}.npz"
    model.save(path)
    back = ResponseModel.load(path, shape_model=sm)
    assert type(back) is type(model)
    np.testing.assert_array_equal(back.predict(d.forces), model.predict(d.forces))
    other = ShapeModel(3).fit(d.shapes, d.mesh)
    with pytest.raises(ValueError, match=r"was fitted for shape model 'latlong-21-.*-k4-.*not for the given shape model 'latlong-21-.*-k3-"):
        ResponseModel.load(path, shape_model=other)
    with pytest.raises(ValueError, match="not a 'polynomial' model" if model.kind != "polynomial" else "not a 'anfis'"):
        (PolynomialResponse if model.kind != "polynomial" else AnfisResponse).load(path)


def test_loading_refuses_corrupt_or_mismatched_files(paper, tmp_path):
    d, sm, b, sp = paper
    model = PolynomialResponse(2).fit(d.forces, b)
    path = tmp_path / "p.npz"
    model.save(path)
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["state_coef"] = arrays["state_coef"][:-1]
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(ValueError, match="do not match order 2 in 4 inputs"):
        ResponseModel.load(tmp_path / "bad.npz")
    (tmp_path / "junk.npz").write_bytes(b"PK\x03\x04 junk")
    with pytest.raises(ValueError, match="corrupt"):
        ResponseModel.load(tmp_path / "junk.npz")


@pytest.mark.parametrize("model", quick_models(), ids=lambda m: m.kind)
def test_predict_single_batch_clip_and_bad_input(model, paper):
    d, sm, b, sp = paper
    model.clip = True
    model.fit(d.forces[sp.train], b[sp.train], shape_model=sm)
    batch = model.predict(d.forces[:5])
    assert batch.shape == (5, sm.n_components_)
    np.testing.assert_allclose(model.predict(d.forces[2]), batch[2], rtol=1e-12, atol=1e-15)
    far = d.forces[:5] * np.array([1, 1, 1, 40.0])
    y, clipped = model.predict(far, return_clipped=True)
    assert (y >= sm.b_min_).all() and (y <= sm.b_max_).all() and clipped.shape == y.shape
    with pytest.raises(ValueError, match=r"forces must be finite; found nan"):
        model.predict([0.0, np.nan, 0.03, 1.0])
    with pytest.raises(ValueError, match=r"forces must have trailing shape \(4\)"):
        model.predict(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="forces has 3 rows but b has 2"):
        type(model)().fit(d.forces[:3], b[:2])


def test_prediction_does_not_import_torch(paper, tmp_path):
    d, sm, b, sp = paper
    paths = []
    for model in (MLPResponse(restarts=1, max_epochs=20), AnfisResponse(epochs=3), PolynomialResponse(3, ridge=1e-8)):
        model.fit(d.forces[sp.train], b[sp.train])
        paths.append(str(tmp_path / f"{model.kind}.npz"))
        model.save(paths[-1])
    code = ("import sys, numpy as np\nfrom softenv.response import ResponseModel\n"
            f"for p in {paths!r}:\n    ResponseModel.load(p).predict(np.array([[0.0, 0.0, 0.03, 4.0]]))\n"
            "assert 'torch' not in sys.modules, 'torch was imported'\nprint('ok')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


def test_exact_response_reproduces_the_noise_free_data():
    d = paper_dataset(441, n_deformations=3, noise=0.0)
    sm = ShapeModel("scree").fit(d.shapes, d.mesh)
    exact = ExactResponse(AnalyticTissue(d.mesh, d.tissue), d.layout, sm)
    np.testing.assert_allclose(exact.predict(d.forces), sm.encode(d.shapes), atol=1e-15)


def test_table_is_exact_for_affine_functions_and_converges_quadratically():
    low, high = np.array([0.0, -1.0, 2.0]), np.array([1.0, 1.0, 5.0])
    A = np.array([[1.0, -2.0], [0.5, 3.0], [-1.0, 0.25]])
    nodes = (5, 3, 4)
    axes = [np.linspace(lo, hi, n) for lo, hi, n in zip(low, high, nodes)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    table = TabulatedResponse(low, high, grid @ A + 1.5)
    x = np.random.default_rng(7).uniform(low, high, (200, 3))
    np.testing.assert_allclose(table.predict(x), x @ A + 1.5, atol=1e-12)
    np.testing.assert_allclose(table.predict(high), high @ A + 1.5, atol=1e-12)     # the upper corner

    def err(n):
        g = np.linspace(0, 1, n)
        t = TabulatedResponse([0.0], [1.0], np.sin(3 * g)[:, None])
        xs = np.linspace(0, 1, 1001)
        return np.abs(t.predict(xs[:, None])[:, 0] - np.sin(3 * xs)).max()

    assert 3.5 < err(11) / err(21) < 4.5                                             # O(h^2)


def test_table_scalar_and_vector_lookups_agree_bitwise():
    rng = np.random.default_rng(8)
    table = TabulatedResponse([0.0, -0.02, 0.0, -10.0], [0.09, 0.02, 40.0, 10.0], rng.standard_normal((9, 5, 4, 3, 7)))
    x = rng.uniform(table.low_, table.high_, (300, 4))
    x[:4] = table.high_
    x[4:8] = table.low_
    batch = table.lookup(x)
    for i in range(300):
        assert np.array_equal(table.lookup_one(x[i].tolist()), batch[i])
    table.CHUNK = 64                                  # large batches go in chunks (here 4 full and a partial one)
    assert np.array_equal(table.lookup(x), batch)
    work = table.workspace(300)                       # a batched env's scratch arrays: the same bits
    assert np.array_equal(table.lookup(x, work), batch)
    assert np.array_equal(table.lookup(x[::-1].copy(), work), batch[::-1])
    assert np.array_equal(table.lookup(x[:5], work), batch[:5])      # and for fewer points
    with pytest.raises(ValueError, match=r"work holds 5 points; a lookup of 7 needs workspace\(7\) or larger"):
        table.lookup(x[:7], table.workspace(5))
    with pytest.raises(ValueError, match=r"forces\[0, 2\] = 41 lies outside the tabulated range \[0, 40\]"):
        table.predict([0.01, 0.0, 41.0, 0.0])


def test_a_lookup_into_a_workspace_allocates_none_of_its_large_arrays():
    """The gathered corner rows (N x 16 x k) are the workspace's: what the lookup allocates at once (its
    result, small arrays and numpy's buffers for broadcast operands) stays far below them (fresh large
    blocks can cost a page fault a page)."""
    import tracemalloc

    table = TabulatedResponse([0.0, -0.02, 0.0, -10.0], [0.09, 0.02, 40.0, 10.0],
                              np.random.default_rng(2).standard_normal((9, 5, 4, 3, 28)))
    x = np.random.default_rng(3).uniform(table.low_, table.high_, (1024, 4))
    work = table.workspace(1024)
    peaks = []
    for given in (work, None):
        table.lookup(x, given)
        tracemalloc.start()
        table.lookup(x, given)
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    assert peaks[1] > work.rows.nbytes                        # without a workspace, the rows are fresh
    assert peaks[0] < work.rows.nbytes / 4


def test_a_point_a_rounding_error_below_the_table_reads_its_face_not_a_wrapped_row():
    """A force of -1 in action units can land one ulp below the box; its cell index must not go
    negative (numpy would wrap it to the table's far end and mix in that row's values)."""
    values = np.random.default_rng(3).standard_normal((9, 5, 4, 3, 7))
    values[-1] = 1e18           # the far end, where a wrapped index reads: any weight on it shows
    table = TabulatedResponse([0.0, -0.02, 0.0, -10.0], [0.09, 0.02, 40.0, 10.0], values)
    below = np.nextafter(table.low_, -np.inf)
    at, off = table.lookup(np.stack([table.low_, below]))
    np.testing.assert_allclose(off, at, rtol=0, atol=1e-9)
    assert np.array_equal(table.lookup_one(below.tolist()), off)


def test_tabulated_exact_response_is_close_to_direct(tmp_path):
    d = paper_dataset(441, n_deformations=4)
    sm = ShapeModel("scree").fit(d.shapes, d.mesh)
    from softenv.forces import DorsumLayout

    exact = ExactResponse(AnalyticTissue(d.mesh, d.tissue), DorsumLayout(0.03), sm)
    ws = Workspace((0.035, -0.008, 0.0, -2.0), (0.06, 0.008, 10.0, 2.0))
    coarse, fine = tabulate(exact, ws, (5, 3, 2, 2)), tabulate(exact, ws, (17, 9, 2, 2))
    x = np.random.default_rng(9).uniform(ws.low, ws.high, (100, 4))
    truth = exact.predict(x)
    e_coarse = np.abs(coarse.predict(x) - truth).max()
    e_fine = np.abs(fine.predict(x) - truth).max()
    assert e_fine < e_coarse / 5
    fine.save(tmp_path / "t.npz")
    np.testing.assert_array_equal(ResponseModel.load(tmp_path / "t.npz").predict(x), fine.predict(x))


@pytest.mark.parametrize("model", [PolynomialResponse(3, ridge=1e-8), AnfisResponse(epochs=3),
                                   AnfisResponse(epochs=3, multi_output=True),
                                   AnfisResponse(epochs=3, rules="cluster", mf="gaussian"),
                                   MLPResponse(restarts=1, max_epochs=20)],
                         ids=["poly3", "anfis", "anfis-shared", "anfis-cluster", "mlp"])
def test_rowwise_prediction_is_independent_of_the_batch(model, paper):
    """Environments need one row to give the same bits alone or in a batch of any size."""
    d, sm, b, sp = paper
    model.fit(d.forces[sp.train], b[sp.train])
    x = np.random.default_rng(10).uniform(d.forces.min(0), d.forces.max(0), (257, 4))
    batch = model.predict_rowwise(x)
    for i in range(0, 257, 3):
        assert np.array_equal(model.predict_rowwise(x[i:i + 1])[0], batch[i])
    np.testing.assert_allclose(batch, model.predict(x), rtol=1e-12, atol=1e-15)
