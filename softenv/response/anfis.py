r"""First-order Takagi-Sugeno fuzzy model trained by ANFIS (Jang 1993), the paper's second regressor.

Layers: membership functions -> rule strength (product) -> normalisation -> linear consequents ->
sum. Rule strengths are computed in log space and normalised with a softmax, so an input far from
every rule never gives the ``0/0`` of "no rule fires": the output is always a convex combination of
the rules' linear consequents, finite for finite input and bounded by ``max_r |a_r0 + a_r . x|``
(it grows at most linearly far outside the data, where the nearest rules dominate).

Training is ANFIS's hybrid learning: in each epoch the consequents are solved by regularised least
squares with the premise fixed (the grid partition has ``(n+1) m^n`` unknowns -- 80 for 4 inputs and
2 MFs, more than the 77 training rows of the paper's split -- hence the ridge), then the premise
parameters take one gradient step of fixed length (``step_size``), adapted by Jang's rules (x1.1
after four decreases of the error, x0.9 after two up-down oscillations). The parameters of the epoch
with the lowest validation error (training error without validation data) are kept. Membership
widths never fall below ``min_width``.

Rules come from a grid partition (``n_mfs`` per input, MATLAB ``genfis1``) or from subtractive
clustering of the inputs (Chiu 1994, MATLAB ``genfis2``): one Gaussian rule per cluster centre.
One model per shape parameter (the paper's choice, ``multi_output=False``) or one shared premise
for all outputs.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from .._validation import check_choice, check_int, check_real
from .base import ResponseModel

MF_KINDS = ("gbell", "gaussian")


def subtractive_clustering(u: np.ndarray, radius: float = 0.5, squash: float = 1.25, accept: float = 0.5,
                           reject: float = 0.15) -> np.ndarray:
    """Chiu's subtractive clustering of points ``u`` in the unit hypercube; returns the centres."""
    alpha, beta = 4.0 / radius ** 2, 4.0 / (squash * radius) ** 2
    d2 = ((u[:, None, :] - u[None, :, :]) ** 2).sum(axis=2)
    potential = np.exp(-alpha * d2).sum(axis=1)
    first = potential.max()
    centres: list[np.ndarray] = []
    while True:
        i = int(np.argmax(potential))
        p = potential[i]
        if p > accept * first or not centres:
            pass
        elif p < reject * first:
            break
        else:
            d_min = min(np.sqrt(((u[i] - c) ** 2).sum()) for c in centres)
            if d_min / radius + p / first < 1.0:
                potential[i] = 0.0
                if potential.max() <= 0:
                    break
                continue
        centres.append(u[i].copy())
        potential = potential - p * np.exp(-beta * ((u - u[i]) ** 2).sum(axis=1))
        if potential.max() <= 0 or len(centres) >= len(u):
            break
    return np.array(centres)


