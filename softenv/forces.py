"""Force vectors: the numbers a device reports, and how they become a load on the tissue.

A *layout* names the columns of a force-vector array and converts rows into contact points and
force vectors for :class:`~softenv.tissue.AnalyticTissue`:

* :class:`PaperLayout` -- the paper's four numbers ``(x, y, z, F)``: contact point (m) and magnitude
  (N) of a force of fixed direction (default straight down, ``-z``: pressing on the dorsum).
* :class:`DorsumLayout` -- a laryngoscope blade on the dorsum: ``(insertion, lateral, normal, sideways)``.
  ``insertion`` is the arc length (m) along the midline from the front of the sphere (``+x``) over
  the top toward the back; ``lateral`` is the arc length (m) off the midline toward ``+y``; ``normal``
  (N, >= 0) presses into the surface; ``sideways`` (N) drags the surface toward ``+y``.

A :class:`Workspace` is a box over a layout's columns; :func:`sample_workspace` draws contact points
and loads from it (Latin hypercube or Sobol), grouped by contact point so that splits can hold out
whole contact points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ._validation import check_array, check_choice, check_int, check_real


class ForceLayout:
    """Base class: column names and units, conversion to ``(contacts, force_vectors)``."""

    name: ClassVar[str]
    feature_names: ClassVar[tuple[str, ...]]
    feature_units: ClassVar[tuple[str, ...]]

    @property
    def n_features(self) -> int:
        return len(self.feature_names)

    def to_loads(self, features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:
        raise NotImplementedError

    def check(self, features: Any, name: str = "forces") -> np.ndarray:
        """``features`` as a float64 ``(N, n_features)`` array, finite, else ``ValueError``."""
        return check_array(features, name, ndim=(1, 2), shape=(self.n_features,)).reshape(-1, self.n_features)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, ForceLayout) and self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(str(sorted(self.to_dict().items())))

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.to_dict().items() if k != "layout")
        return f"{type(self).__name__}({args})"


class PaperLayout(ForceLayout):
    """``(x, y, z, F)``: contact point on the sphere (m) and magnitude (N, >= 0) of a fixed-direction force."""

    name = "paper"
    feature_names = ("x", "y", "z", "F")
    feature_units = ("m", "m", "m", "N")

    def __init__(self, direction: tuple[float, float, float] = (0.0, 0.0, -1.0)) -> None:
        d = check_array(direction, "direction", ndim=1, shape=(3,))
        norm = float(np.linalg.norm(d))
        if norm == 0.0:
            raise ValueError("direction must be a non-zero 3-vector, got [0, 0, 0]")
        self.direction = tuple(float(v) for v in d / norm)

    def to_loads(self, features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        f = self.check(features)
        if (f[:, 3] < 0).any():
            i = int(np.argmax(f[:, 3] < 0))
            raise ValueError(f"forces[{i}, 3] (magnitude F) = {f[i, 3]:g} N is negative; allowed F >= 0")
        return f[:, :3].copy(), f[:, 3:4] * np.asarray(self.direction)

    def to_dict(self) -> dict[str, Any]:
        return {"layout": self.name, "direction": list(self.direction)}


class DorsumLayout(ForceLayout):
    """``(insertion, lateral, normal, sideways)`` of a blade on a sphere of ``radius`` (see module docstring)."""

    name = "dorsum"
    feature_names = ("insertion", "lateral", "normal", "sideways")
    feature_units = ("m", "m", "N", "N")

    def __init__(self, radius: float) -> None:
        self.radius = check_real(radius, "radius", 0.0, None, low_open=True)

    def contact_frame(self, insertion: np.ndarray, lateral: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unit outward normal ``n_c`` and unit sideways tangent ``e_lat`` at the contact points."""
        theta = np.asarray(insertion) / self.radius
        phi = np.asarray(lateral) / self.radius
        ct, st, cp, sp = np.cos(theta), np.sin(theta), np.cos(phi), np.sin(phi)
        normal = np.stack([cp * ct, sp, cp * st], axis=-1)
        sideways = np.stack([-sp * ct, cp, -sp * st], axis=-1)
        return normal, sideways

    def to_loads(self, features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        f = self.check(features)
        if (f[:, 2] < 0).any():
            i = int(np.argmax(f[:, 2] < 0))
            raise ValueError(f"forces[{i}, 2] (normal) = {f[i, 2]:g} N is negative; a blade only pushes: normal >= 0")
        limit = math.pi / 2 * self.radius
        if (np.abs(f[:, 1]) >= limit).any():
            i = int(np.argmax(np.abs(f[:, 1]) >= limit))
            raise ValueError(f"forces[{i}, 1] (lateral) = {f[i, 1]:g} m; allowed |lateral| < pi R / 2 = {limit:g} m")
        n_c, e_lat = self.contact_frame(f[:, 0], f[:, 1])
        return self.radius * n_c, -f[:, 2:3] * n_c + f[:, 3:4] * e_lat

    def to_dict(self) -> dict[str, Any]:
        return {"layout": self.name, "radius": self.radius}


def layout_from_dict(spec: dict[str, Any]) -> ForceLayout:
    """Rebuild a layout saved with ``to_dict()``."""
    kind = check_choice(spec.get("layout"), "layout", ("paper", "dorsum"))
    if kind == "paper":
        return PaperLayout(tuple(spec["direction"]))
    return DorsumLayout(spec["radius"])


@dataclass(frozen=True)
class Workspace:
    """An axis-aligned box over a layout's columns: ``low[i] <= forces[:, i] <= high[i]``.

    The first ``n_contact`` columns locate the contact (shared by all loads at one contact point);
    the rest are the load.
    """

    low: tuple[float, ...]
    high: tuple[float, ...]
    n_contact: int = 2

    def __post_init__(self) -> None:
        low = check_array(self.low, "low", ndim=1)
        high = check_array(self.high, "high", ndim=1, shape=(low.size,))
        if (high < low).any():
            i = int(np.argmax(high < low))
            raise ValueError(f"workspace high[{i}]={high[i]:g} is below low[{i}]={low[i]:g}")
        check_int(self.n_contact, "n_contact", 1, low.size)

    @property
    def n_features(self) -> int:
        return len(self.low)

    def scale(self, unit: np.ndarray) -> np.ndarray:
        """Map points of the unit box ``[0, 1]^d`` into the workspace."""
        low, high = np.asarray(self.low), np.asarray(self.high)
        return low + unit * (high - low)


def unit_samples(n: int, dims: int, method: str = "lhs", seed: int = 0) -> np.ndarray:
    """``n`` points in ``[0, 1)^dims``: Latin hypercube (numpy) or scrambled Sobol (needs scipy)."""
    n = check_int(n, "n", 1)
    dims = check_int(dims, "dims", 1)
    check_choice(method, "method", ("lhs", "sobol"))
    rng = np.random.default_rng(seed)
    if method == "lhs":
        strata = np.stack([rng.permutation(n) for _ in range(dims)], axis=1)
        return (strata + rng.random((n, dims))) / n
    try:
        from scipy.stats import qmc                         # scipy: the fem extra
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise ImportError("method='sobol' needs scipy: pip install 'softenv[fem]'") from exc
    return qmc.Sobol(dims, scramble=True, seed=rng).random(n)


def sample_workspace(workspace: Workspace, n_contacts: int, n_loads: int, method: str = "lhs",
                     seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Force vectors over ``workspace``: ``n_contacts`` contact points x ``n_loads`` loads each.

    Returns ``(forces (n_contacts * n_loads, d), contact_ids)``; contact points and loads are each
    space-filling (``method``) and independent, seeded by ``seed``.
    """
    c = workspace.n_contact
    d = workspace.n_features
    contact_unit = unit_samples(n_contacts, c, method, seed)
    load_unit = unit_samples(n_contacts * n_loads, d - c, method, seed + 1) if d > c else np.zeros((n_contacts * n_loads, 0))
    unit = np.concatenate([np.repeat(contact_unit, n_loads, axis=0), load_unit], axis=1)
    return workspace.scale(unit), np.repeat(np.arange(n_contacts), n_loads)
