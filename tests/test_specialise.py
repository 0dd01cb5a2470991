"""The float kernels of softenv._specialise against the functions they are made from, run with ScalarOps."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from softenv._ops import ScalarOps
from softenv._specialise import scalar_kernel


def bits(values: Any) -> list[Any]:
    """Floats as their IEEE bit patterns (so -0.0 differs from 0.0 and NaN equals itself)."""
    return [struct.pack("<d", v) if isinstance(v, float) else v for v in values]


@dataclass
class Constants:
    scale: float
    top: int
    pair: tuple[float, float]


def lever(point: tuple, scale: float, c: Constants) -> tuple[Any, Any]:
    """A helper with a tuple parameter, a constant and a docstring."""
    x, y = point
    r = ScalarOps.sqrt(x * x + y * y)
    return r * c.scale + scale, c.pair[0] * x - c.pair[1] * y


def arithmetic(x: Any, y: Any, table: Any, c: Constants, ops: Any) -> tuple[Any, ...]:
    """Every op with a float form, nested, with repeated and compound arguments, and inlined helpers."""
    p = ops.positive(x - y)
    q = ops.clip(x * y, -c.scale, ops.positive(y) + 1.0)
    i = ops.index(ops.positive(x * c.scale), c.top)
    t = ops.take(table, i) + ops.take(table, ops.index(ops.positive(y) * c.scale, c.top))
    w = ops.where(x > y, ops.sqrt(ops.positive(x)), y - x)
    r, s = lever((x, y), p, c)
    u, v = lever((x + 1.0, q), w, c)
    flag = 1.0 if ops is ScalarOps else 0.0
    return p, q, i, t, w, r, s, u, v, flag


SPECIAL = [0.0, -0.0, 1.0, -1.0, 0.5, -2.5, 1e-310, -1e-310, 1e300, -1e300, math.inf, -math.inf, math.nan, 3.0, 7.5]


def test_kernel_returns_the_bits_of_scalar_ops_on_special_and_random_floats() -> None:
    c = Constants(scale=3.0, top=9, pair=(0.25, -1.5))
    table = [float(v) for v in np.linspace(-1.0, 1.0, 10)]
    kernel = scalar_kernel(arithmetic, c, helpers=(lever,))
    rng = np.random.default_rng(0)
    pairs = [(x, y) for x in SPECIAL for y in SPECIAL] + [tuple(v) for v in rng.normal(0, 4, (2000, 2)).tolist()]
    checked = 0
    for x, y in pairs:
        try:
            expected = arithmetic(x, y, table, c, ScalarOps)
        except (ValueError, OverflowError) as exc:          # int(nan), int(inf): the kernel raises alike
            with pytest.raises(type(exc)):
                kernel(x, y, table, c, ScalarOps)
            continue
        assert bits(kernel(x, y, table, c, ScalarOps)) == bits(expected), (x, y)
        checked += 1
    assert checked > 2000
    assert kernel(1.0, 0.0, table, c, ScalarOps)[-1] == 1.0          # `ops is ScalarOps` folded to True


def test_kernel_binds_the_constants_it_was_made_with() -> None:
    table = [0.0, 1.0, 2.0, 3.0]
    a = scalar_kernel(arithmetic, Constants(1.0, 3, (1.0, 0.0)), helpers=(lever,))
    b = scalar_kernel(arithmetic, Constants(2.0, 3, (0.0, 1.0)), helpers=(lever,))
    assert a(0.7, 0.2, table, None, None) == arithmetic(0.7, 0.2, table, Constants(1.0, 3, (1.0, 0.0)), ScalarOps)
    assert b(0.7, 0.2, table, None, None) == arithmetic(0.7, 0.2, table, Constants(2.0, 3, (0.0, 1.0)), ScalarOps)


CALLS: list[float] = []


def counted(v: float) -> float:
    CALLS.append(v)
    return v


def twice_read(x: Any, c: Any, ops: Any) -> Any:
    """Templates read their first argument twice or more."""
    return ops.positive(counted(x)) + ops.index(counted(x), c.top) + ops.clip(counted(x), 0.0, counted(x))


def test_each_argument_is_evaluated_once() -> None:
    kernel = scalar_kernel(twice_read, Constants(1.0, 5, (0.0, 0.0)))
    CALLS.clear()
    assert kernel(2.5, None, None) == twice_read(2.5, Constants(1.0, 5, (0.0, 0.0)), ScalarOps) == 7.0
    assert CALLS == [2.5] * 8                     # 4 calls each


def early_return(x: Any, c: Any, ops: Any) -> Any:
    if x > 0:
        return x
    return -x


def uses_early_return(x: Any, c: Any, ops: Any) -> Any:
    y = early_return(x, c, ops)
    return y


def assigns_parameter(x: Any, c: Any, ops: Any) -> Any:
    x = x + 1.0
    return x


def uses_assigns_parameter(x: Any, c: Any, ops: Any) -> Any:
    y = assigns_parameter(x, c, ops)
    return y


def uses_stack(x: Any, c: Any, ops: Any) -> Any:
    return ops.stack([x, x])


def enclosed() -> Any:
    k = 2.0

    def inner(x: Any, c: Any, ops: Any) -> Any:
        return x * k
    return inner


@pytest.mark.parametrize("fn, helpers, message", [
    (uses_early_return, (early_return,), "early_return only as .* with one return, its last statement"),
    (uses_assigns_parameter, (assigns_parameter,), "assigns_parameter: it assigns to its parameter x"),
    (uses_stack, (), "ops.stack has no float form"),
    (enclosed(), (), "not a plain function of its module"),
    (arithmetic, (ScalarOps.positive,), "not in arithmetic's module"),
])
def test_what_it_cannot_compile_is_refused_by_name(fn: Any, helpers: tuple, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        scalar_kernel(fn, Constants(1.0, 1, (0.0, 0.0)), helpers=helpers)


def test_without_source_the_function_itself_serves(monkeypatch: pytest.MonkeyPatch) -> None:
    import inspect

    import softenv._specialise as specialise

    def no_source(obj: Any) -> str:
        raise OSError("could not get source code")

    monkeypatch.setattr(inspect, "getsource", no_source)
    specialise._compile.cache_clear()
    try:
        assert scalar_kernel(arithmetic, Constants(1.0, 3, (0.0, 0.0)), helpers=(lever,)) is arithmetic
    finally:
        specialise._compile.cache_clear()
