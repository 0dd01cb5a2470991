"""Training of :class:`~softenv.response.mlp.MLPResponse` in torch (float64). Imported only by ``fit``."""

from __future__ import annotations

from typing import Any

import numpy as np

try:
    import torch
    from torch.func import jacrev
except ImportError as exc:  # pragma: no cover - depends on the install
    raise ImportError("training MLPResponse needs torch: pip install -c constraints.txt 'softenv[rl]'") from exc


def _unflatten(theta: "torch.Tensor", shapes: list[tuple[int, ...]]) -> list["torch.Tensor"]:
    out, i = [], 0
    for s in shapes:
        n = int(np.prod(s))
        out.append(theta[i:i + n].reshape(s))
        i += n
    return out


def _forward(theta: "torch.Tensor", shapes: list[tuple[int, ...]], x: "torch.Tensor") -> "torch.Tensor":
    p = _unflatten(theta, shapes)
    h = x
    for i in range(0, len(p) - 2, 2):
        h = torch.tanh(h @ p[i] + p[i + 1])
    return h @ p[-2] + p[-1]


def train_mlp(init: list[np.ndarray], x: np.ndarray, y: np.ndarray,
              validation: tuple[np.ndarray, np.ndarray] | None, cfg: Any) -> tuple[list[np.ndarray], float, int]:
    """Train from ``init``; return (weights, validation MSE -- training MSE without validation, epochs run)."""
    shapes = [p.shape for p in init]
    theta = torch.tensor(np.concatenate([p.ravel() for p in init]), dtype=torch.float64)
    X, Y = torch.as_tensor(x, dtype=torch.float64), torch.as_tensor(y, dtype=torch.float64)
    if validation is not None:
        Xv = torch.as_tensor(validation[0], dtype=torch.float64)
        Yv = torch.as_tensor(validation[1], dtype=torch.float64)

    def mse(t: "torch.Tensor", a: "torch.Tensor", b: "torch.Tensor") -> float:
        with torch.no_grad():
            return float(((_forward(t, shapes, a) - b) ** 2).mean())

    def score(t: "torch.Tensor") -> float:
        return mse(t, Xv, Yv) if validation is not None else mse(t, X, Y)

    step = {"lm": _lm_epochs, "lbfgs": _lbfgs_epochs, "adam": _adam_epochs}[cfg.trainer]
    best, best_score, fails, epochs = theta.clone(), score(theta), 0, 0
    for current in step(theta, shapes, X, Y, cfg):
        epochs += 1
        s = score(current)
        if s < best_score:
            best, best_score, fails = current.clone(), s, 0
        else:
            fails += 1
            if validation is not None and fails >= cfg.max_fail:
                break
    weights = [p.detach().numpy().copy() for p in _unflatten(best, shapes)]
    return weights, best_score, epochs


def _lm_epochs(theta, shapes, X, Y, cfg):
    """Levenberg-Marquardt as MATLAB's ``trainlm``: one accepted step per epoch."""
    def residual(t):
        return (_forward(t, shapes, X) - Y).reshape(-1)

    mu = cfg.mu
    eye = torch.eye(theta.numel(), dtype=torch.float64)
    for _ in range(cfg.max_epochs):
        r = residual(theta)
        J = jacrev(residual)(theta)
        g = J.T @ r
        if float(torch.linalg.vector_norm(g)) / r.numel() < cfg.min_grad:
            return
        JTJ = J.T @ J
        error = float(r @ r)
        while mu <= cfg.mu_max:
            delta = torch.linalg.solve(JTJ + mu * eye, -g)
            candidate = theta + delta
            r_new = residual(candidate)
            if float(r_new @ r_new) < error:
                theta = candidate
                mu *= cfg.mu_dec
                break
            mu *= cfg.mu_inc
        else:
            return
        yield theta


def _lbfgs_epochs(theta, shapes, X, Y, cfg):
    """L-BFGS with a strong-Wolfe line search, 20 iterations per epoch."""
    t = theta.clone().requires_grad_(True)
    opt = torch.optim.LBFGS([t], lr=1.0, max_iter=20, history_size=20, line_search_fn="strong_wolfe",
                            tolerance_grad=cfg.min_grad, tolerance_change=1e-14)

    def closure():
        opt.zero_grad()
        loss = ((_forward(t, shapes, X) - Y) ** 2).mean()
        loss.backward()
        return loss

    for _ in range(max(1, cfg.max_epochs // 20)):
        opt.step(closure)
        yield t.detach().clone()


def _adam_epochs(theta, shapes, X, Y, cfg):
    """Full-batch Adam; an 'epoch' is 20 steps."""
    t = theta.clone().requires_grad_(True)
    opt = torch.optim.Adam([t], lr=cfg.learning_rate)
    for _ in range(max(1, cfg.max_epochs // 20)):
        for _ in range(20):
            opt.zero_grad()
            loss = ((_forward(t, shapes, X) - Y) ** 2).mean()
            loss.backward()
            opt.step()
        yield t.detach().clone()
