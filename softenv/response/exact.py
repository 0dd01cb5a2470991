"""The exact response (analytic tissue, then projection on the shape model) and its table.

:class:`ExactResponse` is the truth for analytic scenes; its cost grows with the number of surface
points. :class:`TabulatedResponse` samples any response on a grid over a workspace box and
interpolates multilinearly, at a cost independent of the mesh: environments step with it. Its
lookup has a vectorised form and a scalar form (for one environment) that perform the same IEEE
operations in the same order, so a batch of environments and single ones agree bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .._validation import check_array
from .._progress import Progress
from ..forces import ForceLayout, Workspace, layout_from_dict
from ..geometry import mesh_from_spec
from ..shape_model import ShapeModel
from ..tissue import AnalyticTissue, TissueParams
from .base import MinMaxScaler, ResponseModel


def _identity_scalers(model: ResponseModel, n_features: int, n_outputs: int) -> None:
    model.n_features_, model.n_outputs_ = n_features, n_outputs
    model.input_scaler_ = MinMaxScaler(np.ones(n_features), np.zeros(n_features))
    model.output_scaler_ = MinMaxScaler(np.ones(n_outputs), np.zeros(n_outputs))


class ExactResponse(ResponseModel):
    """Force vectors -> tissue surface (:class:`~softenv.tissue.AnalyticTissue`) -> ``b`` (projection).

    Nothing is learned: :meth:`fit` only checks shapes and returns ``self``.
    """

    kind = "exact"

    def __init__(self, tissue: AnalyticTissue, layout: ForceLayout, shape_model: ShapeModel, *, clip: bool = False) -> None:
        super().__init__(clip=clip)
        if shape_model.n_features_ != 3 * tissue.mesh.n_vertices:
            raise ValueError(f"the shape model has {shape_model.n_features_} coordinates but the tissue mesh has "
                             f"{tissue.mesh.n_vertices} vertices")
        self.tissue, self.layout, self.shape_model = tissue, layout, shape_model
        _identity_scalers(self, layout.n_features, shape_model.n_components_)
        self.shape_model_fingerprint_ = shape_model.fingerprint()
        self.b_low_, self.b_high_ = shape_model.b_min_.copy(), shape_model.b_max_.copy()

    def fit(self, forces: Any = None, b: Any = None, **_: Any) -> "ExactResponse":
        return self

    def _predict_scaled(self, x: np.ndarray) -> np.ndarray:
        return self.shape_model.encode(self.tissue.surfaces(*self.layout.to_loads(x)))

    def _params(self) -> dict[str, Any]:
        return {"clip": self.clip}

    def _extra_meta(self) -> dict[str, Any]:
        return {"tissue": self.tissue.params.to_dict(), "mesh": self.tissue.mesh.spec(), "layout": self.layout.to_dict()}

    @classmethod
    def _from_saved(cls, params: dict[str, Any], arrays: dict[str, np.ndarray], meta: dict[str, Any],
                    shape_model: ShapeModel | None, path: Any) -> "ExactResponse":
        if shape_model is None:
            raise ValueError(f"{str(path)!r} holds an exact response: load it with the shape_model it projects onto")
        extra = meta.get("extra", {})
        tissue = AnalyticTissue(mesh_from_spec(extra["mesh"]), TissueParams(**extra["tissue"]))
        return cls(tissue, layout_from_dict(extra["layout"]), shape_model, **params)


@dataclass
class TableWork:
    """The scratch arrays of table lookups of up to ``n`` points (:meth:`TabulatedResponse.workspace`).

    A batched env keeps one and passes it every step, so its step allocates none of the lookup's large
    temporaries (the result is a new array, as any numpy function's): fresh large blocks can fault their
    pages in one by one (docs/performance.md: measured choices).
    """

    weights: np.ndarray   # (m, 2^d) corner weights, m = min(n, CHUNK) points at a time
    index: np.ndarray     # (m, 2^d) the corners' rows in the flat table
    rows: np.ndarray      # (m, 2^d, k) the corners' rows, gathered


@dataclass(frozen=True)
class TableGrid:
    """A table's layout: a point's base corner is ``sum(floor((x - low) * inv_step) * strides)``, and
    corner ``c`` of its cell is row ``base + offsets[c]`` of ``flat``, weighted along axis ``j`` by
    ``t_j`` where ``bits[c, j]`` is 1, else ``1 - t_j``."""

    flat: np.ndarray              # (rows, k) node values, one node padded past the top of each axis
    strides: tuple[int, ...]      # rows between neighbouring nodes along each axis
    bits: np.ndarray              # (2^d, d) corner c's offset along axis j
    offsets: tuple[int, ...]      # (2^d,) corner c's row offset from the base corner


class TabulatedResponse(ResponseModel):
    """Multilinear interpolation of a response sampled on a regular grid over ``[low, high]``.

    Inputs must lie in the box; values within ``1e-9`` of its size outside are clamped onto it,
    anything further is a ``ValueError``. The output is a convex combination of grid values, so it
    stays within their range.
    """

    kind = "table"
    # points per chunk of lookup: a chunk's gathered corners stay in cache (docs/performance.md)
    CHUNK = 1024

    def __init__(self, low: Sequence[float] | np.ndarray, high: Sequence[float] | np.ndarray, values: np.ndarray, *,
                 clip: bool = False) -> None:
        super().__init__(clip=clip)
        self.low_ = np.asarray(low, dtype=np.float64)
        self.high_ = np.asarray(high, dtype=np.float64)
        values = check_array(values, "values", ndim=self.low_.size + 1)
        counts = np.array(values.shape[:-1])
        if (counts < 2).any() or (self.high_ <= self.low_).any():
            raise ValueError(f"a table needs at least 2 nodes per axis and high > low; got nodes {counts.tolist()}, "
                             f"low {self.low_.tolist()}, high {self.high_.tolist()}")
        self.values_ = values
        d = self.low_.size
        _identity_scalers(self, d, values.shape[-1])
        self.b_low_, self.b_high_ = values.reshape(-1, values.shape[-1]).min(0), values.reshape(-1, values.shape[-1]).max(0)
        self.shape_model_fingerprint_ = ""
        self.inv_step_ = (counts - 1) / (self.high_ - self.low_)
        # pad one node per axis (a copy of the last) so a point on the upper face needs no clamping
        padded = np.pad(values, [(0, 1)] * d + [(0, 0)], mode="edge")
        self._flat = np.ascontiguousarray(padded.reshape(-1, values.shape[-1]))
        strides = np.cumprod([1, *np.array(padded.shape[:-1])[::-1][:-1]])[::-1].astype(np.int64)
        self._strides_f = strides.astype(np.float64)
        # corner c of a cell has bit j of c (the first axis the highest bit) as its offset along axis j
        self._bits = np.array([[(c >> (d - 1 - j)) & 1 for j in range(d)] for c in range(2 ** d)], dtype=np.int64)
        self._offsets = self._bits @ strides
        self._low_col, self._inv_col = self.low_[:, None], self.inv_step_[:, None]
        self._low_list, self._inv_list = self.low_.tolist(), self.inv_step_.tolist()
        self._stride_list = strides.tolist()

    def grid(self) -> TableGrid:
        """The padded table and its corner layout, for evaluators on other arrays (the torch twin)."""
        return TableGrid(self._flat, tuple(self._stride_list), self._bits, tuple(self._offsets.tolist()))

    @property
    def nodes(self) -> tuple[int, ...]:
        return tuple(self.values_.shape[:-1])

    def fit(self, forces: Any = None, b: Any = None, **_: Any) -> "TabulatedResponse":
        return self

    def _predict_scaled(self, x: np.ndarray) -> np.ndarray:
        tol = 1e-9 * (self.high_ - self.low_)
        outside = (x < self.low_ - tol) | (x > self.high_ + tol)
        if outside.any():
            i, j = np.argwhere(outside)[0]
            raise ValueError(f"forces[{i}, {j}] = {x[i, j]:g} lies outside the tabulated range "
                             f"[{self.low_[j]:g}, {self.high_[j]:g}] of column {j}")
        return self.lookup(np.clip(x, self.low_, self.high_))

    def predict_rowwise(self, x: np.ndarray) -> np.ndarray:
        return self.lookup(x)

    def workspace(self, n: int) -> TableWork:
        """Arrays for lookups of ``n`` points (see :class:`TableWork`)."""
        m, corners, k = min(n, self.CHUNK), len(self._offsets), self._flat.shape[1]
        return TableWork(np.empty((m, corners)), np.empty((m, corners), np.int64), np.empty((m, corners, k)))

    def lookup(self, x: np.ndarray, work: TableWork | None = None) -> np.ndarray:
        """Interpolate at ``(N, d)`` points inside the box (not checked). Large batches go in chunks of
        :attr:`CHUNK` points: the gathered corners of 100,000 points would take 360 MB, and every row
        is computed alone, so chunks change no bit. With ``work`` (from :meth:`workspace` for ``N`` or
        more points) the only large array allocated is the result."""
        work = self.workspace(len(x)) if work is None else work
        if len(work.rows) < min(len(x), self.CHUNK):
            raise ValueError(f"work holds {len(work.rows)} points; a lookup of {len(x)} needs "
                             f"workspace({len(x)}) or larger")
        out = np.empty((len(x), self._flat.shape[1]))
        for start in range(0, len(x), self.CHUNK):
            self._lookup(x[start:start + self.CHUNK], work, out[start:start + self.CHUNK])
        return out

    def _lookup(self, x: np.ndarray, work: TableWork, out: np.ndarray) -> None:
        n = len(x)
        weights, index, rows = work.weights[:n], work.index[:n], work.rows[:n]
        # axis by axis over all points, (d, N): the weights' products then run over long rows
        t = (x.T - self._low_col) * self._inv_col
        # a point a rounding error below the box (a force of -1 in action units) stays in the first cell:
        # its fraction is then a hair below 0, a linear extrapolation of 1e-16 (a negative index would wrap)
        cell = np.maximum(np.floor(t), 0.0)
        frac = t - cell
        # (2^j, N) -> (2^(j+1), N): the same left-to-right products as lookup_one; the last axis's
        # products go straight into the (N, 2^d) weights, through a (2^(d-1), 2, N) view of them
        pairs = [np.stack([1.0 - f, f]) for f in frac]
        last = weights.reshape(n, -1, 2).transpose(1, 2, 0)
        if len(pairs) == 1:
            last[0] = pairs[0]
        else:
            w = pairs[0]
            for pair in pairs[1:-1]:
                w = (w[:, None] * pair).reshape(-1, n)
            np.multiply(w[:, None], pairs[-1], out=last)
        base = (self._strides_f @ cell).astype(np.int64)
        np.add(base[:, None], self._offsets, out=index)
        # take on the contiguous table copies whole rows: 1.3x faster than fancy indexing (as lookup_one);
        # mode="clip" lets it write into `rows` unbuffered (the indices are in range for points in the box)
        self._flat.take(index, axis=0, out=rows, mode="clip")
        np.matmul(weights[:, None, :], rows, out=out[:, None, :])

    def lookup_one(self, x: Sequence[float]) -> np.ndarray:
        """Interpolate at one point given as Python floats: :meth:`lookup` of one row, bit for bit.

        The corner weights are the same left-to-right products in the same corner order, so the
        result equals ``lookup`` bit for bit, without numpy's per-call cost on tiny arrays.
        """
        base = 0
        pairs = []
        for xj, lo, inv, stride in zip(x, self._low_list, self._inv_list, self._stride_list):
            t = (xj - lo) * inv
            cell = math.floor(t)
            if cell < 0:
                cell = 0
            frac = t - cell
            base += cell * stride
            pairs.append((1.0 - frac, frac))
        weights: list[float] = list(pairs[0])
        for pair in pairs[1:]:
            weights = [w * p for w in weights for p in pair]
        rows = self._flat[base:].take(self._offsets, axis=0)      # the corners' rows, from the base corner's
        return np.dot(np.array(weights), rows)          # the same BLAS vector-matrix kernel as lookup's matmul

    def _state(self) -> dict[str, np.ndarray]:
        return {"low": self.low_, "high": self.high_, "values": self.values_}

    @classmethod
    def _from_saved(cls, params: dict[str, Any], arrays: dict[str, np.ndarray], meta: dict[str, Any],
                    shape_model: ShapeModel | None, path: Any) -> "TabulatedResponse":
        try:
            table = cls(arrays["state_low"], arrays["state_high"], arrays["state_values"], **params)
        except KeyError as exc:
            raise ValueError(f"{str(path)!r}: table arrays are missing {exc}") from exc
        return table


def tabulate(model: ResponseModel, workspace: Workspace, nodes: Sequence[int], progress: bool = False
             ) -> TabulatedResponse:
    """Sample ``model`` on a grid of ``nodes[i]`` points along each workspace axis: a
    :class:`TabulatedResponse` (multilinear, row-wise exact, fast)."""
    nodes = tuple(int(n) for n in nodes)
    if len(nodes) != workspace.n_features or min(nodes) < 2:
        raise ValueError(f"nodes={nodes} needs {workspace.n_features} counts of at least 2")
    axes = [np.linspace(lo, hi, n) for lo, hi, n in zip(workspace.low, workspace.high, nodes)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(nodes))
    values = np.empty((grid.shape[0], model.n_outputs_))
    chunk = 2048
    with Progress(-(-grid.shape[0] // chunk), f"tabulating the {model.kind} response", enabled=progress) as bar:
        for start in range(0, grid.shape[0], chunk):
            values[start:start + chunk] = model.predict(grid[start:start + chunk])
            bar.advance()
    table = TabulatedResponse(workspace.low, workspace.high, values.reshape(*nodes, -1))
    table.shape_model_fingerprint_ = model.shape_model_fingerprint_
    return table