class AnfisResponse(ResponseModel):
    """Takagi-Sugeno fuzzy model (first order) trained by ANFIS hybrid learning.

    Args:
        n_mfs: membership functions per input for the grid partition (MATLAB default 2).
        mf: ``"gbell"`` (MATLAB default) or ``"gaussian"``.
        rules: ``"grid"`` (``n_mfs ** d`` rules) or ``"cluster"`` (subtractive clustering).
        cluster_radius: range of influence of a cluster centre, in the unit hypercube (genfis2: 0.5).
        epochs: training epochs (MATLAB default 10).
        step_size: initial length of the premise gradient step (MATLAB default 0.01).
        ridge: Tikhonov weight of the consequent least squares, relative to the mean diagonal.
        multi_output: one shared premise for all shape parameters instead of one model per parameter.
        min_width: smallest membership width (``a`` of gbell, ``sigma`` of Gaussian), scaled units.
        clip: see :class:`~softenv.response.ResponseModel`.
    """

    kind = "anfis"
    rule_mf_: np.ndarray          # (R, d) each rule's membership function per input
    premise_: np.ndarray          # (d, m, P) membership parameters
    consequent_: np.ndarray       # (K, R, d + 1, q) linear consequents

    def __init__(self, n_mfs: int = 2, mf: str = "gbell", rules: str = "grid", cluster_radius: float = 0.5,
                 epochs: int = 10, step_size: float = 0.01, ridge: float = 1e-6, multi_output: bool = False,
                 min_width: float = 0.05, *, clip: bool = False) -> None:
        super().__init__(clip=clip)
        self.n_mfs = check_int(n_mfs, "n_mfs", 1, 10)
        self.mf = check_choice(mf, "mf", MF_KINDS)
        self.rules = check_choice(rules, "rules", ("grid", "cluster"))
        self.cluster_radius = check_real(cluster_radius, "cluster_radius", 0.0, 2.0, low_open=True)
        self.epochs = check_int(epochs, "epochs", 0, 100_000)
        self.step_size = check_real(step_size, "step_size", 0.0, None, low_open=True)
        self.ridge = check_real(ridge, "ridge", 0.0, None)
        self.multi_output = bool(multi_output)
        self.min_width = check_real(min_width, "min_width", 0.0, None, low_open=True)

    # -- structure --------------------------------------------------------------------------------

    def _initial_premise(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rule table ``(R, d)`` and premise ``(d, m, P)`` on scaled inputs in [-1, 1]."""
        d = x.shape[1]
        if self.rules == "grid":
            m = self.n_mfs
            rule_mf = np.array(list(itertools.product(range(m), repeat=d)), dtype=np.int64)
            centres = np.linspace(-1.0, 1.0, m) if m > 1 else np.zeros(1)
            width = 2.0 / (2 * (m - 1)) if m > 1 else 1.0   # genfis1: neighbouring MFs cross at 0.5
            c = np.broadcast_to(centres, (d, m))
            if self.mf == "gbell":
                premise = np.stack([np.full((d, m), width), np.full((d, m), 2.0), c], axis=-1)
            else:
                premise = np.stack([np.full((d, m), width / np.sqrt(2 * np.log(2))), c], axis=-1)
        else:
            centres = subtractive_clustering((x + 1.0) / 2.0, self.cluster_radius) * 2.0 - 1.0   # (R, d)
            R = len(centres)
            rule_mf = np.tile(np.arange(R)[:, None], (1, d))
            sigma = np.full((d, R), self.cluster_radius * 2.0 / np.sqrt(8.0))                 # genfis2
            if self.mf == "gbell":
                premise = np.stack([sigma * np.sqrt(2 * np.log(2)), np.full((d, R), 2.0), centres.T], axis=-1)
            else:
                premise = np.stack([sigma, centres.T], axis=-1)
        return rule_mf, np.ascontiguousarray(premise, dtype=np.float64)

    # -- forward pass -----------------------------------------------------------------------------

    def _log_memberships(self, x: np.ndarray, premise: np.ndarray, with_grad: bool = False
                         ) -> tuple[np.ndarray, Any]:
        """``log mu`` ``(K, N, d, m)`` and, if asked, ``d log mu / d premise`` ``(K, N, d, m, P)``."""
        xe = x[None, :, :, None]
        if self.mf == "gaussian":
            sigma, c = premise[..., 0][:, None], premise[..., 1][:, None]
            r = (xe - c) / sigma
            logmu = -0.5 * r ** 2
            if not with_grad:
                return logmu, None
            return logmu, np.stack([r ** 2 / sigma, r / sigma], axis=-1)
        a, b, c = premise[..., 0][:, None], premise[..., 1][:, None], premise[..., 2][:, None]
        diff = xe - c
        z = np.abs(diff) / a
        if not with_grad:  # z = 0 gives log mu = 0: a tiny floor avoids log(0) and its warning
            return -np.logaddexp(0.0, 2.0 * b * np.log(np.maximum(z, 1e-300))), None
        with np.errstate(divide="ignore", invalid="ignore"):
            logz = np.log(z)
            t = 2.0 * b * logz
            logmu = -np.logaddexp(0.0, t)
            sig = np.where(z > 0, 1.0 / (1.0 + np.exp(-t)), 0.0)          # z^2b / (1 + z^2b)
            d_a = sig * 2.0 * b / a
            d_b = np.where(z > 0, -2.0 * logz * sig, 0.0)
            d_c = np.where(z > 0, 2.0 * b * np.sign(diff) * sig / (a * z), 0.0)   # ~ z^(2b-1) -> 0 at z = 0
        return logmu, np.stack([d_a, d_b, d_c], axis=-1)

    def _weights(self, logmu: np.ndarray) -> np.ndarray:
        """Normalised rule strengths ``(K, N, R)``: softmax of the summed log memberships."""
        K, N, d, m = logmu.shape
        ell = logmu.reshape(K, N, d * m) @ self._selector                   # (K, N, R): sum over each rule's MFs
        ell -= ell.max(axis=-1, keepdims=True)
        w = np.exp(ell)
        w /= w.sum(axis=-1, keepdims=True)
        return w

    def _outputs(self, x: np.ndarray, w: np.ndarray, consequent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rule outputs ``f`` ``(K, N, R, q)`` and model outputs ``(K, N, q)``."""
        f = consequent[:, None, :, 0, :] + np.einsum("ni,kriq->knrq", x, consequent[:, :, 1:, :])
        return f, np.einsum("knr,knrq->knq", w, f)

    def _predict_scaled(self, x: np.ndarray) -> np.ndarray:
        logmu, _ = self._log_memberships(x, self.premise_)
        _, y = self._outputs(x, self._weights(logmu), self.consequent_)
        return y[:, :, 0].T if not self.multi_output else y[0]

    def _predict_scaled_rowwise(self, x: np.ndarray) -> np.ndarray:
        logmu, _ = self._log_memberships(x, self.premise_)                    # elementwise
        ell = logmu[:, :, 0, self.rule_mf_[:, 0]]
        for i in range(1, x.shape[1]):
            ell = ell + logmu[:, :, i, self.rule_mf_[:, i]]                  # (K, N, R)
        ell = np.ascontiguousarray(ell)  # reductions over a strided axis change their order with N
        w = np.exp(ell - ell.max(axis=-1, keepdims=True))
        w = w / w.sum(axis=-1, keepdims=True)
        c = self.consequent_                                                 # (K, R, d + 1, q)
        f = c[:, None, :, 0, :]
        for i in range(x.shape[1]):
            f = f + x[None, :, None, i:i + 1] * c[:, None, :, i + 1, :]      # (K, N, R, q)
        y = np.ascontiguousarray((w[..., None] * f).transpose(0, 1, 3, 2)).sum(axis=-1)  # rules on a contiguous last axis
        return y[:, :, 0].T if not self.multi_output else y[0]

    # -- hybrid learning --------------------------------------------------------------------------

    def _fit_scaled(self, x: np.ndarray, y: np.ndarray, validation: tuple[np.ndarray, np.ndarray] | None) -> None:
        n, d = x.shape
        self.rule_mf_, premise = self._initial_premise(x)
        self._set_selector(premise.shape[1])
        K = 1 if self.multi_output else y.shape[1]
        targets = y[None] if self.multi_output else y.T[:, :, None]               # (K, N, q)
        premise = np.repeat(premise[None], K, axis=0)
        m = premise.shape[2]
        onehot = (self.rule_mf_[:, :, None] == np.arange(m)).astype(np.float64)   # (R, d, m)
        x1 = np.concatenate([np.ones((n, 1)), x], axis=1)
        step = np.full(K, self.step_size)
        errors: list[np.ndarray] = []
        best = np.full(K, np.inf)
        best_premise, best_consequent = premise.copy(), None
        self.best_epoch_ = np.zeros(K, dtype=np.int64)
        val_targets = None
        if validation is not None:
            xv, yv = validation
            val_targets = yv[None] if self.multi_output else yv.T[:, :, None]
        history = []
        for epoch in range(max(self.epochs, 1)):
            logmu, dlogmu = self._log_memberships(x, premise, with_grad=True)
            w = self._weights(logmu)
            consequent = self._least_squares(w, x1, targets)
            f, out = self._outputs(x, w, consequent)
            err = ((out - targets) ** 2).mean(axis=(1, 2))
            if val_targets is not None:
                lv, _ = self._log_memberships(xv, premise)
                _, ov = self._outputs(xv, self._weights(lv), consequent)
                score = ((ov - val_targets) ** 2).mean(axis=(1, 2))
            else:
                score = err
            history.append(np.stack([err, score]))
            better = score < best
            best = np.where(better, score, best)
            best_premise[better] = premise[better]
            best_consequent = consequent.copy() if best_consequent is None else np.where(
                better[:, None, None, None], consequent, best_consequent)
            self.best_epoch_[better] = epoch
            if epoch == self.epochs - 1 or self.epochs == 0:
                break
            # gradient of the mean squared error with respect to the premise, consequents fixed
            resid = 2.0 * (out - targets) / (n * targets.shape[2])                # (K, N, q)
            G = w * np.einsum("knq,knrq->knr", resid, f - out[:, :, None, :])    # dE / d log-strength
            H = np.einsum("knr,rim->knim", G, onehot)
            grad = np.einsum("knim,knimp->kimp", H, dlogmu)
            norm = np.sqrt((grad ** 2).sum(axis=(1, 2, 3)))
            premise = premise - (step / np.where(norm > 0, norm, 1.0))[:, None, None, None] * grad
            self._enforce_limits(premise)
            errors.append(err)
            step = self._adapt_step(step, errors)
        assert best_consequent is not None                                       # every run has an epoch
        self.premise_, self.consequent_ = best_premise, best_consequent
        self.history_ = np.array(history)                                          # (epochs, 2, K)

    def _least_squares(self, w: np.ndarray, x1: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """Ridge solution of the consequents ``(K, R, d + 1, q)`` for fixed strengths ``w``."""
        K, n, R = w.shape
        D = (w[:, :, :, None] * x1[None, :, None, :]).reshape(K, n, -1)
        A = np.einsum("kni,knj->kij", D, D)
        lam = self.ridge * np.trace(A, axis1=1, axis2=2) / A.shape[1] + 1e-12
        A[:, np.arange(A.shape[1]), np.arange(A.shape[1])] += lam[:, None]
        theta = np.linalg.solve(A, np.einsum("kni,knq->kiq", D, targets))
        return theta.reshape(K, R, x1.shape[1], -1)

    def _set_selector(self, n_mfs: int) -> None:
        """0/1 matrix ``(d * m, R)`` picking each rule's membership functions (so strengths are one product)."""
        d = self.rule_mf_.shape[1]
        sel = np.zeros((d, n_mfs, self.rule_mf_.shape[0]))
        sel[np.arange(d)[None, :], self.rule_mf_, np.arange(self.rule_mf_.shape[0])[:, None]] = 1.0
        self._selector = sel.reshape(d * n_mfs, -1)

    def _enforce_limits(self, premise: np.ndarray) -> None:
        np.maximum(premise[..., 0], self.min_width, out=premise[..., 0])
        if self.mf == "gbell":
            np.clip(premise[..., 1], 0.55, 20.0, out=premise[..., 1])

    @staticmethod
    def _adapt_step(step: np.ndarray, errors: list[np.ndarray]) -> np.ndarray:
        """Jang's rules: x1.1 after 4 consecutive decreases; x0.9 after two up-down oscillations."""
        if len(errors) < 5:
            return step
        diffs = np.diff(np.array(errors[-5:]), axis=0) < 0                       # (4, K): True = decrease
        grow = diffs.all(axis=0)
        oscillate = (diffs[0] != diffs[1]) & (diffs[1] != diffs[2]) & (diffs[2] != diffs[3])
        return np.where(grow, step * 1.1, np.where(oscillate, step * 0.9, step))

    # -- persistence ------------------------------------------------------------------------------

    def _params(self) -> dict[str, Any]:
        return {"n_mfs": self.n_mfs, "mf": self.mf, "rules": self.rules, "cluster_radius": self.cluster_radius,
                "epochs": self.epochs, "step_size": self.step_size, "ridge": self.ridge,
                "multi_output": self.multi_output, "min_width": self.min_width, "clip": self.clip}

    def _state(self) -> dict[str, np.ndarray]:
        return {"rule_mf": self.rule_mf_, "premise": self.premise_, "consequent": self.consequent_}

    def _set_state(self, state: dict[str, np.ndarray], extra: dict[str, Any], path: Any) -> None:
        try:
            rule_mf, premise, consequent = state["rule_mf"], state["premise"], state["consequent"]
        except KeyError as exc:
            raise ValueError(f"{str(path)!r}: ANFIS state is missing {exc}") from exc
        K = 1 if self.multi_output else self.n_outputs_
        P = 3 if self.mf == "gbell" else 2
        R = rule_mf.shape[0]
        ok = (rule_mf.ndim == 2 and rule_mf.shape[1] == self.n_features_ and premise.ndim == 4
              and premise.shape[0] == K and premise.shape[1] == self.n_features_ and premise.shape[3] == P
              and consequent.shape == (K, R, self.n_features_ + 1, self.n_outputs_ if self.multi_output else 1)
              and rule_mf.min() >= 0 and rule_mf.max() < premise.shape[2])
        if not ok:
            raise ValueError(f"{str(path)!r}: ANFIS arrays do not fit {self.n_features_} inputs, {self.n_outputs_} outputs")
        self.rule_mf_, self.premise_, self.consequent_ = rule_mf, premise, consequent
        self._set_selector(premise.shape[2])

    @property
    def n_rules_(self) -> int:
        return int(self.rule_mf_.shape[0])
