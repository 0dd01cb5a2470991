"""The paper's neural network: ``d-7-9-k``, tansig hidden layers, linear output (MATLAB ``newff`` defaults).

Inference is numpy (``tanh`` of small products); training runs in torch, float64, imported only by
:meth:`MLPResponse.fit`: Levenberg-Marquardt with ``trainlm``'s defaults (mu 1e-3, x0.1 / x10,
mu_max 1e10, min_grad 1e-7, stop after 6 validation failures), or L-BFGS or Adam. Weights start from
Nguyen-Widrow (MATLAB ``initnw``); several restarts, the best on validation kept. Because every
hidden unit is a ``tanh`` and the output layer is linear, the output is bounded whatever the input:
``|y - b_out| <= sum |W_out|`` in scaled units (the paper's "the neural network will never become
unstable").
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validation import check_choice, check_int, check_real
from .base import ResponseModel

TRAINERS = ("lm", "lbfgs", "adam")


def nguyen_widrow(sizes: list[int], rng: np.random.Generator) -> list[np.ndarray]:
    """Initial weights ``[W0, b0, W1, b1, ...]`` (``W`` as ``(inputs, outputs)``) for inputs in [-1, 1]."""
    params: list[np.ndarray] = []
    for i, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:])):
        if i == len(sizes) - 2:  # linear output layer: small uniform weights
            params += [rng.uniform(-0.5, 0.5, (n_in, n_out)), rng.uniform(-0.5, 0.5, n_out)]
            continue
        beta = 0.7 * n_out ** (1.0 / n_in)
        W = rng.uniform(-1.0, 1.0, (n_in, n_out))
        W *= beta / np.linalg.norm(W, axis=0, keepdims=True)
        b = beta * np.linspace(-1.0, 1.0, n_out) * np.sign(W[0]) if n_out > 1 else np.zeros(1)
        params += [W, b]
    return params


def mlp_forward(params: list[np.ndarray], x: np.ndarray) -> np.ndarray:
    """``tanh`` hidden layers and a linear output, in numpy."""
    h = x
    last = len(params) - 2
    for i in range(0, last, 2):
        h = np.tanh(h @ params[i] + params[i + 1])
    return h @ params[last] + params[last + 1]


def mlp_forward_rowwise(params: list[np.ndarray], x: np.ndarray) -> np.ndarray:
    """:func:`mlp_forward` with each product accumulated input by input: rows independent of the batch."""
    h = x
    last = len(params) - 2
    for i in range(0, len(params), 2):
        W, b = params[i], params[i + 1]
        acc = h[:, :1] * W[0]
        for j in range(1, W.shape[0]):
            acc = acc + h[:, j:j + 1] * W[j]
        acc = acc + b
        h = np.tanh(acc) if i < last else acc
    return h


class MLPResponse(ResponseModel):
    """Feed-forward network ``d-hidden...-k`` with tanh hidden layers and a linear output.

    Args:
        hidden: hidden layer sizes (the paper: 7 and 9).
        trainer: ``"lm"`` (Levenberg-Marquardt, MATLAB ``trainlm``), ``"lbfgs"`` or ``"adam"``.
        restarts: independent initialisations; the best on validation is kept.
        max_epochs: training epochs (``trainlm``: 1000).
        max_fail: stop after this many epochs without a validation improvement (``trainlm``: 6).
        mu, mu_dec, mu_inc, mu_max, min_grad: ``trainlm`` parameters.
        learning_rate: Adam's step.
        validation_fraction: share of the training rows held out for early stopping when ``fit`` gets
            no ``validation`` set (MATLAB's 70/15/15 split holds out 15 %).
        seed: seeds initialisation and the held-out split.
        clip: see :class:`~softenv.response.ResponseModel`.
    """

    kind = "mlp"

    def __init__(self, hidden: tuple[int, ...] = (7, 9), trainer: str = "lm", restarts: int = 5,
                 max_epochs: int = 1000, max_fail: int = 6, mu: float = 1e-3, mu_dec: float = 0.1,
                 mu_inc: float = 10.0, mu_max: float = 1e10, min_grad: float = 1e-7, learning_rate: float = 1e-2,
                 validation_fraction: float = 0.15, seed: int = 0, *, clip: bool = False) -> None:
        super().__init__(clip=clip)
        self.hidden = tuple(check_int(h, "hidden", 1, 4096) for h in hidden)
        self.trainer = check_choice(trainer, "trainer", TRAINERS)
        self.restarts = check_int(restarts, "restarts", 1, 1000)
        self.max_epochs = check_int(max_epochs, "max_epochs", 1)
        self.max_fail = check_int(max_fail, "max_fail", 1)
        self.mu = check_real(mu, "mu", 0.0, None, low_open=True)
        self.mu_dec = check_real(mu_dec, "mu_dec", 0.0, 1.0, low_open=True, high_open=True)
        self.mu_inc = check_real(mu_inc, "mu_inc", 1.0, None, low_open=True)
        self.mu_max = check_real(mu_max, "mu_max", 0.0, None, low_open=True)
        self.min_grad = check_real(min_grad, "min_grad", 0.0, None)
        self.learning_rate = check_real(learning_rate, "learning_rate", 0.0, None, low_open=True)
        self.validation_fraction = check_real(validation_fraction, "validation_fraction", 0.0, 0.9, high_open=True)
        self.seed = check_int(seed, "seed", 0)

    def _fit_scaled(self, x: np.ndarray, y: np.ndarray, validation: tuple[np.ndarray, np.ndarray] | None) -> None:
        from ._torch_train import train_mlp  # torch only for training

        rng = np.random.default_rng(self.seed)
        if validation is None and self.validation_fraction > 0 and len(x) >= 10:
            perm = rng.permutation(len(x))
            n_val = max(1, int(round(self.validation_fraction * len(x))))
            validation = (x[perm[:n_val]], y[perm[:n_val]])
            x, y = x[perm[n_val:]], y[perm[n_val:]]
        sizes = [x.shape[1], *self.hidden, y.shape[1]]
        best_score, best_params, self.restart_scores_ = np.inf, [], []
        for _ in range(self.restarts):
            params, score, epochs = train_mlp(nguyen_widrow(sizes, rng), x, y, validation, self)
            self.restart_scores_.append(score)
            if score < best_score:
                best_score, best_params, self.epochs_ = score, params, epochs
        self.params_ = [np.ascontiguousarray(p) for p in best_params]
        self.validation_mse_ = float(best_score)

    def _predict_scaled(self, x: np.ndarray) -> np.ndarray:
        return mlp_forward(self.params_, x)

    def _predict_scaled_rowwise(self, x: np.ndarray) -> np.ndarray:
        return mlp_forward_rowwise(self.params_, x)

    def output_bound(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of the output for any input (tanh hidden units lie in [-1, 1]), in ``b`` units."""
        self._check_fitted()
        W, c = self.params_[-2], self.params_[-1]
        reach = np.abs(W).sum(axis=0)
        lo, hi = self.output_scaler_.inverse(c - reach), self.output_scaler_.inverse(c + reach)
        return np.minimum(lo, hi), np.maximum(lo, hi)

    def _params(self) -> dict[str, Any]:
        return {"hidden": list(self.hidden), "trainer": self.trainer, "restarts": self.restarts,
                "max_epochs": self.max_epochs, "max_fail": self.max_fail, "mu": self.mu, "mu_dec": self.mu_dec,
                "mu_inc": self.mu_inc, "mu_max": self.mu_max, "min_grad": self.min_grad,
                "learning_rate": self.learning_rate, "validation_fraction": self.validation_fraction,
                "seed": self.seed, "clip": self.clip}

    def _state(self) -> dict[str, np.ndarray]:
        return {f"p{i}": p for i, p in enumerate(self.params_)}

    def _set_state(self, state: dict[str, np.ndarray], extra: dict[str, Any], path: Any) -> None:
        sizes = [self.n_features_, *self.hidden, self.n_outputs_]
        params = []
        for i, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:])):
            W, b = state.get(f"p{2 * i}"), state.get(f"p{2 * i + 1}")
            if W is None or b is None or W.shape != (n_in, n_out) or b.shape != (n_out,):
                raise ValueError(f"{str(path)!r}: MLP weights do not fit the layer sizes {sizes}")
            params += [W, b]
        if len(state) != len(params):
            raise ValueError(f"{str(path)!r}: MLP file has {len(state)} weight arrays, layer sizes {sizes} need {len(params)}")
        self.params_ = params
