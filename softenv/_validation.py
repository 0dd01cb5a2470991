"""Argument checks shared by the whole package.

Every check raises ``ValueError`` with a message that names the argument, shows the offending value
and says what is allowed, so that bad input never travels further than the public call that got it.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np


def _show(value: Any) -> str:
    """A short, readable rendering of a value for error messages."""
    if isinstance(value, np.ndarray):
        if value.size <= 6:
            return np.array2string(value, precision=6, separator=", ")
        return f"array of shape {value.shape} and dtype {value.dtype}"
    return repr(value)


def printable(text: str) -> str:
    """``text`` with the bytes of file names that are not UTF-8 (surrogates, as Python reads them from the
    command line) shown as ``\\xff`` escapes, so that printing, writing or drawing it never fails."""
    try:
        return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    except UnicodeEncodeError:                        # lone surrogates of another origin
        return text.encode("utf-8", "backslashreplace").decode("utf-8")


def check_real(value: Any, name: str, low: float | None = None, high: float | None = None,
               *, low_open: bool = False, high_open: bool = False) -> float:
    """A finite real number inside ``[low, high]`` (ends open where asked); returned as float."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name} must be a real number, got {_show(value)}")
    lo = "-inf" if low is None else f"{low:g}"
    hi = "inf" if high is None else f"{high:g}"
    allowed = f"{'(' if low_open or low is None else '['}{lo}, {hi}{')' if high_open or high is None else ']'}"
    try:
        x = float(value)
    except OverflowError:                    # an int beyond any float, e.g. 10**400
        digits = len(str(abs(int(value)))) - 1
        raise ValueError(f"{name}={'-' if value < 0 else ''}1e+{digits} (about) is out of range; allowed range "
                         f"{allowed}") from None
    if not math.isfinite(x):
        raise ValueError(f"{name} must be finite, got {x!r}; allowed range {allowed}")
    if low is not None and (x < low or (low_open and x == low)):
        raise ValueError(f"{name}={x:g} is out of range; allowed range {allowed}")
    if high is not None and (x > high or (high_open and x == high)):
        raise ValueError(f"{name}={x:g} is out of range; allowed range {allowed}")
    return x


def check_int(value: Any, name: str, low: int | None = None, high: int | None = None) -> int:
    """An integer inside ``[low, high]``; returned as int."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer, got {_show(value)}")
    x = int(value)
    if (low is not None and x < low) or (high is not None and x > high):
        lo = "-inf" if low is None else str(low)
        hi = "inf" if high is None else str(high)
        raise ValueError(f"{name}={x} is out of range; allowed range [{lo}, {hi}]")
    return x


def check_choice(value: Any, name: str, choices: Sequence[Any]) -> Any:
    """One of ``choices``."""
    if value not in choices:
        raise ValueError(f"{name}={value!r} is not allowed; choose one of {list(choices)}")
    return value


def check_array(value: Any, name: str, *, ndim: int | tuple[int, ...] | None = None,
                shape: tuple[int | None, ...] | None = None, dtype: Any = np.float64,
                finite: bool = True, copy: bool = False) -> np.ndarray:
    """A numeric array of the given rank/shape, converted to ``dtype``, optionally all finite.

    ``shape`` may hold ``None`` for free axes and is matched against the trailing axes when
    ``ndim`` allows more than one rank. Strings, objects and complex numbers are refused rather
    than cast.
    """
    arr = value if type(value) is np.ndarray else np.asarray(value)
    if arr.dtype.kind not in "biuf":
        raise ValueError(f"{name} must be a real numeric array, got {_show(value)} (dtype {arr.dtype})")
    if ndim is not None:
        ranks = (ndim,) if isinstance(ndim, int) else ndim
        if arr.ndim not in ranks:
            raise ValueError(f"{name} must have {' or '.join(map(str, ranks))} dimension(s), "
                             f"got shape {arr.shape}")
    if shape is not None:
        tail = arr.shape[arr.ndim - len(shape):] if arr.ndim >= len(shape) else None
        if tail is None or any(s is not None and s != t for s, t in zip(shape, tail)):
            want = "(" + ", ".join("any" if s is None else str(s) for s in shape) + ")"
            raise ValueError(f"{name} must have trailing shape {want}, got shape {arr.shape}")
    out = np.array(arr, dtype=dtype, copy=True) if copy else (arr if arr.dtype == dtype else arr.astype(dtype))
    if finite and not (out.size < 4096 and np.isfinite(out).all()):  # small arrays: one cheap check
        check_finite(out, name)
    return out


def real_array(value: Any, name: str, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` as an array of exactly ``shape`` with a real numeric dtype (int, uint or float; returned
    as given, not converted): the one rule for actions and targets. Strings (numeric ones included),
    bools, complex numbers, dicts and other objects are refused, never cast."""
    try:
        arr = value if type(value) is np.ndarray else np.asarray(value)
    except (TypeError, ValueError) as exc:     # ragged nesting and the like
        raise ValueError(f"{name} must be a real numeric array of shape {shape}, got {_show(value)} ({exc})") from None
    if arr.dtype.kind not in "iuf":
        raise ValueError(f"{name} must be a real numeric array of shape {shape}, got {_show(value)} (dtype {arr.dtype})")
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got shape {arr.shape}")
    return arr


def check_finite(arr: np.ndarray, name: str) -> None:
    """Raise if any entry is NaN or infinite, naming the first bad index and value.

    Large arrays are checked in blocks of rows, so the check needs little memory of its own.
    """
    step = max(1, (1 << 22) // max(1, arr[0].size)) if arr.ndim >= 2 else max(1, arr.shape[0] if arr.ndim else 1)
    for start in range(0, arr.shape[0] if arr.ndim else 1, step):
        block = arr[start:start + step] if arr.ndim else arr
        if not np.isfinite(block).all():
            bad = np.argwhere(~np.isfinite(block))[0]
            index = (int(bad[0]) + start, *map(int, bad[1:])) if arr.ndim else ()
            raise ValueError(f"{name} must be finite; found {float(arr[index])!r} at index {index} "
                             f"(array of shape {arr.shape})")
