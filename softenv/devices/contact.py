"""The blade-tongue contact law, consistent with the scene's tissue.

**Normal law.** The analytic tissue (``softenv.tissue``) indents the surface at the contact by
``W(P)`` under a normal load ``P``: linear (``W = c_n P``) or Fung-stiffening, then smoothly
saturated below 80 % of the radius. The contact law is its inverse: a blade that penetrates the
undeformed sphere by ``delta`` feels ``P(delta) = W^-1(delta)``. A press held with force ``F``
therefore settles at exactly the indentation that the response's shape for ``F`` has. ``P(delta)``
is tabulated once per scene on a uniform grid of ``delta`` (4,096 intervals, inverted from a dense
geometric grid of loads) and interpolated linearly; past the table's last node (``P`` at 1e5 times
the design force, or where saturation flattens ``W`` to the float resolution) it continues as a wall
(the last slope, at least ``wall_stiffness``). Lookups use only ``+ - * /`` and truncation, so the single env and the batched twin get
the same bits.

**Stiff-safe application.** Explicit penalty springs are stable only for ``K < 4 m / h^2``. The
substep ``h`` is chosen for the stiffness ``K_ref`` at the design force (or where saturation sets in,
if a soft tissue gets there first); the table's slope beyond it
(the saturation barrier makes it grow without bound) is applied linearly implicitly (backward Euler
along the contact normal with the blade's effective mass there, the other forces predicted by the
coupling's push), which is stable for any slope and exact at rest. The contact damper is explicit,
critical for ``K_ref`` (tissue is viscous; lighter damping let a blade pressed hard into a soft
tongue rock in a limit cycle), and kept below ``m_eff / h`` (half the stability limit ``2 m / h``).

**Lateral law (the sweep).** While in contact the tongue's surface sticks to the blade: the sideways
force is ``Q = k_t (y_blade - y_anchor)`` with the tissue's tangential stiffness
``k_t = 1 / c_t`` (``TissueParams.tangential_compliance``: the drag the response gives for ``Q``),
limited by Coulomb friction ``|Q| <= mu P``; past it the anchor slides. Off contact the anchor follows
the blade and ``Q = 0``. ``y_anchor`` is the lateral position of the loaded surface point at rest:
the response's ``lateral`` feature.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..geometry import SphereMesh
from ..tissue import DESIGN_INDENTATION, AnalyticTissue, TissueParams, effective_modulus

TABLE_INTERVALS = 4096
_LOAD_SPAN = (1e-7, 1e5)        # loads tabulated, as multiples of the design force and of the tissue's own scale
DEPTH_STEP = 1e-4      # the central difference's relative step in the stiffening depth (the tissue is smooth in it)


@dataclass(frozen=True, eq=False)
class ContactCurve:
    """The tissue's normal load-indentation curve at the top of the dorsum, rising from 0, and the
    tangential compliance there: all the contact law needs from a tissue model.

    Attributes:
        loads, depths: the curve's points (N, m), strictly rising; ``(0, 0)`` is implied.
        knee: the depth (m) past which the tissue gets stiffer without bound (the analytic tissue's
            saturation; the FE curve's last solve): the explicit stiffness is taken no deeper.
        lateral_compliance: drag of the loaded surface point per newton of sideways load (m/N).
        design_depth: the depth at the device's largest pressing force (m), computed by the tissue.
    """

    loads: np.ndarray
    depths: np.ndarray
    knee: float
    lateral_compliance: float
    design_depth: float


def analytic_curve(tissue: TissueParams, mesh: SphereMesh, design_force: float) -> ContactCurve:
    """The analytic tissue's curve, from well below to well above both the device's force and the
    tissue's own scale (the load indenting it by the design share of its radius), so a tissue far softer
    or stiffer than the device still gets its rising part; saturation's flat end is cut off."""
    analytic = AnalyticTissue(mesh, tissue)

    def indentation(loads: np.ndarray) -> np.ndarray:
        R, loads = tissue.radius, np.asarray(loads, dtype=np.float64)
        forces = np.zeros((loads.size, 3))
        forces[:, 2] = -loads
        return analytic.amplitudes(np.tile([0.0, 0.0, R], (loads.size, 1)), forces)["indentation"]

    own = tissue.E / effective_modulus(1.0, DESIGN_INDENTATION, tissue.nu, tissue.radius, tissue.patch_radius)
    low, high = min(design_force, own) * _LOAD_SPAN[0], max(design_force, own) * _LOAD_SPAN[1]
    loads = np.geomspace(low, high, 20_000)
    depth = indentation(loads)
    flat = np.flatnonzero(np.diff(depth) <= 0)
    if len(flat):
        loads, depth = loads[:flat[0] + 1], depth[:flat[0] + 1]
    knee = tissue.linear_fraction * tissue.max_indentation * tissue.radius
    return ContactCurve(loads, depth, knee, tissue.tangential_compliance, float(indentation(np.array([design_force]))[0]))


class TongueContact:
    """Normal law ``P(delta)`` (tabulated inverse of the tissue's indentation curve) and lateral stiffness.

    Args:
        curve: the scene's :class:`ContactCurve` (``Scene.contact_curve``).
        friction: Coulomb coefficient of the blade on the tongue (lateral sticking limit).
        wall_stiffness: least stiffness (N/m) of the law past its last node, where the saturated
            tissue is a wall: the device sets it 1,000 times its coupling stiffness, so no force the
            hand can exert pushes the blade more than a fraction of a millimetre beyond.
    """

    def __init__(self, curve: ContactCurve, friction: float, wall_stiffness: float = 0.0) -> None:
        self.curve = curve
        self.friction = friction
        loads, depth = np.concatenate([[0.0], curve.loads]), np.concatenate([[0.0], curve.depths])
        if len(loads) < 3 or not (np.all(np.diff(depth) > 0) and np.all(np.diff(loads) > 0)):
            raise ValueError("the tissue's indentation does not rise with the load; cannot invert it")
        self.step = float(depth[-1]) / TABLE_INTERVALS
        nodes = np.arange(TABLE_INTERVALS + 1) * self.step
        self.loads = np.interp(nodes, depth, loads)                     # P at each node (N)
        self.slopes = np.diff(self.loads) / self.step                   # N/m on each interval
        self.slopes[-1] = max(self.slopes[-1], wall_stiffness)          # the barrier past the table's end
        self.inv_step = 1.0 / self.step
        self.top = TABLE_INTERVALS - 1                                  # last interval index
        self.loads_list, self.slopes_list = self.loads[:-1].tolist(), self.slopes.tolist()
        # the explicit part: the stiffness at the design force, or where saturation sets in if sooner
        self.reference_stiffness = self.stiffness(min(curve.design_depth, 0.999 * curve.knee))
        self.lateral_stiffness = 1.0 / curve.lateral_compliance         # k_t, N/m

    def indentation(self, loads: np.ndarray) -> np.ndarray:
        """The curve's indentation (m) under normal loads ``P`` (N), interpolated linearly."""
        return np.interp(loads, np.concatenate([[0.0], self.curve.loads]), np.concatenate([[0.0], self.curve.depths]))

    def load(self, depth: np.ndarray) -> np.ndarray:
        """``P(delta)`` (N) for penetrations ``delta`` (m, any shape; 0 for ``delta <= 0``)."""
        d = np.asarray(depth, dtype=np.float64)
        i = np.minimum(np.maximum(d, 0.0) * self.inv_step, self.top).astype(np.int64)
        p = self.loads[i] + (d - i * self.step) * self.slopes[i]
        return np.where(d > 0.0, np.maximum(p, 0.0), 0.0)

    def stiffness(self, depth: float) -> float:
        """Slope ``dP/d delta`` (N/m) of the tabulated law at a penetration."""
        i = min(int(max(depth, 0.0) * self.inv_step), self.top)
        return float(self.slopes[i])

    def potential(self, depth: np.ndarray) -> np.ndarray:
        """Elastic energy ``int_0^delta P`` (J) stored at penetrations ``delta`` (exact for the table)."""
        d = np.maximum(np.asarray(depth, dtype=np.float64), 0.0)
        cumulative = np.concatenate([[0.0], np.cumsum((self.loads[:-1] + self.loads[1:]) * 0.5 * self.step)])
        i = np.minimum(d * self.inv_step, self.top).astype(np.int64)
        x = d - i * self.step
        return cumulative[i] + self.loads[i] * x + 0.5 * self.slopes[i] * x * x


def depth_derivative(contact: TongueContact, tissue: TissueParams, mesh: SphereMesh,
                     design_force: float) -> tuple[np.ndarray, np.ndarray]:
    """The analytic stiffening tongue's law ``contact`` in a factor ``q`` on the law's depth, at ``q = 1``:
    ``dP/dq`` at the law's nodes (N) and its slope on each interval (N/m), by central differences of the
    tissue's curve at ``q = 1 +- DEPTH_STEP`` read at the law's own nodes. Where a node lies past either
    curve's end (loads beyond 1e5 times the design force) the derivative holds its last value, and on the
    interval past the table the wall does not move with the depth."""
    nodes = np.arange(TABLE_INTERVALS + 1) * contact.step
    curves = [analytic_curve(replace(tissue, stiffening_depth=tissue.stiffening_depth * q), mesh, design_force)
              for q in (1 + DEPTH_STEP, 1 - DEPTH_STEP)]
    plus, minus = (np.interp(nodes, np.r_[0.0, c.depths], np.r_[0.0, c.loads]) for c in curves)
    loads = (plus - minus) / (2 * DEPTH_STEP)
    last = int(np.searchsorted(nodes, min(c.depths[-1] for c in curves), side="right")) - 1
    loads[last + 1:] = loads[last]
    slopes = np.diff(loads) / contact.step
    if contact.slopes[-1] != (contact.loads[-1] - contact.loads[-2]) / contact.step:     # the wall took the last slope
        slopes[-1] = 0.0
    return loads, slopes
