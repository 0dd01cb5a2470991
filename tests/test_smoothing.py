"""Randomized smoothing (softenv/smoothing.py) against closed forms of Gaussian-smoothed functions, through the
differentiable twin, and bad settings refused by name."""

import json
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from scipy.stats import norm

import softenv  # noqa: F401  (registers the ids)
from softenv.smoothing import smoothed_gradient

ROOT = Path(__file__).resolve().parent.parent
X = torch.tensor([-0.3, 0.05, 0.4], dtype=torch.float64)
T = 0.2


def _absolute(points):
    return points.abs().sum(-1)


def _step(points):
    """A unit jump at 0 in each entry, flat elsewhere: its exact gradient is 0 everywhere it exists."""
    return torch.where(points > 0, 1.0, 0.0).sum(-1) + 0.0 * points.sum(-1)


@pytest.mark.parametrize("estimator", ["first-order", "zeroth-order"])
def test_the_smoothed_absolute_value_s_gradient_is_erf(estimator):
    """E|x + T e| has the gradient erf(x / (T sqrt 2)) = 2 Phi(x / T) - 1: both estimators reach it."""
    got = smoothed_gradient(_absolute, X, T, 4000, estimator, torch.Generator().manual_seed(0))
    truth = 2 * norm.cdf(X.numpy() / T) - 1
    stderr = got.gradient_stderr.numpy()
    assert np.all(stderr < 0.05)
    assert np.all(np.abs(got.gradient.numpy() - truth) < 4 * stderr), (got.gradient, truth, stderr)
    x = X.numpy()
    value = (T * np.sqrt(2 / np.pi) * np.exp(-x ** 2 / (2 * T * T)) + x * (1 - 2 * norm.cdf(-x / T))).sum()
    assert abs(got.value - value) < 4 * got.value_stderr


def test_across_a_jump_the_first_order_estimate_misses_it_and_the_zeroth_order_finds_the_density():
    """The smoothed step's gradient is the Gaussian's density phi(x / T) / T: the zeroth-order estimator
    finds it; the first-order one averages the exact slopes (0) and is biased by all of it."""
    truth = norm.pdf(X.numpy() / T) / T
    zeroth = smoothed_gradient(_step, X, T, 4000, "zeroth-order", torch.Generator().manual_seed(1))
    assert np.all(np.abs(zeroth.gradient.numpy() - truth) < 4 * zeroth.gradient_stderr.numpy())
    assert np.all(zeroth.gradient.numpy() > 4 * zeroth.gradient_stderr.numpy())     # told apart from 0
    first = smoothed_gradient(_step, X, T, 4000, "first-order", torch.Generator().manual_seed(1))
    assert torch.equal(first.gradient, torch.zeros(3, dtype=torch.float64))
    assert abs(first.value - norm.cdf(X.numpy() / T).sum()) < 4 * first.value_stderr


def _episode(env_id: str, steps: int, samples: int):
    """The summed shape error of plans ``tanh(z)`` ``(samples, steps, 4)`` from ``reset(seed=0)`` on the
    differentiable twin."""
    env = gym.make_vec(f"softenv:{env_id}", num_envs=samples, vectorization_mode="vector_entry_point",
                       backend="torch", differentiable=True, task={"horizon": steps})

    def objective(z):
        env.reset(seed=[0] * samples)
        return sum(env.step(torch.tanh(z[:, t]))[4]["shape_error_mm"] for t in range(steps))
    return objective


def test_at_temperature_0_it_is_the_exact_gradient_and_a_seeded_generator_repeats_it():
    z = torch.as_tensor(np.random.default_rng(0).uniform(-1, 1, (6, 4)))
    exact = z.clone().requires_grad_(True)
    _episode("SoftSphere-v0", 6, 1)(exact[None]).sum().backward()
    got = smoothed_gradient(_episode("SoftSphere-v0", 6, 1), z, 0.0, 1)
    assert torch.equal(got.gradient, exact.grad)        # the one sample is z itself
    runs = [smoothed_gradient(_episode("SoftSphere-v0", 6, 4), z, 0.1, 4, generator=torch.Generator().manual_seed(5))
            for _ in range(2)]
    assert torch.equal(runs[0].gradient, runs[1].gradient) and runs[0].value == runs[1].value
    assert not torch.equal(runs[0].gradient, exact.grad)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"temperature": -0.1}, r"temperature=-0.1: must be a finite number >= 0"),
    ({"temperature": float("nan")}, r"temperature=nan"),
    ({"samples": 0}, r"samples=0: must be an integer >= 1"),
    ({"samples": 3, "estimator": "zeroth-order"}, r"samples=3: must be an even integer >= 2"),
    ({"temperature": 0.0, "estimator": "zeroth-order"}, r"temperature=0: the zeroth-order estimator divides"),
    ({"estimator": "second-order"}, r"estimator='second-order': must be one of"),
    ({"x": torch.tensor([0.0, float("inf")])}, r"x: must be finite; 1 of its 2 entries"),
    ({"x": torch.tensor([1, 2])}, r"x: must be a floating-point torch tensor"),
    ({"objective": lambda p: p.sum()}, r"objective: must return a tensor of shape \(4,\)"),
    ({"objective": lambda p: p.sum(-1).detach()}, r"objective: its values carry no gradient"),
    ({"objective": lambda p: p.sum(-1) / 0.0}, r"objective: returned 4 non-finite values of 4"),
])
def test_bad_settings_are_refused_by_name(kwargs, match):
    settings = {"objective": _absolute, "x": X, "temperature": T, "samples": 4, "estimator": "first-order", **kwargs}
    with pytest.raises(ValueError, match=match):
        smoothed_gradient(**settings)


def test_the_bias_script_at_its_smallest_measures_a_bias_that_grows_with_the_temperature(tmp_path):
    """``scripts/smoothing_bias.py`` on the ideal device: J_T moves further from J at the larger temperature,
    the smoothed gradient keeps the exact one's direction, and both lead downhill."""
    done = subprocess.run([sys.executable, "scripts/smoothing_bias.py", "--out", str(tmp_path), "--cases",
                           "ideal, reach from no force", "--episodes", "1", "--samples", "4", "--line-samples", "8",
                           "--temperatures", "0.01", "0.3"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    episode = json.loads((tmp_path / "results.json").read_text())["cases"]["ideal, reach from no force"]["episodes"][0]
    low, high = episode["temperatures"]
    assert 0 <= low["bias"] < high["bias"]                       # a convex-looking J: noise raises it, more with T
    assert low["first_vs_exact_cosine"] > 0.99
    assert episode["exact_downhill"]["best_change"] < 0 and low["first_downhill"]["best_change"] < 0
    assert "| ideal, reach from no force | 0 | 0.3 |" in (tmp_path / "README.md").read_text()
