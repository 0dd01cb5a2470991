"""The blade against the upper incisors as Chipmunk collides and solves them, on numpy arrays (``n`` devices).

The second piece of the laryngoscope on arrays (issue 37, after :mod:`.rigid`): Chipmunk's
``SegmentToPoly`` for the incisors (a static rounded segment) and the blade (a convex polygon without
radius), without its iterative search. Chipmunk finds the edge of the Minkowski difference
``blade - incisors`` nearest the origin: by GJK while the two cores are apart (the blade less than the
incisors' 4 mm radius into them), where that edge is the nearest of the difference's candidate edges
(each vertex of one shape against each edge of the other); by EPA once the cores overlap (a fast blade
sinks deeper in one substep), where it is the nearest edge of the difference's hull. Every candidate is
measured at once and the nearest taken, among the hull's edges alone when the origin lies inside it. Its
closest points, normal and distance, then the contact points clipped from the two support edges, follow
Chipmunk's expressions (``ClosestPointsNew``, ``SupportEdgeFor*``, ``ContactPoints``), so the same IEEE
operations run in the same order (``tests/test_laryngoscope_arrays.py`` holds them to Chipmunk's
``cpShapesCollide``, bit for bit, apart and sunk).

The contact's solver follows ``cpArbiter``: each device's arbiter (:class:`Arbiters`) keeps its
contacts' accumulated impulses from step to step, matched by the features they join, and outlives its
last contact by :data:`PERSISTENCE` steps; :func:`prestep`, :func:`apply_cached` and
:func:`apply_impulse` are ``cpArbiterPreStep``, ``ApplyCachedImpulse`` and ``ApplyImpulse`` with
Chipmunk's sequential impulses, friction cone and position-correcting bias velocity.
:func:`~.rigid.coupling_step` runs them in Chipmunk's order.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

TINY = np.finfo(np.float64).tiny         # CPFLOAT_MIN, which Chipmunk adds to keep divisions finite


def polygon_planes(outline: Any) -> tuple[np.ndarray, np.ndarray]:
    """The blade's vertices ``(V, 2)`` (body frame, pymunk's order) and each vertex's plane normal: that
    of the edge ending there (``cpPolyShape``'s ``planes``)."""
    v = np.asarray(outline, dtype=np.float64)
    edge = v - np.roll(v, 1, axis=0)
    rperp = np.stack([edge[:, 1], -edge[:, 0]], axis=1)
    length = np.sqrt(rperp[:, 0] * rperp[:, 0] + rperp[:, 1] * rperp[:, 1])
    return v, rperp * (1.0 / (length + TINY))[:, None]


def transformed(local: Any, x: Any, y: Any, cos_a: Any, sin_a: Any, xp: Any = np, offset: bool = True) -> Any:
    """``local`` ``(V, 2)`` points (or, without ``offset``, vectors) in the world frame of ``n`` bodies:
    ``(n, V, 2)``, as ``cpTransformPoint`` / ``cpTransformVect`` compute them."""
    lx, ly = local[None, :, 0], local[None, :, 1]
    c, s = cos_a[:, None], sin_a[:, None]
    wx, wy = c * lx + -s * ly, s * lx + c * ly
    if offset:
        wx, wy = wx + x[:, None], wy + y[:, None]
    return xp.stack([wx, wy], axis=-1)


def _dot(a: Any, b: Any) -> Any:
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def _cross(a: Any, b: Any) -> Any:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _lerp_t(a: Any, b: Any, t: Any) -> Any:
    ht = (0.5 * t)[..., None]
    return a * (0.5 - ht) + b * (0.5 + ht)


def _closest_t(a: Any, b: Any, xp: Any) -> Any:
    delta = b - a
    d2 = _dot(delta, delta)
    nonzero = d2 != 0.0
    # where d2 is 0 the quotient is discarded: dividing by 1 there instead keeps 0/0 out, same bits elsewhere
    t = -xp.clip(_dot(delta, a + b) / xp.where(nonzero, d2, 1.0), -1.0, 1.0)
    return xp.where(nonzero, t, 0.0)


def _pick(x: Any, rows: Any, i: Any) -> Any:
    return x[rows, i]


def collide(s: Solver, vertices: Any, normals: Any, xp: Any) -> tuple[Any, Any, Any, Any, Any]:
    """The contacts of the solver's static segment (``s.ends``, radius ``s.radius``) with ``n`` polygons
    (world ``vertices`` and plane ``normals``, ``(n, V, 2)``, arrays of the namespace ``xp``). Returns the
    normal ``(n, 2)`` (from the segment toward the blade), the contact points on the segment's surface
    and on the blade ``(n, 2, 2)`` each, which of the (at most two) contacts exist ``(n, 2)``, and the
    features each joins ``(n, 2, 2)``: the segment's end and the blade's vertex (Chipmunk's contact hash,
    by which a contact keeps its impulses from one step to the next)."""
    n_dev, count = vertices.shape[:2]
    ends, radius = s.ends, s.radius
    ia, ja, ib, jb = s.candidates
    # the Minkowski points blade vertex j - segment end i: (n, 2, V, 2)
    ab = vertices[:, None, :, :] - ends[None, :, None, :]
    # candidate edges: each segment end against each blade edge (j, j + 1), each blade vertex against the segment
    v0 = xp.concat([xp.reshape(ab, (n_dev, 2 * count, 2)), ab[:, 0]], axis=1)
    v1 = xp.concat([xp.reshape(xp.roll(ab, -1, axis=2), (n_dev, 2 * count, 2)), ab[:, 1]], axis=1)
    t_all = _closest_t(v0, v1, xp)
    p_all = _lerp_t(v0, v1, t_all)
    left, inside = _hull_sides(v0, v1, xp.reshape(ab, (n_dev, 2 * count, 2)), xp)
    # apart, the nearest candidate is where GJK ends; sunk deeper than the radius (the cores overlap, the
    # origin inside the difference), EPA ends on the nearest edge of the hull: candidates inside it are out
    dist = _dot(p_all, p_all)
    best = xp.argmin(xp.where(inside[:, None] & (left == 0), xp.inf, dist), axis=1)      # the first of equals
    rows = xp.arange(n_dev, device=vertices.device)
    # either way the edge is oriented with the hull on its inner side (rperp points into it): d > 0 apart,
    # d < 0 sunk
    e0, e1 = _pick(v0, rows, best), _pick(v1, rows, best)
    delta = e1 - e0
    outward = _dot(xp.stack([delta[:, 1], -delta[:, 0]], axis=1), _pick(p_all, rows, best)) < 0.0
    flip = xp.where(inside, _pick(left, rows, best) == 1, outward)
    m0 = ab[rows, xp.where(flip, ib[best], ia[best]), xp.where(flip, jb[best], ja[best])]
    m1 = ab[rows, xp.where(flip, ia[best], ib[best]), xp.where(flip, ja[best], jb[best])]
    # ClosestPointsNew
    t = _closest_t(m0, m1, xp)
    p = _lerp_t(m0, m1, t)
    d_ab = m1 - m0
    rp = xp.stack([d_ab[:, 1], -d_ab[:, 0]], axis=1)
    normal = rp * (1.0 / (xp.sqrt(_dot(rp, rp)) + TINY))[:, None]
    d = _dot(normal, p)
    vertex_pair = ~((d <= 0.0) | ((-1.0 < t) & (t < 1.0)))
    d2 = xp.sqrt(_dot(p, p))
    normal = xp.where(vertex_pair[:, None], p * (1.0 / (d2 + TINY))[:, None], normal)
    d = xp.where(vertex_pair, d2, d)
    # SupportEdgeForSegment(seg, n) and SupportEdgeForPoly(poly, -n)
    forward = _dot(s.seg_normal[None], normal) > 0.0
    s_a = xp.where(forward[:, None], ends[0], ends[1])
    s_b = xp.where(forward[:, None], ends[1], ends[0])
    back = -normal
    i1p = xp.argmax(_dot(vertices, back[:, None, :]), axis=1)
    i0p, i2p = (i1p - 1 + count) % count, (i1p + 1) % count
    keep = _dot(back, _pick(normals, rows, i1p)) > _dot(back, _pick(normals, rows, i2p))
    q_a = xp.where(keep[:, None], _pick(vertices, rows, i0p), _pick(vertices, rows, i1p))
    q_b = xp.where(keep[:, None], _pick(vertices, rows, i1p), _pick(vertices, rows, i2p))
    # ContactPoints (the blade has no radius: its offset is n * -0.0)
    touching = (d - radius) - 0.0 <= 0.0
    touching &= d <= radius + 0.0
    d1a, d1b, d2a, d2b = _cross(s_a, normal), _cross(s_b, normal), _cross(q_a, normal), _cross(q_b, normal)
    e1_denom = 1.0 / (d1b - d1a + TINY)
    e2_denom = 1.0 / (d2b - d2a + TINY)
    zero, one = xp.zeros_like(i1p), xp.ones_like(i1p)
    seg_a, seg_b = xp.where(forward, zero, one), xp.where(forward, one, zero)
    blade_a, blade_b = xp.where(keep, i0p, i1p), xp.where(keep, i1p, i2p)
    features = xp.stack([xp.stack([seg_a, blade_b], axis=1), xp.stack([seg_b, blade_a], axis=1)], axis=1)
    points_a, points_b, exists = [], [], []
    for first, second in ((d2b - d1a, d1a - d2a), (d2a - d1a, d1b - d2a)):
        u = xp.clip(first * e1_denom, 0.0, 1.0)[:, None]
        v = xp.clip(second * e2_denom, 0.0, 1.0)[:, None]
        p1 = normal * radius + (s_a * (1.0 - u) + s_b * u)
        p2 = normal * -0.0 + (q_a * (1.0 - v) + q_b * v)
        points_a.append(p1)
        points_b.append(p2)
        exists.append(touching & (_dot(p2 - p1, normal) <= 0.0))
    return normal, xp.stack(points_a, axis=1), xp.stack(points_b, axis=1), xp.stack(exists, axis=1), features


def _hull_sides(v0: Any, v1: Any, points: Any, xp: Any) -> tuple[Any, Any]:
    """For each candidate edge ``v0 -> v1`` ``(n, E, 2)`` of the difference whose points are ``points``
    ``(n, P, 2)``: which side of it they all lie on (1 left, -1 right, 0 both: not a hull edge), and for
    each device whether the origin lies strictly inside the hull (the cores overlap)."""
    edge = v1 - v0
    side = _cross(edge[:, :, None, :], points[:, None, :, :] - v0[:, :, None, :])
    left = xp.where(xp.all(side >= 0.0, axis=2), 1, xp.where(xp.all(side <= 0.0, axis=2), -1, 0))
    origin = _cross(edge, -v0)
    inner = ((left == 1) & (origin > 0.0)) | ((left == -1) & (origin < 0.0)) | (left == 0)
    return left, xp.all(inner, axis=1)


def segment_normal(ends: np.ndarray) -> np.ndarray:
    """``cpSegmentShape``'s normal: ``rperp`` of the unit direction from ``a`` to ``b``."""
    delta = ends[1] - ends[0]
    unit = delta * (1.0 / (np.sqrt(_dot(delta, delta)) + TINY))
    return np.array([unit[1], -unit[0]])


PERSISTENCE = 3                          # pymunk's collision_persistence: steps an arbiter outlives its contact


@dataclass
class Arbiters:
    """Each device's arbiter with the incisors, as Chipmunk keeps it between steps: whether it exists
    (``alive``), the steps since it last had contacts (``ticks``), and its contacts (at most two
    slots: ``exists``, the features they join, ``features`` (segment end, blade vertex), and their
    accumulated normal and tangent impulses ``jn``, ``jt``). Within a step: whether this is its first
    collision (no cached impulse), the normal and each contact's offsets, masses, bias and bias impulse.
    Arrays of one namespace (numpy, or torch through ``array_api_compat``)."""

    alive: Any
    ticks: Any
    exists: Any
    features: Any
    jn: Any
    jt: Any
    first: Any = None
    normal: Any = None
    r2: Any = None
    n_mass: Any = None
    t_mass: Any = None
    bias: Any = None
    j_bias: Any = None

    @classmethod
    def none(cls, n: int, xp: Any = np, device: Any = "cpu") -> Arbiters:
        # a normal from the start (read, masked, by devices without contact), so no step branches on its absence
        return cls(xp.zeros(n, dtype=xp.bool, device=device), xp.zeros(n, dtype=xp.int64, device=device),
                   xp.zeros((n, 2), dtype=xp.bool, device=device),
                   xp.full((n, 2, 2), -1, dtype=xp.int64, device=device),
                   xp.zeros((n, 2), dtype=xp.float64, device=device), xp.zeros((n, 2), dtype=xp.float64, device=device),
                   normal=xp.zeros((n, 2), dtype=xp.float64, device=device))

    def drop(self, mask: Any, xp: Any) -> None:
        """Drop the masked devices' arbiters (as the pymunk space's flush does)."""
        self.alive = xp.where(mask, False, self.alive)
        self.ticks = xp.where(mask, 0, self.ticks)
        self.exists = xp.where(mask[:, None], False, self.exists)
        self.features = xp.where(mask[:, None, None], -1, self.features)
        self.jn = xp.where(mask[:, None], 0.0, self.jn)
        self.jt = xp.where(mask[:, None], 0.0, self.jt)


@dataclass(frozen=True)
class Solver:
    """The contact's constants: the segment (``ends``, its normal) and its radius, the blade's polygon,
    inverse mass and moment, the friction (the product of the shapes'), the step, the space's slop and
    bias; and the candidate edges' indices :func:`collide` measures (constant arrays of the batch's
    namespace, made once by :meth:`of`)."""

    segment: tuple[tuple[float, float], tuple[float, float]]
    radius: float
    local: Any
    local_normals: Any
    m_inv: float
    i_inv: float
    friction: float
    h: float
    slop: float
    bias_coef: float
    ends: Any
    seg_normal: Any
    candidates: tuple[Any, Any, Any, Any]

    @classmethod
    def of(cls, segment: tuple[tuple[float, float], tuple[float, float]], radius: float, outline: Any,
           m_inv: float, i_inv: float, friction: float, h: float, slop: float, bias_coef: float,
           asarray: Any = np.asarray) -> Solver:
        """The solver with its arrays made by ``asarray`` (numpy's, or one onto a torch device)."""
        local, local_normals = polygon_planes(outline)
        count = len(local)
        ends = np.array(segment, dtype=np.float64)
        # v0 of each candidate: (segment end, blade vertex); v1 the next point of its edge
        ia = np.concatenate([np.repeat([0, 1], count), np.zeros(count, dtype=np.int64)])
        ja = np.concatenate([np.tile(np.arange(count), 2), np.arange(count)])
        ib = np.concatenate([np.repeat([0, 1], count), np.ones(count, dtype=np.int64)])
        jb = np.concatenate([np.tile((np.arange(count) + 1) % count, 2), np.arange(count)])
        return cls(segment, radius, asarray(local), asarray(local_normals), m_inv, i_inv, friction, h, slop,
                   bias_coef, asarray(ends), asarray(segment_normal(ends)),
                   (asarray(ia), asarray(ja), asarray(ib), asarray(jb)))


def _max0(x: Any, xp: Any) -> Any:
    return xp.where(x > 0.0, x, 0.0)                  # cpfmax(x, 0): 0.0, never -0.0


def rotate(n: Any, jn: Any, jt: Any) -> tuple[Any, Any]:
    return n[:, 0] * jn - n[:, 1] * jt, n[:, 0] * jt + n[:, 1] * jn


def prestep(arb: Arbiters, s: Solver, px: Any, py: Any, cos_a: Any, sin_a: Any, xp: Any) -> Any:
    """Collide, update each device's arbiter (cpArbiterUpdate, the cache's filter) and pre-step its
    contacts (cpArbiterPreStep) at the blade's new pose.
    Returns which devices touch the incisors this step."""
    vertices = transformed(s.local, px, py, cos_a, sin_a, xp)
    normals = transformed(s.local_normals, px, py, cos_a, sin_a, xp, offset=False)
    normal, on_segment, on_blade, exists, features = collide(s, vertices, normals, xp)
    touching = xp.any(exists, axis=1)
    jn, jt = xp.zeros_like(arb.jn), xp.zeros_like(arb.jt)
    for new in range(2):
        for old in range(2):
            same = arb.alive & arb.exists[:, old] & xp.all(features[:, new] == arb.features[:, old], axis=1)
            jn[:, new] = xp.where(same, arb.jn[:, old], jn[:, new])
            jt[:, new] = xp.where(same, arb.jt[:, old], jt[:, new])
    arb.first = touching & ~(arb.alive & (arb.ticks == 0))
    ticks = xp.where(touching, 0, arb.ticks + 1)
    arb.alive = touching | (arb.alive & (ticks < PERSISTENCE))
    arb.ticks = ticks
    kept = touching[:, None]
    arb.exists = xp.where(kept, exists, arb.exists)
    arb.features = xp.where(kept[..., None], features, arb.features)
    arb.jn, arb.jt = xp.where(kept, jn, arb.jn), xp.where(kept, jt, arb.jt)
    arb.normal = xp.where(kept, normal, arb.normal)
    n = arb.normal
    r1 = on_segment - 0.0                                # the static body sits at the origin
    r2 = on_blade - xp.stack([px, py], axis=1)[:, None, :]
    arb.r2 = r2
    rcn = r2[..., 0] * n[:, None, 1] - r2[..., 1] * n[:, None, 0]
    arb.n_mass = 1.0 / (0.0 + (s.m_inv + s.i_inv * rcn * rcn))
    rct = r2[..., 0] * n[:, None, 0] - r2[..., 1] * -n[:, None, 1]
    arb.t_mass = 1.0 / (0.0 + (s.m_inv + s.i_inv * rct * rct))
    dx, dy = (r2[..., 0] - r1[..., 0]) + px[:, None], (r2[..., 1] - r1[..., 1]) + py[:, None]
    dist = dx * n[:, None, 0] + dy * n[:, None, 1]
    low = dist + s.slop
    arb.bias = -s.bias_coef * xp.where(0.0 < low, 0.0, low) / s.h
    arb.j_bias = xp.zeros_like(arb.bias)
    return touching


def apply_cached(arb: Arbiters, touching: Any, s: Solver, dt_coef: float, vx: Any, vy: Any, w: Any,
                 xp: Any) -> tuple[Any, Any, Any]:
    """cpArbiterApplyCachedImpulse: the contacts' impulses of the last step again (not on a first collision)."""
    assert arb.normal is not None and arb.r2 is not None and arb.first is not None
    for slot in range(2):
        on = touching & ~arb.first & arb.exists[:, slot]
        jx, jy = rotate(arb.normal, arb.jn[:, slot], arb.jt[:, slot])
        jx, jy = jx * dt_coef, jy * dt_coef
        r2x, r2y = arb.r2[:, slot, 0], arb.r2[:, slot, 1]
        vx = xp.where(on, vx + jx * s.m_inv, vx)
        vy = xp.where(on, vy + jy * s.m_inv, vy)
        w = xp.where(on, w + s.i_inv * (r2x * jy - r2y * jx), w)
    return vx, vy, w


def apply_impulse(arb: Arbiters, touching: Any, s: Solver, bounce: Any, vx: Any, vy: Any, w: Any,
                  bias: list[Any], xp: Any) -> tuple[Any, Any, Any]:
    """One pass of cpArbiterApplyImpulse over each device's contacts; ``bias`` (vx, vy, spin of the
    position correction) is updated in place."""
    assert arb.normal is not None and arb.r2 is not None and arb.n_mass is not None and arb.t_mass is not None
    assert arb.bias is not None and arb.j_bias is not None
    n = arb.normal
    nx, ny = n[:, 0], n[:, 1]
    for slot in range(2):
        on = touching & arb.exists[:, slot]
        r2x, r2y = arb.r2[:, slot, 0], arb.r2[:, slot, 1]
        n_mass, t_mass = arb.n_mass[:, slot], arb.t_mass[:, slot]
        bvx, bvy, bw = bias
        vb_x, vb_y = bvx + -r2y * bw, bvy + r2x * bw
        vr_x, vr_y = vx + -r2y * w, vy + r2x * w
        vbn = vb_x * nx + vb_y * ny
        vrn = vr_x * nx + vr_y * ny
        vrt = vr_x * -ny + vr_y * nx
        jbn = (arb.bias[:, slot] - vbn) * n_mass
        jbn_old = arb.j_bias[:, slot]
        j_bias = _max0(jbn_old + jbn, xp)
        jn = -(bounce[:, slot] + vrn) * n_mass
        jn_old = arb.jn[:, slot]
        jn_acc = _max0(jn_old + jn, xp)
        jt_max = s.friction * jn_acc
        jt = -vrt * t_mass
        jt_old = arb.jt[:, slot]
        x = jt_old + jt
        x = xp.where(x > -jt_max, x, -jt_max)
        jt_acc = xp.where(x < jt_max, x, jt_max)
        bx, by = nx * (j_bias - jbn_old), ny * (j_bias - jbn_old)
        jx, jy = rotate(n, jn_acc - jn_old, jt_acc - jt_old)
        bias[0] = xp.where(on, bvx + bx * s.m_inv, bvx)
        bias[1] = xp.where(on, bvy + by * s.m_inv, bvy)
        bias[2] = xp.where(on, bw + s.i_inv * (r2x * by - r2y * bx), bw)
        vx = xp.where(on, vx + jx * s.m_inv, vx)
        vy = xp.where(on, vy + jy * s.m_inv, vy)
        w = xp.where(on, w + s.i_inv * (r2x * jy - r2y * jx), w)
        arb.j_bias[:, slot] = xp.where(on, j_bias, jbn_old)
        arb.jn[:, slot] = xp.where(on, jn_acc, jn_old)
        arb.jt[:, slot] = xp.where(on, jt_acc, jt_old)
    return vx, vy, w


def bounce_velocity(arb: Arbiters, vx: Any, vy: Any, w: Any) -> Any:
    """Each contact's normal velocity times the restitution (0 x 0): Chipmunk's ``bounce``, kept for its
    sign of zero."""
    assert arb.normal is not None and arb.r2 is not None
    r2x, r2y = arb.r2[..., 0], arb.r2[..., 1]
    vrx, vry = vx[:, None] + -r2y * w[:, None], vy[:, None] + r2x * w[:, None]
    return (vrx * arb.normal[:, None, 0] + vry * arb.normal[:, None, 1]) * (0.0 * 0.0)
