"""softenv._ops: the array operations return the bits of the scalar ones (the single env's), element by
element, on this machine's CPU. On AVX-512 CPUs numpy's own arctan2 and arcsin differ from the C
library's in the last bit for about 1 value in 600, which broke the haptic twin's agreement with the
single env; this test finds such a difference among 20,000 values."""

import math

import numpy as np
import pytest
import torch

from softenv._ops import ArrayOps, ScalarOps
from softenv._torch_ops import TorchOps

RNG = np.random.default_rng(0)
X, Y = RNG.uniform(-4.0, 4.0, 20_000), RNG.uniform(-4.0, 4.0, 20_000)
U = RNG.uniform(-1.0, 1.0, 20_000)


@pytest.mark.parametrize("name, args", [("sqrt", (np.abs(X),)), ("cos", (X,)), ("sin", (X,)), ("atan2", (Y, X)),
                                        ("asin", (U,)), ("exp", (X,))])
def test_array_ops_equal_scalar_ops_bit_for_bit(name, args):
    batched = getattr(ArrayOps, name)(*args)
    one_by_one = np.array([getattr(ScalarOps, name)(*(float(a[i]) for a in args)) for i in range(len(args[0]))])
    assert batched.dtype == np.float64
    mismatches = np.flatnonzero(batched.view(np.uint64) != one_by_one.view(np.uint64))
    assert mismatches.size == 0, f"{name}: {mismatches.size} values differ, first at {[a[mismatches[0]] for a in args]}"


def test_elementwise_ops_broadcast_and_keep_shapes_and_nan():
    y = np.array([[1.0, -1.0, 0.0]])
    x = np.array([[2.0], [-3.0]])
    out = ArrayOps.atan2(y, x)
    assert out.shape == (2, 3)
    assert out[1, 1] == math.atan2(-1.0, -3.0)
    assert ArrayOps.atan2(0.5, 0.25).shape == ()
    assert np.isnan(ArrayOps.asin(np.array([np.nan, 0.5])))[0]
    assert ArrayOps.asin(np.empty(0)).shape == (0,)



@pytest.mark.parametrize("name, ends, inner, slope", [
    ("sqrt", [0.0], [0.25, 2.0], lambda x: 0.5 / np.sqrt(x)),
    ("asin", [-1.0, 1.0], [-0.5, 0.3], lambda x: 1.0 / np.sqrt(1.0 - x * x))])
def test_torch_ops_take_a_gradient_of_0_at_the_ends_of_their_domain(name, ends, inner, slope):
    """TorchOps.sqrt at 0 and TorchOps.asin at +-1 (where a clamp before them saturates): torch's values bit
    for bit, and under autograd a gradient of 0 there (torch's own is 0 times infinity: NaN); inside, the
    analytic slope."""
    x = torch.tensor(ends + inner, dtype=torch.float64, requires_grad=True)
    y = getattr(TorchOps, name)(x)
    assert torch.equal(y.detach(), getattr(torch, name)(x.detach()))
    y.sum().backward()
    assert torch.all(x.grad[:len(ends)] == 0)
    np.testing.assert_allclose(x.grad[len(ends):].numpy(), slope(np.array(inner)), rtol=1e-14)
