"""Tissue identification from a device log: the tongue's stiffness and the hand-blade coupling fitted to
a recorded session by gradients through the differentiable torch twin (``docs/gradients.md``).

A session is a hand-pose log (what ``softenv play`` writes and ``softenv score`` reads) and what its sensors
read at each control period (:data:`CHANNELS`, the log's optional columns; :func:`identify_log` fits a log
that carries them): the tongue's normal force (a blade-mounted load cell, as the
manikin studies measure it) and the blade's height (a tracked marker). The hand's path does not depend on
the tissue: :func:`log_actions` turns the log into the actions that replay it (as
:func:`~softenv.training.scoring.replay_hand` steers), and :func:`identify` replays them on the torch twin
with the parameters of :data:`PARAMETERS` tracked (factors on the scene's values:
:meth:`~softenv.envs.torch_twin.SoftSphereTorchVectorEnv.track_params`), one env a session, and fits their
logarithms by Adam: weighted least squares, each channel's residual over its sensor's noise. Sessions are
fitted side by side, each env's loss a function of its own parameters only.

Error bars (:class:`Identification`): the Laplace approximation at the fit, the covariance of the
log-parameters the inverse of the loss's Hessian (central differences of its gradient; the residuals are
in units of their noise). Where the sensors cannot separate two parameters, their errors correlate near
-1 or 1 (:meth:`Identification.confounded`): the session fixes a combination of them, not each.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from .._validation import check_array, check_int, check_real
from ..envs.torch_twin import SoftSphereTorchVectorEnv
from ..sections import SceneConfig
from .hand import hand_actions, hand_config, haptic_config, reach_env, steer
from .logs import HAND_LOG, SENSOR_COLUMNS, read_log, read_readings, read_scene

PARAMETERS = ("tissue_stiffness", "coupling_stiffness", "coupling_damping")   # each a factor on the scene's
# what a session's sensors measure each control period, from the step's info: the tongue's normal force (a
# blade-mounted load cell) and the blade's height (a tracked marker on its centre of mass, zeroed at its first
# reading); a hand-pose log carries them as its optional columns
CHANNELS = SENSOR_COLUMNS


def log_actions(table: np.ndarray, config: SceneConfig | None = None, source: str = "log") -> np.ndarray:
    """The actions ``(K, 4)`` that replay the hand-pose log ``table`` on ``config``'s laryngoscope, one a control
    period (the closed-loop steering of :func:`~softenv.training.hand.steer`)."""
    config = hand_config(config)
    _, poses = hand_actions(table, config, source)
    env = reach_env(config, len(poses) - 1)
    env.reset(seed=0)
    return np.array([action for action, _ in steer(env, poses)], dtype=np.float64)


def log_readings(table: np.ndarray, readings: dict[str, np.ndarray], config: SceneConfig | None = None,
                 source: str = "log") -> tuple[tuple[str, ...], np.ndarray]:
    """The sensor readings of a hand-pose log (``readings``: column -> a reading a row of ``table``) as
    :func:`identify` takes them: the channels the log has (in :data:`CHANNELS` order) and each one's reading
    at the end of each control period ``(K, C)`` of its replay (:func:`log_actions`), interpolated linearly
    between rows as the poses are, the blade's height zeroed at the first period's reading (as
    :func:`measure` zeroes the twin's marker: a marker's mount is not known)."""
    times, _ = hand_actions(table, hand_config(config), source)
    channels = tuple(c for c in CHANNELS if c in readings)
    if not channels:
        raise ValueError(f"{source} carries no sensor readings: identification needs one or more of the columns "
                         f"{list(CHANNELS)} (what softenv play records beside the hand's poses)")
    elapsed = table[:, 0] - table[0, 0]
    columns = []
    for c in channels:
        values = np.interp(times, elapsed, readings[c])
        columns.append(values - values[0] if c == "blade_z_mm" else values)
    return channels, np.column_stack(columns)


def identify_log(path: str | Path, noise: dict[str, float], config: SceneConfig | None = None,
                 names: Sequence[str] = PARAMETERS, **fit: Any) -> Identification:
    """Fit ``names`` to the session a hand-pose log records (its poses and its sensor columns), on
    ``config``'s scene (default: the scene the log records, as ``softenv score`` replays it); ``noise``:
    each channel's sensor standard deviation, for every channel the log carries; ``fit``: :func:`identify`'s
    ``iterations``, ``lr``, ``newton``."""
    _, table = read_log(path, HAND_LOG)
    source = f"trajectory {str(path)!r}"
    config = haptic_config(read_scene(path)) if config is None else hand_config(config)
    channels, measured = log_readings(table, read_readings(path), config, source)
    missing = [c for c in channels if c not in noise]
    if missing:
        raise ValueError(f"noise={noise!r}: give the standard deviation of every channel the log carries ({missing} "
                         "missing)")
    actions = log_actions(table, config, source)
    return identify(actions[:, None], measured[:, None], [noise[c] for c in channels], config, names, channels, **fit)


def session_env(config: SceneConfig, sessions: int, steps: int) -> SoftSphereTorchVectorEnv:
    """The differentiable torch twin of ``config`` with one env a session, over ``steps`` control periods."""
    sections: dict[str, Any] = {**config, "task": {**config["task"], "kind": "reach", "horizon": steps}}
    return SoftSphereTorchVectorEnv(num_envs=sessions, differentiable=True, **sections)


def measure(env: SoftSphereTorchVectorEnv, actions: torch.Tensor, channels: tuple[str, ...]) -> torch.Tensor:
    """What ``channels`` (of :data:`CHANNELS`) read ``(K, n, C)`` at each control period of ``actions``
    ``(K, n, 4)`` from a reset."""
    env.reset(seed=0)
    start: torch.Tensor | None = None
    readings = []
    for a in actions:
        info = env.step(a)[4]
        z = info["blade_pose"][:, 1]
        start = z if start is None else start       # a marker zeroed at its first reading (its mount's offset unknown)
        values = {"tongue_force_N": info["tongue_force_N"], "blade_z_mm": (z - start) * 1e3}
        readings.append(torch.stack([values[c] for c in channels], dim=-1))
    return torch.stack(readings)


def _channels(channels: Sequence[str]) -> tuple[str, ...]:
    chosen = tuple(channels)
    if not chosen or any(c not in CHANNELS for c in chosen) or len(set(chosen)) != len(chosen):
        raise ValueError(f"channels={list(chosen)!r}: choose one or more of {list(CHANNELS)}, each once")
    return chosen


def simulate_sessions(actions: np.ndarray, truth: dict[str, np.ndarray], config: SceneConfig | None = None,
                      channels: Sequence[str] = CHANNELS, noise: Sequence[float] | None = None,
                      seed: int = 0) -> np.ndarray:
    """What the sensors ``channels`` read ``(K, n, C)`` in sessions of known parameters: under ``actions``
    ``(K, n, 4)`` with each session's factors ``truth`` (name -> ``(n,)``), plus Gaussian noise of ``noise``
    (each channel's standard deviation; None: none)."""
    config, channels = hand_config(config), _channels(channels)
    a = torch.as_tensor(check_array(actions, "actions", ndim=(3,)), dtype=torch.float64)
    env = session_env(config, a.shape[1], a.shape[0])
    leaves = env.track_params(tuple(truth))
    with torch.no_grad():
        for name, values in truth.items():
            leaves[name].copy_(torch.as_tensor(np.asarray(values, dtype=np.float64)))
        clean = measure(env, a, channels).numpy()
    if noise is None:
        return clean
    sigma = _noise(noise, channels)
    return clean + np.random.default_rng(seed).normal(0.0, 1.0, clean.shape) * sigma


def _noise(noise: Sequence[float], channels: tuple[str, ...]) -> np.ndarray:
    sigma = check_array(noise, "noise", ndim=(1,))
    if len(sigma) != len(channels) or not (sigma > 0).all():
        raise ValueError(f"noise={sigma.tolist()!r}: one standard deviation > 0 per channel of {list(channels)}")
    return sigma


@dataclass
class Identification:
    """Fitted factors (name -> ``(n,)``), their 95 % intervals (Laplace, in the log-parameters), the
    correlation matrices ``(n, p, p)`` of the log-parameters' errors, each session's residuals' RMS over the
    channels' noise, and the loss per iteration."""

    names: tuple[str, ...]
    values: dict[str, np.ndarray]
    low: dict[str, np.ndarray]
    high: dict[str, np.ndarray]
    correlation: np.ndarray
    normalised_rms: np.ndarray
    losses: list[float]

    def confounded(self, threshold: float = 0.95) -> list[tuple[str, str, float]]:
        """The pairs of parameters whose errors correlate beyond ``threshold`` in the median session (its
        median correlation): what the sessions cannot separate, only a combination of."""
        rho = np.median(self.correlation, axis=0)
        return [(a, b, float(rho[i, j])) for i, a in enumerate(self.names) for j, b in enumerate(self.names)
                if i < j and abs(rho[i, j]) > threshold]


def identify(actions: np.ndarray, measured: np.ndarray, noise: Sequence[float], config: SceneConfig | None = None,
             names: Sequence[str] = PARAMETERS, channels: Sequence[str] = CHANNELS, iterations: int = 150,
             lr: float = 0.05, newton: int = 2) -> Identification:
    """Fit ``names`` (factors on the scene's values, from 1) to the readings ``measured`` ``(K, n, C)`` of
    ``channels`` in ``n`` sessions replayed by ``actions`` ``(K, n, 4)`` (:func:`log_actions`): weighted least
    squares (each channel's residual over its ``noise``), by ``iterations`` of Adam (learning rate ``lr``) on
    the parameters' logarithms, then ``newton`` Newton steps on the loss's Hessian (none along a direction it
    does not curve); error bars as the module docstring says."""
    config, channels = hand_config(config), _channels(channels)
    check_int(iterations, "iterations", 1, 100_000)
    check_real(lr, "lr", 0.0, 10.0, low_open=True)
    check_int(newton, "newton", 0, 100)
    a = torch.as_tensor(check_array(actions, "actions", ndim=(3,)), dtype=torch.float64)
    y = torch.as_tensor(check_array(measured, "measured", ndim=(3,)), dtype=torch.float64)
    if tuple(y.shape) != (a.shape[0], a.shape[1], len(channels)):
        raise ValueError(f"measured has shape {tuple(y.shape)}; it must be (steps, sessions, channels) = "
                         f"{(a.shape[0], a.shape[1], len(channels))}: each channel's reading at each control period")
    sigma = torch.as_tensor(_noise(noise, channels))
    names = tuple(names)
    if not names or any(n not in PARAMETERS for n in names) or len(set(names)) != len(names):
        raise ValueError(f"names={list(names)!r}: choose one or more of {list(PARAMETERS)}, each once")
    fit = _Fit(session_env(config, a.shape[1], a.shape[0]), names, channels, a, y, sigma)
    theta = torch.zeros(len(names), a.shape[1], dtype=torch.float64, requires_grad=True)
    optimizer = torch.optim.Adam([theta], lr=lr)
    losses = []
    for _ in range(iterations):
        loss, grad = fit(theta.detach())
        optimizer.zero_grad()
        theta.grad = grad
        optimizer.step()
        losses.append(float(loss.sum()))
    fitted = theta.detach().clone()
    for _ in range(newton):                  # Adam's last steps jitter: Newton's converge where the loss curves
        hessian = fit.hessian(fitted)
        w, v = torch.linalg.eigh(hessian)
        inverse = torch.where(w > 1e-6 * w.max(dim=-1, keepdim=True).values, 1.0 / w, 0.0)   # flat directions: no step
        step = (v * inverse[:, None, :]) @ v.transpose(1, 2) @ fit(fitted)[1].T[:, :, None]
        fitted -= step[:, :, 0].T
        losses.append(float(fit(fitted)[0].sum()))
    loss, _ = fit(fitted)
    cov = _covariance(fit.hessian(fitted))                                             # (n, p, p)
    sd = torch.sqrt(torch.diagonal(cov, dim1=1, dim2=2))                               # (n, p)
    corr = cov / (sd[:, :, None] * sd[:, None, :])
    values = {name: np.exp(fitted[j].numpy()) for j, name in enumerate(names)}
    # a flat direction's interval runs to 0 and infinity (torch's exp saturates where numpy's would warn)
    low = {name: torch.exp(fitted[j] - 1.96 * sd[:, j]).numpy() for j, name in enumerate(names)}
    high = {name: torch.exp(fitted[j] + 1.96 * sd[:, j]).numpy() for j, name in enumerate(names)}
    rms = torch.sqrt(2.0 * loss / (a.shape[0] * len(channels)))
    return Identification(names, values, low, high, corr.numpy(), rms.numpy(), losses)


def _covariance(hessian: torch.Tensor, floor: float = 1e-12) -> torch.Tensor:
    """The inverse of each session's Hessian ``(n, p, p)``, its curvatures held at least ``floor`` times the
    largest (a direction the data do not curve, or that differences make slightly negative, gets a variance
    ``1 / floor`` times the best-determined one's: a flat ridge, not a division by 0)."""
    w, v = torch.linalg.eigh(hessian)
    w = torch.maximum(w, floor * w.max(dim=-1, keepdim=True).values.clamp(min=1e-300))
    return (v / w[:, None, :]) @ v.transpose(1, 2)


def _grad(leaf: torch.Tensor) -> torch.Tensor:
    """A leaf's gradient after ``backward()`` (zeros where the readings do not depend on it)."""
    return torch.zeros_like(leaf) if leaf.grad is None else leaf.grad


class _Fit:
    """Each session's loss and its gradient in the log-parameters, on one env a session."""

    def __init__(self, env: SoftSphereTorchVectorEnv, names: tuple[str, ...], channels: tuple[str, ...],
                 actions: torch.Tensor, measured: torch.Tensor, sigma: torch.Tensor) -> None:
        self.env, self.names, self.channels = env, names, channels
        self.actions, self.measured, self.sigma = actions, measured, sigma
        self.leaves = env.track_params(names)

    def __call__(self, theta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Each session's half sum of squared normalised residuals ``(n,)`` at log-parameters ``theta``
        ``(p, n)``, and its gradient ``(p, n)`` (a session's loss depends on its own column only)."""
        with torch.no_grad():
            for j, name in enumerate(self.names):
                self.leaves[name].copy_(torch.exp(theta[j]))
                self.leaves[name].grad = None
        r = (measure(self.env, self.actions, self.channels) - self.measured) / self.sigma
        loss = 0.5 * torch.sum(r * r, dim=(0, 2))
        loss.sum().backward()
        grad = torch.stack([_grad(self.leaves[n]) * self.leaves[n].detach() for n in self.names])   # d/dlog = x d/dx
        self.env.detach()
        return loss.detach(), grad

    def hessian(self, theta: torch.Tensor, step: float = 1e-4) -> torch.Tensor:
        """Each session's Hessian ``(n, p, p)`` of its loss: central differences of the gradient, symmetrised."""
        columns = []
        for j in range(len(self.names)):
            shift = torch.zeros_like(theta)
            shift[j] = step
            columns.append((self(theta + shift)[1] - self(theta - shift)[1]) / (2.0 * step))   # (p, n)
        h = torch.stack(columns, dim=1).permute(2, 0, 1)                                     # (n, p, p)
        return 0.5 * (h + h.transpose(1, 2))
