r"""PCA shape model (active-shape-model style): ``X ~ m + Phi b`` (the paper's eqs. 2.3-2.4).

Fitting never forms the ``p x p`` covariance. With fewer samples than coordinates it takes the
eigen-decomposition of the ``n x n`` Gram matrix of the centred data (milliseconds for the paper's
110 x 2883); otherwise a thin SVD; for very large data a randomized SVD (Halko, Martinsson & Tropp
2011) with implicit centring, so a 10,000 x 30,000 float32 array is never copied.

Components are stored as rows (``components_``, ``k x p``): decoding reads them once, contiguously,
which is twice as fast as the column layout. Component signs are fixed (the largest-magnitude
entry of each is positive), so a model is reproducible bit for bit. With orthonormal components the
surface error between two shapes of the model is ``||X - X*|| = ||b - b*||``: environments work in
``b`` and never rebuild vertices unless asked.
"""

from __future__ import annotations

import hashlib
import math
import os
from collections import OrderedDict
from statistics import NormalDist
from typing import Any

import numpy as np

from ._artifact import load_artifact, require_arrays, save_artifact
from ._blas import SMALL_GEMM_MAX_MNK, has_small_gemm
from ._validation import check_array, check_choice, check_finite, check_int, check_real
from .geometry import SphereMesh
from .scree import select_n_components

MODEL_FORMAT = "softenv.ShapeModel"
MODEL_VERSION = 1
SOLVERS = ("auto", "gram", "svd", "randomized")
REGIONS = ("data", "box", "ellipsoid")
THREE_SIGMA = 0.9973002039367398  # P(|z| <= 3) of a standard normal
# batched decoding: one product per block whose output stays in L2 (docs/performance.md, "Batched decoding")
_DECODE_BLOCK_BYTES = 768 * 1024


