"""Polynomial least squares of order 1-3 (the paper's eqs. 2.5-2.8), with full cross terms."""

from __future__ import annotations

from itertools import combinations_with_replacement
from typing import Any

import numpy as np

from .._validation import check_int, check_real
from .base import ResponseModel


def monomial_exponents(n_inputs: int, order: int) -> np.ndarray:
    """Exponents ``(n_terms, n_inputs)`` of every monomial of total degree <= ``order`` (35 for 4 inputs, order 3)."""
    rows = [np.zeros(n_inputs, dtype=np.int64)]
    for degree in range(1, order + 1):
        for combo in combinations_with_replacement(range(n_inputs), degree):
            e = np.zeros(n_inputs, dtype=np.int64)
            np.add.at(e, list(combo), 1)
            rows.append(e)
    return np.array(rows)


class PolynomialResponse(ResponseModel):
    """``b = C^T phi(f)``, ``phi`` all monomials of the scaled inputs up to ``order``, by least squares.

    Args:
        order: 1, 2 or 3 (the paper's first-, second- and third-order models).
        ridge: Tikhonov weight (0 = plain least squares by SVD-based ``lstsq``), relative to the
            mean squared feature.
        clip: see :class:`~softenv.response.ResponseModel`.
    """

    kind = "polynomial"

    def __init__(self, order: int = 2, ridge: float = 0.0, *, clip: bool = False) -> None:
        super().__init__(clip=clip)
        self.order = check_int(order, "order", 1, 3)
        self.ridge = check_real(ridge, "ridge", 0.0, None)

    def features(self, x: np.ndarray) -> np.ndarray:
        """Monomials ``(N, n_terms)`` of scaled inputs ``x`` ``(N, d)``."""
        powers = x[:, :, None] ** self._degrees                       # (N, d, order + 1)
        return np.prod(powers[:, self._inputs, self.exponents_], axis=2)

    def _fit_scaled(self, x: np.ndarray, y: np.ndarray, validation: Any) -> None:
        self._set_exponents(monomial_exponents(x.shape[1], self.order))
        phi = self.features(x)
        if phi.shape[0] < phi.shape[1] and self.ridge == 0:
            raise ValueError(f"order {self.order} in {x.shape[1]} inputs has {phi.shape[1]} coefficients per output "
                             f"but only {phi.shape[0]} training samples; use ridge > 0 or a lower order")
        if self.ridge > 0:
            lam = np.sqrt(self.ridge * np.mean(phi ** 2))
            phi = np.vstack([phi, lam * np.eye(phi.shape[1])])
            y = np.vstack([y, np.zeros((phi.shape[1], y.shape[1]))])
        self.coef_, *_ = np.linalg.lstsq(phi, y, rcond=None)

    def _predict_scaled(self, x: np.ndarray) -> np.ndarray:
        return self.features(x) @ self.coef_

    def _predict_scaled_rowwise(self, x: np.ndarray) -> np.ndarray:
        phi = self.features(x)
        y = phi[:, :1] * self.coef_[0]
        for m in range(1, phi.shape[1]):
            y = y + phi[:, m:m + 1] * self.coef_[m]
        return y

    def _set_exponents(self, exponents: np.ndarray) -> None:
        self.exponents_ = exponents
        self._inputs = np.arange(exponents.shape[1])
        self._degrees = np.arange(self.order + 1)

    def _params(self) -> dict[str, Any]:
        return {"order": self.order, "ridge": self.ridge, "clip": self.clip}

    def _state(self) -> dict[str, np.ndarray]:
        return {"coef": self.coef_, "exponents": self.exponents_}

    def _set_state(self, state: dict[str, np.ndarray], extra: dict[str, Any], path: Any) -> None:
        expected = monomial_exponents(self.n_features_, self.order)
        if "exponents" not in state or not np.array_equal(state["exponents"], expected) or \
                state.get("coef", np.empty(0)).shape != (len(expected), self.n_outputs_):
            raise ValueError(f"{str(path)!r}: polynomial coefficients do not match order {self.order} "
                             f"in {self.n_features_} inputs")
        self._set_exponents(expected)
        self.coef_ = state["coef"]
