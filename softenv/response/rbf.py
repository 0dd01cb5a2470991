"""A scattered-data interpolant: cubic radial basis functions with a linear polynomial tail.

``b(x) = sum_i w_i |x - x_i|^3 + c_0 + c^T x`` on the scaled inputs, through every training sample
(``smoothing`` = 0) or a ridge-regularised fit of them. The cubic kernel is conditionally positive
definite of order 2, so with the linear tail the interpolation system has a unique solution for
distinct samples. Not one of the paper's regressors: FE scenes use it, tabulated, as their response
(on the FE workspace data it misses held-out solves by a seventh of the order-3 polynomial's error;
``results/fem_scene.md``). Prediction costs a distance to every sample, so scenes tabulate it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validation import check_real
from .base import ResponseModel


class RBFResponse(ResponseModel):
    """Cubic RBF interpolation with a linear tail (see the module docstring).

    Args:
        smoothing: added to the kernel matrix's diagonal (0 interpolates the samples exactly).
        clip: see :class:`~softenv.response.ResponseModel`.
    """

    kind = "rbf"

    def __init__(self, smoothing: float = 0.0, *, clip: bool = False) -> None:
        super().__init__(clip=clip)
        self.smoothing = check_real(smoothing, "smoothing", 0.0, None)

    @staticmethod
    def _kernel(x: np.ndarray, centres: np.ndarray) -> np.ndarray:
        d2 = ((x[:, None, :] - centres[None, :, :]) ** 2).sum(axis=2)
        return d2 * np.sqrt(d2)                                       # |x - x_i|^3

    @staticmethod
    def _tail(x: np.ndarray) -> np.ndarray:
        return np.hstack([np.ones((len(x), 1)), x])

    def _fit_scaled(self, x: np.ndarray, y: np.ndarray, validation: Any) -> None:
        if len(np.unique(x, axis=0)) < len(x):
            raise ValueError("forces has repeated rows; an interpolant needs distinct samples (average them first)")
        n, tail = len(x), self._tail(x)
        m = tail.shape[1]
        system = np.block([[self._kernel(x, x) + self.smoothing * np.eye(n), tail], [tail.T, np.zeros((m, m))]])
        solution = np.linalg.solve(system, np.vstack([y, np.zeros((m, y.shape[1]))]))
        self.centres_, self.weights_, self.tail_coef_ = x, solution[:n], solution[n:]

    def _predict_scaled(self, x: np.ndarray) -> np.ndarray:
        out = np.empty((len(x), self.weights_.shape[1]))
        for start in range(0, len(x), 2048):                          # bounded memory: 2048 x n distances
            rows = x[start:start + 2048]
            out[start:start + 2048] = self._kernel(rows, self.centres_) @ self.weights_ + self._tail(rows) @ self.tail_coef_
        return out

    def _params(self) -> dict[str, Any]:
        return {"smoothing": self.smoothing, "clip": self.clip}

    def _state(self) -> dict[str, np.ndarray]:
        return {"centres": self.centres_, "weights": self.weights_, "tail_coef": self.tail_coef_}

    def _set_state(self, state: dict[str, np.ndarray], extra: dict[str, Any], path: Any) -> None:
        centres, weights, tail = (state.get(k, np.empty(0)) for k in ("centres", "weights", "tail_coef"))
        n = len(centres)
        if centres.shape != (n, self.n_features_) or weights.shape != (n, self.n_outputs_) or \
                tail.shape != (self.n_features_ + 1, self.n_outputs_):
            raise ValueError(f"{str(path)!r}: RBF arrays of shapes {centres.shape}, {weights.shape}, {tail.shape} do not "
                             f"match {self.n_features_} inputs and {self.n_outputs_} outputs")
        self.centres_, self.weights_, self.tail_coef_ = centres, weights, tail
