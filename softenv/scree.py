"""Rules for the number of principal components to keep.

All rules read the PCA spectrum: the covariance eigenvalues in descending order.

* ``"scree"`` -- Cattell's scree test as the paper applied it: a straight line is fitted to the
  bottom half of the eigenvalues (on a log scale, where a noise floor is a straight line); ``k`` is
  where the curve, coming down from the top, first meets that line (within three residual standard
  deviations of the fit, and at least 0.1 decade).
* ``"kneedle"`` -- Satopaa et al. (2011) on the raw eigenvalues: the point farthest below the chord
  joining the first and last eigenvalues.
* ``"noise"`` -- the noise-floor rule: keep eigenvalues above the largest eigenvalue pure white noise
  of standard deviation ``sigma`` would give, ``sigma^2 (1 + sqrt(p / (n - 1)))^2`` (Marchenko-Pastur
  edge); needs the noise level.
* a float in (0, 1) -- the smallest ``k`` explaining that fraction of the total variance.
* an int -- that many.

Eigenvalues below ``1e-12`` of the largest are floored there: that is the round-off level of the
Gram eigenvalues (about ``n eps lambda_max``), so they are numerical zeros. Noise-free data of rank
``D`` then gives a flat floor that the scree line fits exactly; noise below about ``1e-6`` of the
largest singular value is not told apart from zero.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._validation import check_int, check_real

RULES = ("scree", "kneedle", "noise")
_ZERO_FLOOR = 1e-12


def cattell_scree(eigenvalues: np.ndarray) -> int:
    """Cattell's scree test (the paper's rule): where the curve meets the line through the small eigenvalues."""
    lam = _clean(eigenvalues)
    n = lam.size
    if n < 4:
        return n
    y = np.log10(lam)
    tail = np.arange(n // 2, n)
    slope, intercept = np.polyfit(tail, y[tail], 1)
    line = slope * np.arange(n) + intercept
    tol = max(3.0 * float(np.std(y[tail] - line[tail])), 0.1)
    meets = np.flatnonzero(y <= line + tol)
    return max(int(meets[0]), 1) if meets.size else n


def kneedle(eigenvalues: np.ndarray) -> int:
    """Kneedle on the raw eigenvalues: index of the point farthest below the end-to-end chord."""
    lam = _clean(eigenvalues)
    n = lam.size
    if n < 3:
        return n
    x = np.linspace(0.0, 1.0, n)
    y = (lam - lam[-1]) / (lam[0] - lam[-1]) if lam[0] > lam[-1] else np.zeros(n)
    return max(int(np.argmax((1.0 - x) - y)), 1)


def noise_floor(eigenvalues: np.ndarray, noise_std: float, n_samples: int, n_features: int) -> int:
    """Number of eigenvalues above the white-noise edge ``sigma^2 (1 + sqrt(p / (n - 1)))^2``."""
    sigma = check_real(noise_std, "noise_std", 0.0, None, low_open=True)
    edge = sigma ** 2 * (1.0 + np.sqrt(n_features / (n_samples - 1))) ** 2
    return max(int(np.sum(np.asarray(eigenvalues) > edge)), 1)


def variance_fraction(eigenvalues: np.ndarray, fraction: float, total_variance: float | None = None) -> int:
    """Smallest ``k`` whose eigenvalues explain ``fraction`` of the total variance."""
    fraction = check_real(fraction, "fraction", 0.0, 1.0, low_open=True, high_open=True)
    lam = np.asarray(eigenvalues, dtype=float)
    total = float(lam.sum()) if total_variance is None else float(total_variance)
    k = int(np.searchsorted(np.cumsum(lam) / total, fraction) + 1)
    return min(k, lam.size)


def select_n_components(rule: Any, eigenvalues: np.ndarray, *, noise_std: float | None, n_samples: int,
                        n_features: int, total_variance: float | None = None) -> tuple[int, str, dict[str, int]]:
    """Apply ``rule``; return ``(k, rule name, {rule: k} for every rule that applies)`` for reporting."""
    lam = np.asarray(eigenvalues, dtype=float)
    picks = {"scree": cattell_scree(lam), "kneedle": kneedle(lam)}
    if noise_std is not None and noise_std > 0:
        picks["noise"] = noise_floor(lam, noise_std, n_samples, n_features)
    for frac in (0.9, 0.99, 0.999):
        picks[f"variance_{frac:g}"] = variance_fraction(lam, frac, total_variance)
    if isinstance(rule, str):
        if rule not in RULES:
            raise ValueError(f"n_components={rule!r} is not a rule; use one of {list(RULES)}, a fraction in (0, 1) or an int >= 1")
        if rule == "noise" and "noise" not in picks:
            raise ValueError("n_components='noise' needs noise_std (the white-noise standard deviation, m); got None")
        return picks[rule], rule, picks
    if isinstance(rule, (float, np.floating)) and not float(rule).is_integer():
        k = variance_fraction(lam, float(rule), total_variance)
        name = f"variance_{float(rule):g}"
        picks[name] = k
        return k, name, picks
    k = check_int(int(rule) if isinstance(rule, float) else rule, "n_components", 1)
    return k, "fixed", picks


def _clean(eigenvalues: np.ndarray) -> np.ndarray:
    lam = np.sort(np.asarray(eigenvalues, dtype=float))[::-1]
    if lam.size == 0 or lam[0] <= 0:
        raise ValueError("the spectrum has no positive eigenvalue: the data do not vary")
    return np.maximum(lam, lam[0] * _ZERO_FLOOR)
