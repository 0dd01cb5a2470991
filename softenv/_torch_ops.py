"""The elementwise operations of :mod:`softenv._ops` on torch tensors: the task's formulas in the torch
twin and the laryngoscope's physics on tensors (:mod:`softenv.devices.laryngoscope.tensors`).

Not bit for bit with numpy: torch computes ``cos``, ``sin``, ``exp``, ``atan2`` and ``asin`` with its
own vector code, so a tensor batch agrees with the numpy one to rounding (tested per use). Two rules
keep it in float64 where numpy is: an index is a float64 tensor of whole numbers (``int64 * float``
is float32 in torch, float64 in numpy), cast to ``int64`` only to take.
"""

from __future__ import annotations

import math
from typing import Any, Callable

import array_api_compat.torch as xp_torch
import torch


def _flat_at_ends(op: Callable[[torch.Tensor], torch.Tensor], x: torch.Tensor,
                  inside: Callable[[torch.Tensor], torch.Tensor], safe: float) -> torch.Tensor:
    """``op(x)`` bit for bit; under autograd its slope is 0 where ``inside(x)`` fails (the ends of ``op``'s
    domain, where its own slope is infinite), the rows there evaluated at ``safe`` for the graph only."""
    if not x.requires_grad:
        return op(x)
    keep = inside(x)
    return torch.where(keep, op(torch.where(keep, x, safe)), op(x.detach()))


class TorchOps:
    """:class:`~softenv._ops.PhysicsOps` on tensors, with ``xp``, their array namespace (torch through
    ``array_api_compat``, with numpy's names) for the code that is written for whole arrays."""

    xp = xp_torch
    cos = staticmethod(torch.cos)
    sin = staticmethod(torch.sin)

    @staticmethod
    def sqrt(x: torch.Tensor) -> torch.Tensor:
        """``torch.sqrt``, bit for bit; under autograd its gradient at 0 (a force's size at no contact, where
        torch's is 0 times infinity: NaN) is 0, a subgradient of the norm it takes there."""
        return _flat_at_ends(torch.sqrt, x, lambda v: v > 0.0, 1.0)

    @staticmethod
    def exp(x: Any) -> Any:
        return torch.exp(x) if isinstance(x, torch.Tensor) else math.exp(x)      # a constant of the step: a float
    atan2 = staticmethod(torch.atan2)

    @staticmethod
    def asin(x: torch.Tensor) -> torch.Tensor:
        """``torch.asin``, bit for bit; under autograd its gradient at +-1 (a lateral anchor clipped to the
        tongue's edge, where torch's is 0 over 0: NaN) is 0, as the clip before it gives there."""
        return _flat_at_ends(torch.asin, x, lambda v: v.abs() < 1.0, 0.0)

    @staticmethod
    def positive(x: torch.Tensor) -> torch.Tensor:
        return torch.clamp(x, min=0.0)

    @staticmethod
    def clip(x: torch.Tensor, low: Any, high: Any) -> torch.Tensor:
        return torch.clamp(x, low, high)

    @staticmethod
    def where(condition: torch.Tensor, a: Any, b: Any) -> torch.Tensor:
        return torch.where(condition, a, b)

    @staticmethod
    def index(x: torch.Tensor, top: int) -> torch.Tensor:
        """``x`` (>= 0) truncated to a whole number, at most ``top`` (float64, see the module docstring)."""
        return torch.clamp(torch.trunc(x), max=top)

    @staticmethod
    def take(values: torch.Tensor, i: torch.Tensor) -> torch.Tensor:
        return values[i.to(torch.int64)]

    @staticmethod
    def stack(columns: list[torch.Tensor]) -> torch.Tensor:
        return torch.stack(columns, dim=-1)