def decode_block_rows(n_features: int, n_terms: int, itemsize: int) -> int:
    """Shapes per product when batched decoding writes ``n_features`` values of ``itemsize`` bytes per
    shape, each a sum of ``n_terms`` products (k components and the mean)."""
    if has_small_gemm():
        return max(1, SMALL_GEMM_MAX_MNK // (n_features * n_terms))
    return max(4, _DECODE_BLOCK_BYTES // (n_features * itemsize))


class ShapeModel:
    """Principal-component model of surface shapes.

    Args:
        n_components: ``"scree"`` (Cattell, the paper's), ``"kneedle"``, ``"noise"`` (needs
            ``noise_std``), a variance fraction in (0, 1), or an int. See :mod:`softenv.scree`.
        noise_std: standard deviation (m) of white noise in the data, if known.
        solver: ``"auto"``, ``"gram"``, ``"svd"`` or ``"randomized"``.
        max_components: how many components the randomized solver computes when ``n_components``
            is a rule (the rule then reads this partial spectrum). Default 50.
        random_state: seed of the randomized solver.

    Learned attributes end in ``_``: ``mean_`` (p,), ``components_`` (k, p), ``explained_variance_``
    (k,), ``spectrum_`` (every computed eigenvalue), ``total_variance_``, ``n_components_``,
    ``rule_`` and ``picks_`` (what each rule chose), ``b_min_``/``b_max_`` (range of the training
    data's shape parameters), ``n_samples_``, ``mesh_spec_`` (or None), ``noise_std_``.
    """

    def __init__(self, n_components: int | float | str = "scree", *, noise_std: float | None = None,
                 solver: str = "auto", max_components: int = 50, random_state: int = 0) -> None:
        self.n_components = n_components
        self.noise_std = noise_std
        self.solver = check_choice(solver, "solver", SOLVERS)
        self.max_components = check_int(max_components, "max_components", 1)
        self.random_state = random_state

    # -- fitting ----------------------------------------------------------------------------------

    def fit(self, shapes: np.ndarray, mesh: SphereMesh | None = None) -> "ShapeModel":
        """Fit to ``shapes`` ``(n_samples, p)``; ``mesh`` (optional) is recorded and checked on load."""
        X = np.asarray(shapes)
        dtype = X.dtype if X.dtype in (np.float32, np.float64) else np.float64
        X = check_array(X, "shapes", ndim=2, dtype=dtype)
        n, p = X.shape
        if mesh is not None and p != 3 * mesh.n_vertices:
            raise ValueError(f"shapes have {p} coordinates but the mesh has {mesh.n_vertices} vertices (expected {3 * mesh.n_vertices})")
        if n < 2:
            raise ValueError(f"shapes has {n} sample(s); a shape model needs at least 2")
        if self.noise_std is not None:
            check_real(self.noise_std, "noise_std", 0.0, None)
        fixed_k = self._fixed_k()
        if fixed_k is not None and fixed_k > n - 1:
            raise ValueError(f"n_components={fixed_k} needs at least {fixed_k + 1} samples (centred data of n samples "
                             f"has rank <= n - 1), got {n}")
        solver = self.solver
        if solver == "auto":
            solver = "randomized" if n * p > 2e8 else ("gram" if n <= p else "svd")
        mean = X.mean(axis=0, dtype=np.float64)
        if solver == "randomized":
            spectrum, total, leading = self._randomized(X, mean, fixed_k)
        else:
            spectrum, total, leading = _exact_pca(X, mean, solver)
            spectrum = spectrum[: min(n - 1, p)]  # centred data has rank <= n - 1: drop the structural zero
        k, rule, picks = select_n_components(self.n_components, spectrum, noise_std=self.noise_std,
                                             n_samples=n, n_features=p, total_variance=total)
        numerical_rank = int(np.sum(spectrum > spectrum[0] * 1e-12))
        if k > numerical_rank:
            raise ValueError(f"n_components={k} exceeds the numerical rank ({numerical_rank}) of the data "
                             f"({n} samples x {p} coordinates)")
        components = leading(k)
        signs = np.sign(components[np.arange(k), np.argmax(np.abs(components), axis=1)])
        components = components * signs[:, None]
        self._set_state(mean, components, spectrum, total, k, rule, picks, n,
                        None if mesh is None else mesh.spec(), self.noise_std)
        b = self.encode(X)
        self.b_min_, self.b_max_ = b.min(axis=0), b.max(axis=0)
        return self

    def _fixed_k(self) -> int | None:
        k = self.n_components
        if isinstance(k, (bool, np.bool_)):
            raise ValueError(f"n_components={k!r} is not valid")
        if isinstance(k, (int, np.integer)):
            return check_int(k, "n_components", 1)
        return None

    def _randomized(self, X: np.ndarray, mean: np.ndarray, fixed_k: int | None) -> tuple[np.ndarray, float, Any]:
        """Halko et al. randomized SVD of ``X - 1 mean`` without forming it."""
        n, p = X.shape
        k = fixed_k if fixed_k is not None else min(self.max_components, n - 1)
        width = min(k + 10, n, p)
        rng = np.random.default_rng(self.random_state)
        work = X.dtype
        m = mean.astype(work)
        ones = np.ones(n, dtype=work)

        def centred_times(M: np.ndarray) -> np.ndarray:      # (X - 1 m) @ M
            return X @ M - np.outer(ones, m @ M)

        def centred_T_times(M: np.ndarray) -> np.ndarray:    # (X - 1 m)^T @ M
            return X.T @ M - np.outer(m, ones @ M)

        Q, _ = np.linalg.qr(centred_times(rng.standard_normal((p, width)).astype(work)))
        for _ in range(4):  # power iterations sharpen a slowly decaying spectrum
            Z, _ = np.linalg.qr(centred_T_times(Q))
            Q, _ = np.linalg.qr(centred_times(Z))
        B = centred_T_times(Q).T.astype(np.float64)           # (width, p) = Q^T (X - 1 m)
        _, s, Vt = np.linalg.svd(B, full_matrices=False)
        s = s[:k]  # the oversampled tail is inaccurate: the spectrum stops at the k asked for
        total = 0.0
        for start in range(0, n, 1024):                        # total variance, chunked, float64
            block = X[start:start + 1024].astype(np.float64) - mean
            total += float(np.einsum("ij,ij->", block, block))
        return s ** 2 / (n - 1), total / (n - 1), lambda m: Vt[:m]

    def _set_state(self, mean: Any, components: Any, spectrum: Any, total: float, k: int, rule: str, picks: Any,
                   n: int, mesh_spec: Any, noise_std: float | None) -> None:
        self.mean_ = np.ascontiguousarray(mean, dtype=np.float64)
        self.components_ = np.ascontiguousarray(components, dtype=np.float64)
        self.spectrum_ = np.asarray(spectrum, dtype=np.float64)
        self.explained_variance_ = self.spectrum_[:k].copy()
        self.total_variance_ = float(total)
        self.n_components_ = int(k)
        self.rule_ = str(rule)
        self.picks_ = {str(a): int(b) for a, b in picks.items()}
        self.n_samples_ = int(n)
        self.mesh_spec_ = mesh_spec
        self.noise_std_ = None if noise_std is None else float(noise_std)
        self._components32 = self.components_.astype(np.float32)
        self._mean32 = self.mean_.astype(np.float32)
        self._augmented: dict[np.dtype, np.ndarray] = {np.dtype(np.float64): np.vstack([self.mean_, self.components_]),
                           np.dtype(np.float32): np.vstack([self._mean32, self._components32])}
        self._zeros = {dtype: np.zeros(self.n_components_, dtype) for dtype in self._augmented}
        self._subsets: OrderedDict[bytes, tuple[np.ndarray, np.ndarray, np.ndarray]] = OrderedDict()

    def augmented(self, dtype: Any = np.float64) -> np.ndarray:
        """``[mean; components]``, ``(k + 1, p)`` in ``dtype`` (float64 or float32): the one matrix that
        :meth:`decode` multiplies ``[1, b]`` by (read-only; benchmarks time products with it)."""
        return self._augmented[np.dtype(dtype)]

    # -- encoding and decoding --------------------------------------------------------------------

    @property
    def n_features_(self) -> int:
        return int(self.mean_.size)

    @property
    def sqrt_variance_(self) -> np.ndarray:
        """Standard deviation of each shape parameter, ``sqrt(lambda_i)``."""
        return np.sqrt(self.explained_variance_)

    def encode(self, shapes: np.ndarray) -> np.ndarray:
        """Shape parameters ``b = Phi^T (X - m)`` of ``(p,)`` or ``(N, p)`` shapes (float64).

        Large arrays are processed in blocks of rows, so memory beyond the input stays small.
        """
        self._check_fitted()
        X = np.asarray(shapes)
        X = check_array(X, "shapes", ndim=(1, 2), shape=(self.n_features_,),
                        dtype=X.dtype if X.dtype in (np.float32, np.float64) else np.float64)
        if X.ndim == 1:
            return (X - self.mean_) @ self.components_.T
        b = np.empty((X.shape[0], self.n_components_))
        for start in range(0, X.shape[0], 4096):
            b[start:start + 4096] = (X[start:start + 4096] - self.mean_) @ self.components_.T
        return b

    def decode(self, b: np.ndarray, out: np.ndarray | None = None, *, vertices: np.ndarray | None = None) -> np.ndarray:
        """Surface ``m + Phi b`` for ``b`` of shape ``(k,)`` or ``(N, k)``.

        float32 ``b`` decodes in float32 (the fast path), anything else in float64. ``out`` (optional)
        must be a C-contiguous array of the result's shape and dtype. ``vertices`` (optional index
        array) decodes only those vertices: ``3 len(vertices)`` coordinates per shape.
        """
        self._check_fitted()
        b = np.asarray(b)
        if b.dtype != np.float32 and b.dtype != np.float64:
            b = check_array(b, "b", ndim=(1, 2))
        k = self.n_components_
        if b.shape[-1:] != (k,) or b.ndim > 2:
            raise ValueError(f"b must have shape ({k},) or (N, {k}), got {b.shape}")
        # one shape: b . 0 is 0 for every finite b and NaN otherwise, and takes 0.4 us against 1 us
        # for isfinite().all() on the haptic path
        if not (math.isfinite(np.dot(b, self._zeros[b.dtype])) if b.ndim == 1 else np.isfinite(b).all()):
            check_finite(b, "b")
        if vertices is None:
            comps = self._components32 if b.dtype == np.float32 else self.components_
            mean = self._mean32 if b.dtype == np.float32 else self.mean_
            aug = self._augmented[b.dtype]
        else:
            comps, mean, aug = self._subset(vertices, b.dtype)
        shape = (comps.shape[1],) if b.ndim == 1 else (b.shape[0], comps.shape[1])
        if out is None:
            out = np.empty(shape, dtype=b.dtype)
        elif out.shape != shape or out.dtype != b.dtype or not out.flags.c_contiguous:
            raise ValueError(f"out must be a C-contiguous {b.dtype} array of shape {shape}, "
                             f"got {out.dtype} {out.shape}{'' if out.flags.c_contiguous else ' (not contiguous)'}")
        if b.ndim == 1:
            np.dot(b, comps, out=out)
            out += mean
        else:  # fold the mean into one product so the output is written once, in blocks of rows
            lifted = np.empty((b.shape[0], k + 1), dtype=b.dtype)
            lifted[:, 0] = 1.0
            lifted[:, 1:] = b
            rows = decode_block_rows(out.shape[1], k + 1, out.itemsize)
            for start in range(0, b.shape[0], rows):
                stop = start + rows
                np.dot(lifted[start:stop], aug, out=out[start:stop])
        return out

    def _subset(self, vertices: np.ndarray, dtype: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        v = check_array(vertices, "vertices", ndim=1, dtype=np.int64)
        n_vertices = self.n_features_ // 3
        if v.size and (v.min() < 0 or v.max() >= n_vertices):
            raise ValueError(f"vertices must be indices in [0, {n_vertices - 1}], got values in [{v.min()}, {v.max()}]")
        key = v.tobytes() + np.dtype(dtype).char.encode()
        if key not in self._subsets:
            cols = (3 * v[:, None] + np.arange(3)).ravel()
            aug = np.ascontiguousarray(self._augmented[np.dtype(dtype)][:, cols])
            self._subsets[key] = (np.ascontiguousarray(aug[1:]), aug[0].copy(), aug)
            if len(self._subsets) > 8:
                self._subsets.popitem(last=False)
        return self._subsets[key]

    def rms_distance(self, b: np.ndarray, b_ref: np.ndarray) -> np.ndarray:
        """RMS distance (m) over vertices between the surfaces of ``b`` and ``b_ref``, computed in b-space:
        with orthonormal components ``||X - X_ref|| = ||b - b_ref||``, so no vertex is rebuilt."""
        diff = np.asarray(b, dtype=np.float64) - np.asarray(b_ref, dtype=np.float64)
        return np.sqrt(np.sum(diff * diff, axis=-1) / (self.n_features_ // 3))

    def reconstruct(self, shapes: np.ndarray) -> np.ndarray:
        """Project ``shapes`` on the model and rebuild them (float64)."""
        return self.decode(self.encode(shapes))

    # -- plausible shapes -------------------------------------------------------------------------

    def plausible_box(self, n_std: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
        """Cootes' box ``|b_i| <= n_std sqrt(lambda_i)``."""
        self._check_fitted()
        half = check_real(n_std, "n_std", 0.0, None, low_open=True) * self.sqrt_variance_
        return -half, half

    def mahalanobis_squared(self, b: np.ndarray) -> np.ndarray:
        """``sum_i b_i^2 / lambda_i`` for ``(k,)`` or ``(N, k)`` parameters."""
        self._check_fitted()
        b = check_array(b, "b", ndim=(1, 2), shape=(self.n_components_,))
        return np.sum(b ** 2 / self.explained_variance_, axis=-1)

    def mahalanobis_bound(self, probability: float = THREE_SIGMA) -> float:
        """Chi-square quantile with ``k`` degrees of freedom (Wilson-Hilferty; default: the 3-sigma mass)."""
        self._check_fitted()
        prob = check_real(probability, "probability", 0.0, 1.0, low_open=True, high_open=True)
        k = self.n_components_
        z = NormalDist().inv_cdf(prob)
        return float(k * (1.0 - 2.0 / (9.0 * k) + z * np.sqrt(2.0 / (9.0 * k))) ** 3)

    def plausible_range(self, region: str = "data") -> tuple[np.ndarray, np.ndarray]:
        """Per-parameter bounds: ``"data"`` (training min/max, the paper's slider ranges) or ``"box"``."""
        check_choice(region, "region", ("data", "box"))
        return (self.b_min_.copy(), self.b_max_.copy()) if region == "data" else self.plausible_box()

    def is_plausible(self, b: np.ndarray, region: str = "data") -> np.ndarray:
        """Whether each ``b`` lies in the region (``"data"``, ``"box"`` or ``"ellipsoid"``)."""
        check_choice(region, "region", REGIONS)
        b = check_array(b, "b", ndim=(1, 2), shape=(self.n_components_,))
        if region == "ellipsoid":
            return self.mahalanobis_squared(b) <= self.mahalanobis_bound()
        lo, hi = self.plausible_range(region)
        return np.all((b >= lo) & (b <= hi), axis=-1)

    def clip_plausible(self, b: np.ndarray, region: str = "data") -> np.ndarray:
        """``b`` moved into the region: clipped per parameter (``"data"``, ``"box"``) or scaled
        radially onto the ellipsoid ``sum b_i^2 / lambda_i <= bound`` (``"ellipsoid"``)."""
        check_choice(region, "region", REGIONS)
        b = check_array(b, "b", ndim=(1, 2), shape=(self.n_components_,))
        if region == "ellipsoid":
            d2 = self.mahalanobis_squared(b)
            scale = np.sqrt(np.minimum(1.0, self.mahalanobis_bound() / np.maximum(d2, 1e-300)))
            return b * (scale[..., None] if b.ndim == 2 else scale)
        lo, hi = self.plausible_range(region)
        return np.clip(b, lo, hi)

    # -- persistence ------------------------------------------------------------------------------

    def save(self, path: str | os.PathLike) -> None:
        """Write a versioned ``.npz`` (atomic, pickle-free)."""
        self._check_fitted()
        save_artifact(path, MODEL_FORMAT, MODEL_VERSION,
                      {"mean": self.mean_, "components": self.components_, "spectrum": self.spectrum_,
                       "b_min": self.b_min_, "b_max": self.b_max_},
                      {"n_components": self.n_components_, "rule": self.rule_, "picks": self.picks_,
                       "n_samples": self.n_samples_, "total_variance": self.total_variance_,
                       "mesh": self.mesh_spec_, "noise_std": self.noise_std_,
                       "params": {"n_components": str(self.n_components), "solver": self.solver}})

    @classmethod
    def load(cls, path: str | os.PathLike, mesh: SphereMesh | None = None) -> "ShapeModel":
        """Read a model saved by :meth:`save`; with ``mesh``, refuse a model fitted on another mesh."""
        arrays, meta = load_artifact(path, MODEL_FORMAT, MODEL_VERSION)
        require_arrays(arrays, ["mean", "components", "spectrum", "b_min", "b_max"], path)
        mean, comps = arrays["mean"], arrays["components"]
        k = int(meta.get("n_components", -1))
        if comps.ndim != 2 or comps.shape != (k, mean.size) or arrays["b_min"].shape != (k,) or arrays["b_max"].shape != (k,):
            raise ValueError(f"{str(path)!r} has inconsistent arrays: components {comps.shape}, mean {mean.shape}, "
                             f"n_components {k}")
        recorded = meta.get("mesh")
        if recorded is not None and not isinstance(recorded, dict):
            raise ValueError(f"{str(path)!r} has an invalid header: mesh is {recorded!r}, not a mesh spec")
        if mesh is not None:
            if recorded is not None and recorded.get("fingerprint") != mesh.fingerprint:
                raise ValueError(f"{str(path)!r} was fitted on mesh {recorded.get('fingerprint')!r}, "
                                 f"not on the given mesh {mesh.fingerprint!r}")
            if mean.size != 3 * mesh.n_vertices:
                raise ValueError(f"{str(path)!r} has {mean.size} coordinates; the given mesh has "
                                 f"{mesh.n_vertices} vertices ({3 * mesh.n_vertices} coordinates)")
        if arrays["spectrum"].ndim != 1 or arrays["spectrum"].size < k:
            raise ValueError(f"{str(path)!r} has a spectrum of shape {arrays['spectrum'].shape}; expected at least {k} "
                             "values")
        model = cls(k)
        try:
            model._set_state(mean, comps, arrays["spectrum"], float(meta["total_variance"]), k, meta["rule"],
                             meta["picks"], int(meta["n_samples"]), recorded, meta.get("noise_std"))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{str(path)!r} has an invalid header (missing or bad {exc}); re-create the file") from None
        model.b_min_, model.b_max_ = arrays["b_min"], arrays["b_max"]
        return model

    def fingerprint(self) -> str:
        """Identifies this model's subspace (mesh, k and a digest of mean and components)."""
        self._check_fitted()
        h = hashlib.sha256(self.mean_.tobytes() + self.components_.tobytes()).hexdigest()[:16]
        mesh = self.mesh_spec_["fingerprint"] if self.mesh_spec_ else f"p{self.n_features_}"
        return f"{mesh}-k{self.n_components_}-{h}"

    def _check_fitted(self) -> None:
        if not hasattr(self, "components_"):
            raise RuntimeError("this ShapeModel is not fitted yet: call fit(shapes) or ShapeModel.load(path)")

    def __repr__(self) -> str:
        if hasattr(self, "components_"):
            return f"ShapeModel(k={self.n_components_} by {self.rule_!r}, p={self.n_features_}, n={self.n_samples_})"
        return f"ShapeModel(n_components={self.n_components!r}, solver={self.solver!r})"


def _exact_pca(X: np.ndarray, mean: np.ndarray, solver: str) -> tuple[np.ndarray, float, Any]:
    """Spectrum (covariance eigenvalues), total variance, and ``leading(k)``: the first k right
    singular vectors as rows (computed on demand: the Gram route forms only the k it is asked for)."""
    n = X.shape[0]
    A = X.astype(np.float64) - mean
    total = float(np.einsum("ij,ij->", A, A)) / (n - 1)
    if solver == "gram":
        evals, U = np.linalg.eigh(A @ A.T)
        evals, U = np.maximum(evals[::-1], 0.0), U[:, ::-1]
        return evals / (n - 1), total, lambda k: (U[:, :k].T @ A) / np.sqrt(evals[:k])[:, None]
    _, s, Vt = np.linalg.svd(A, full_matrices=False)
    return s ** 2 / (n - 1), total, lambda k: Vt[:k]
