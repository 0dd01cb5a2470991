"""Randomized smoothing: gradients of an objective convolved with a Gaussian of spread ``temperature``.

Through contact the differentiable twin's gradient is a subgradient: the slope of the branch each substep
took (docs/gradients.md). Where an objective jumps (a contact made or broken, an impulse clamped to 0) that
slope says nothing of the jump, and where it is flat (a blade held off the incisors) it is 0. Smoothing
replaces the objective ``J`` by ``J_T(x) = E[J(x + T e)]``, ``e ~ N(0, I)``: smooth for any ``T > 0``
whatever ``J``'s jumps, equal to ``J`` as ``T -> 0``, and off ``J`` by a bias that grows with ``T``
(``scripts/smoothing_bias.py`` measures it on the scenes).

The step itself stays exact (the one Warp kernel, bit for bit against pymunk): smoothing acts on what a
caller differentiates, so it covers every discrete choice of the step at once (which edge the collision
ends on, whether the blade touches at all), which a soft contact law inside the kernel would not.

Two estimators of ``grad J_T`` from ``samples`` draws, as Suh et al. (ICML 2022, "Do differentiable
simulators give better policy gradients?") compare them:

* ``"first-order"``: the mean of the exact gradients at ``x + T e``. Low variance, but it sees only the
  slopes between jumps: where ``J`` jumps it is biased (a step function's is 0);
* ``"zeroth-order"``: ``mean((J(x + T e) - J(x - T e)) e) / (2 T)`` over antithetic pairs. Unbiased for
  ``grad J_T`` whatever the jumps (no gradient of ``J`` is taken), with a variance that grows as ``T``
  shrinks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import torch

ESTIMATORS = ("first-order", "zeroth-order")


@dataclass(frozen=True)
class SmoothedGradient:
    """What :func:`smoothed_gradient` returns: estimates over its samples, with their standard errors."""

    value: float                  # J_T(x): the mean of the samples' objective
    value_stderr: float
    gradient: torch.Tensor        # grad J_T(x), the shape of x
    gradient_stderr: torch.Tensor  # each entry's standard error (nan with one sample or one pair)
    temperature: float
    samples: int
    estimator: str


def smoothed_gradient(objective: Callable[[torch.Tensor], torch.Tensor], x: torch.Tensor, temperature: float,
                      samples: int, estimator: str = "first-order",
                      generator: torch.Generator | None = None) -> SmoothedGradient:
    """The gradient at ``x`` of ``objective`` smoothed by a Gaussian of spread ``temperature`` (``x``'s units).

    ``objective`` takes a batch ``(samples, *x.shape)`` of points and returns each one's value ``(samples,)``,
    so one batched rollout (an env per sample) serves all of them; for ``"first-order"`` its values must carry
    autograd's graph back to the points. ``temperature = 0`` gives the exact (sub)gradient at ``x``. The draws
    come from ``generator`` (torch's global one when ``None``): a seeded generator repeats the estimate bit
    for bit."""
    if estimator not in ESTIMATORS:
        raise ValueError(f"estimator={estimator!r}: must be one of {ESTIMATORS}")
    if isinstance(temperature, bool) or not isinstance(temperature, (int, float)) or not math.isfinite(temperature) \
            or temperature < 0:
        raise ValueError(f"temperature={temperature!r}: must be a finite number >= 0")
    pairs = estimator == "zeroth-order"
    if isinstance(samples, bool) or not isinstance(samples, int) or samples < (2 if pairs else 1) \
            or (pairs and samples % 2):
        allowed = "an even integer >= 2 (antithetic pairs)" if pairs else "an integer >= 1"
        raise ValueError(f"samples={samples!r}: must be {allowed} for the {estimator} estimator")
    if pairs and temperature == 0:
        raise ValueError("temperature=0: the zeroth-order estimator divides by it; must be > 0 (or use "
                         "estimator='first-order' for the exact gradient)")
    if not isinstance(x, torch.Tensor) or not x.is_floating_point():
        raise ValueError(f"x: must be a floating-point torch tensor, got {type(x).__name__} "
                         f"{getattr(x, 'dtype', '')}".rstrip())
    if not torch.isfinite(x).all():
        raise ValueError(f"x: must be finite; {int((~torch.isfinite(x)).sum())} of its {x.numel()} entries are not")
    x = x.detach()
    noise = torch.randn((samples // 2 if pairs else samples, *x.shape), generator=generator, dtype=x.dtype,
                        device=x.device)
    if pairs:
        with torch.no_grad():
            values = _values(objective, torch.cat([x + temperature * noise, x - temperature * noise]), samples)
        half = samples // 2
        slopes = (values[:half] - values[half:]) / (2 * temperature)
        per_draw = slopes.reshape(-1, *([1] * x.dim())) * noise
    else:
        points = (x + temperature * noise).requires_grad_(True)
        values = _values(objective, points, samples)
        if not values.requires_grad:
            raise ValueError("objective: its values carry no gradient to the points; the first-order estimator "
                             "needs a differentiable objective (a twin made with differentiable=True)")
        per_draw = torch.autograd.grad(values.sum(), points)[0]
        values = values.detach()
    draws = per_draw.shape[0]
    nan = torch.full_like(x, torch.nan)
    return SmoothedGradient(
        value=float(values.mean()),
        value_stderr=float(values.std() / math.sqrt(samples)) if samples > 1 else math.nan,
        gradient=per_draw.mean(0),
        gradient_stderr=per_draw.std(0) / math.sqrt(draws) if draws > 1 else nan,
        temperature=float(temperature), samples=samples, estimator=estimator)


def _values(objective: Callable[[torch.Tensor], torch.Tensor], points: torch.Tensor, samples: int) -> torch.Tensor:
    values = objective(points)
    if not isinstance(values, torch.Tensor) or tuple(values.shape) != (samples,):
        raise ValueError(f"objective: must return a tensor of shape ({samples},), one value a point; got "
                         f"{tuple(values.shape) if isinstance(values, torch.Tensor) else type(values).__name__}")
    if not torch.isfinite(values.detach()).all():
        raise ValueError(f"objective: returned {int((~torch.isfinite(values.detach())).sum())} non-finite values "
                         f"of {samples}")
    return values
