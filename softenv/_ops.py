"""Elementwise operations for Python floats and for numpy arrays, with the same IEEE results.

Code written once against an ``ops`` argument runs on one env's state as Python floats (the
single env: no numpy call overhead on a handful of numbers) and on ``(N,)`` arrays (the batched
twin), and both agree bit for bit: every operation here is either correctly rounded (``+ - * /``,
``sqrt``, comparisons, min/max, truncation) or the same C library function (``cos``, ``sin``, ``atan2``, ``asin``: numpy's
float64 loops agree with ``math`` on the machines softenv runs on, which the single-versus-batched
tests check).
"""

from __future__ import annotations

import math
import operator
from typing import Any

import numpy as np


class ScalarOps:
    """Operations on Python floats (the single environment)."""

    sqrt = staticmethod(math.sqrt)
    cos = staticmethod(math.cos)
    sin = staticmethod(math.sin)
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


class ArrayOps:
    """The same operations on numpy arrays (the batched environment)."""

    sqrt = staticmethod(np.sqrt)
    cos = staticmethod(np.cos)
    sin = staticmethod(np.sin)
    atan2 = staticmethod(np.arctan2)
    asin = staticmethod(np.arcsin)

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
