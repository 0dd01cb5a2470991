"""Elementwise operations for Python floats and for numpy arrays, with the same IEEE results.

Code written once against an ``ops`` argument runs on one env's state as Python floats (the
single env: no numpy call overhead on a handful of numbers) and on ``(N,)`` arrays (the batched
twin), and both agree bit for bit: every operation here is either correctly rounded (``+ - * /``,
``sqrt``, comparisons, min/max, truncation) or the C library's function. numpy's float64 ``cos`` and
``sin`` agree with ``math``'s on the machines softenv runs on (tests/test_ops.py checks). Its
``arctan2`` and ``arcsin`` do not on AVX-512 CPUs, where numpy uses its own vector code (SVML): they
differ from the C library in the last bit for about 1 value in 600. So :class:`ArrayOps` computes those
two element by element with ``math``; they run once per control step, not per substep.
"""

from __future__ import annotations

import math
import operator
from typing import Any, Protocol

import numpy as np


class Ops(Protocol):
    """The elementwise operations the task's formulas use (:mod:`softenv.envs.task`), on any numbers:
    :class:`ScalarOps` (Python floats), :class:`ArrayOps` (numpy), the torch twin's ``TorchOps``.
    Implemented by classes of static methods; the class itself is the ``ops`` argument."""

    def sqrt(self, x: Any, /) -> Any: ...

    def positive(self, x: Any, /) -> Any: ...

    def clip(self, x: Any, low: Any, high: Any, /) -> Any: ...

    def stack(self, columns: list[Any], /) -> Any: ...


class PhysicsOps(Ops, Protocol):
    """:class:`Ops` and what the laryngoscope's contact arithmetic needs besides
    (:mod:`softenv.devices.laryngoscope.physics`): Python floats and numpy."""

    def cos(self, x: Any, /) -> Any: ...

    def sin(self, x: Any, /) -> Any: ...

    def exp(self, x: Any, /) -> Any: ...

    def atan2(self, y: Any, x: Any, /) -> Any: ...

    def asin(self, x: Any, /) -> Any: ...

    def where(self, condition: Any, a: Any, b: Any, /) -> Any: ...

    def index(self, x: Any, top: int, /) -> Any: ...

    def take(self, values: Any, i: Any, /) -> Any: ...


class ScalarOps:
    """Operations on Python floats (the single environment)."""

    sqrt = staticmethod(math.sqrt)
    cos = staticmethod(math.cos)
    sin = staticmethod(math.sin)
    exp = staticmethod(math.exp)
    atan2 = staticmethod(math.atan2)
    asin = staticmethod(math.asin)

    @staticmethod
    def positive(x: float) -> float:
        return x if x > 0.0 else 0.0

    @staticmethod
    def clip(x: float, low: float, high: float) -> float:
        return low if x < low else (high if x > high else x)

    @staticmethod
    def where(condition: bool, a: float, b: float) -> float:
        return a if condition else b

    @staticmethod
    def index(x: float, top: int) -> int:
        """``x`` (>= 0) truncated to an int, at most ``top``."""
        return int(x) if x < top else top

    take = staticmethod(operator.getitem)          # values[i], without a Python frame

    @staticmethod
    def stack(columns: list[float]) -> list[float]:
        """The columns of one row: the values themselves."""
        return list(columns)


class ArrayOps:
    """The same operations on numpy arrays (the batched environment)."""

    sqrt = staticmethod(np.sqrt)
    cos = staticmethod(np.cos)
    sin = staticmethod(np.sin)

    @staticmethod
    def exp(x: Any) -> np.ndarray:
        # numpy's own exp differs from the C library's in the last bit on CPUs with AVX512_ICL (numpy 2.4)
        return _elementwise(math.exp, x)

    @staticmethod
    def atan2(y: Any, x: Any) -> np.ndarray:
        return _elementwise(math.atan2, y, x)

    @staticmethod
    def asin(x: Any) -> np.ndarray:
        return _elementwise(math.asin, x)

    @staticmethod
    def positive(x: np.ndarray) -> np.ndarray:
        return np.maximum(x, 0.0)

    @staticmethod
    def clip(x: np.ndarray, low: Any, high: Any) -> np.ndarray:
        return np.minimum(np.maximum(x, low), high)

    @staticmethod
    def where(condition: np.ndarray, a: Any, b: Any) -> np.ndarray:
        return np.where(condition, a, b)

    @staticmethod
    def index(x: np.ndarray, top: int) -> np.ndarray:
        return np.minimum(x, top).astype(np.int64)

    @staticmethod
    def take(values: np.ndarray, i: np.ndarray) -> np.ndarray:
        return values[i]

    @staticmethod
    def stack(columns: list[np.ndarray]) -> np.ndarray:
        """Columns of equal shape stacked on a new last axis."""
        return np.stack(columns, axis=-1)


def _elementwise(function: Any, *arrays: Any) -> np.ndarray:
    """``function`` (a ``math`` function) of broadcast float64 arrays, element by element."""
    columns = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in arrays))
    shape = columns[0].shape
    values = map(function, *(c.ravel().tolist() for c in columns))
    return np.fromiter(values, np.float64, count=columns[0].size).reshape(shape)
