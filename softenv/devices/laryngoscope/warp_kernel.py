"""The laryngoscope's control period as one NVIDIA Warp kernel, written once for Warp's CPU (LLVM) and CUDA
back ends and, through Warp's generated adjoint, for gradients: the hand's clipped command, the tongue's
contact (:func:`~.physics.tongue_substep_floats`), the virtual coupling, the blade against the incisors
and Chipmunk's solver.

Chipmunk's step runs as pymunk's ``space.step`` runs it, with its expressions as written, so the same
IEEE operations run in the same order: positions (spending the contact's bias velocities), the collision
and the arbiter's pre-step, the springs' explicit impulses, velocities, the contact's cached impulses,
then ``SOLVER_ITERATIONS`` passes of the contact's and the springs' implicit impulses. The collision is
``SegmentToPoly`` without its iterative search: the nearest of the Minkowski difference's candidate
edges while the cores are apart (GJK), the nearest edge of its hull once the blade sinks past the
incisors' radius (EPA), then ``ClosestPointsNew``, ``SupportEdgeFor*`` and ``ContactPoints``. Warp's CPU
path compiles without fused multiply-add and calls the C library's ``sin``, ``cos``, ``exp`` and
``sqrt``, so ``tests/test_laryngoscope_warp.py`` holds every device to a single pymunk device bit for bit.

One device's state is a :class:`Device`; :func:`substep` advances it by one substep. Two kernels call it:
:func:`control_period` runs a period's substeps in registers (the fast path, compiled without an
adjoint), and :func:`one_substep` runs one substep from one array to another, so that a
:class:`warp.Tape` over a launch a substep keeps every intermediate state for the adjoint (Warp
differentiates a loop only where it unrolls it). Warp does not differentiate an assignment to a vector's
component, so :func:`substep` builds new vectors (:func:`put`).

No contact state crosses a control period (:mod:`.space`): :func:`start` opens each period with no
arbiter and no bias velocity. Warp caches the compiled kernels in the user's cache directory
(``warp.config.kernel_cache_dir``), keyed by their source.
"""

from __future__ import annotations

import math

import warp as wp

from .params import SCENE_COLUMNS, SPRING_LENGTH
from .state import HAND_ANCHORS, PERSISTENCE, SOLVER_ITERATIONS, TINY

wp.config.log_level = wp.LOG_WARNING      # Warp greets and reports every module it loads otherwise
wp.init()

f64 = wp.float64
ZERO, HALF, ONE, TWO = f64(0.0), f64(0.5), f64(1.0), f64(2.0)
TINY_ = f64(TINY)
MAX_VERTICES = 8                    # the blade polygon's vertices a kernel holds (the default blade has 5)
Outline = wp.types.matrix(shape=(MAX_VERTICES, 2), dtype=f64)              # CPFLOAT_MIN
# The Minkowski difference's points, (segment end i, blade vertex j) at MAX_VERTICES i + j: a stack array the
# collision's loops index (indexing the Outline matrix at a run-time row stores it to the stack at every read)
Difference = wp.fixedarray(dtype=wp.vec2d, shape=(2 * MAX_VERTICES,))
ANCHOR_0, ANCHOR_1 = (wp.constant(wp.vec2d(*anchor)) for anchor in HAND_ANCHORS)    # the springs' hand anchors


@wp.struct
class Params:
    """Every constant a substep reads (:class:`~.physics.Constants` and :class:`~.state.IncisorContact`)."""

    R: f64
    h: f64
    inv_m: f64
    inv_I: f64
    h_over_m: f64
    k: f64
    c: f64
    k_t: f64
    mu: f64
    k_ref: f64
    damping: f64
    step: f64
    inv_step: f64
    top: int
    grip: wp.vec2d
    heel: wp.vec2d
    tip: wp.vec2d
    low: wp.vec4d
    high: wp.vec4d
    end0: wp.vec2d       # the incisors' segment, its normal and radius
    end1: wp.vec2d
    seg_normal: wp.vec2d
    radius: f64
    friction: f64
    slop: f64
    bias_coef: f64
    dt_coef: f64
    jaw: wp.vec2d        # the lower incisal edge's centre, its radius, the jaw's spring and damper
    jaw_radius: f64
    k_jaw: f64
    c_jaw: f64
    jaw_present: int     # 0: no lower incisors
    vertices: int        # the blade polygon's vertex count
    max_hand_speed: f64  # the hand's speeds at |action| = 1 (m/s, rad/s)
    max_pitch_rate: f64
    max_sweep_speed: f64


# a device's scene parameters (params.SCENE_COLUMNS, :func:`scene_row`), then the wrist damper's coefficient
Tune = wp.types.vector(length=len(SCENE_COLUMNS) + 1, dtype=f64)


@wp.struct
class Device:
    """One device's state within a control period: blade (position, angle, velocity), hand, lateral
    spring, hand velocity, tongue contact, the blade's bias velocity, the incisors' arbiter, the
    period's summed incisor impulse and the incisors' force and torque on the blade in the last substep."""

    px: f64
    py: f64
    a: f64
    ca: f64              # cos and sin of the blade's angle, as the last substep left them
    sa: f64
    vx: f64
    vy: f64
    w: f64
    gx: f64
    gy: f64
    pitch: f64
    lat_y: f64
    lat_v: f64
    hand_lat: f64
    anchor: f64
    hvx: f64
    hvy: f64
    hw: f64
    hl: f64
    P: f64
    Q: f64
    cx: f64
    cy: f64
    bvx: f64
    bvy: f64
    bw: f64
    alive: int
    ticks: int
    anx: f64
    any_: f64
    ex: wp.vec2i
    feat: wp.vec4i       # slot 0's (segment end, blade vertex), then slot 1's
    jn: wp.vec2d
    jt: wp.vec2d
    impulse: f64
    tfx: f64
    tfy: f64
    ttq: f64


@wp.func
def clip(x: f64, low: f64, high: f64) -> f64:
    if x < low:
        return low
    if x > high:
        return high
    return x


@wp.func
def put(v: wp.vec2d, s: int, x: f64) -> wp.vec2d:
    """``v`` with component ``s`` set to ``x``: a new vector, as Warp's adjoint needs (it does not
    differentiate through assignment to a component)."""
    if s == 0:
        return wp.vec2d(x, v[1])
    return wp.vec2d(v[0], x)


@wp.func
def root(x: f64) -> f64:
    """``sqrt(x)``, whose adjoint is 0 at ``x = 0`` (:func:`adj_root`)."""
    return wp.sqrt(x)


@wp.func_grad(root)
def adj_root(x: f64, adj_ret: f64):
    # sqrt's slope is infinite at 0, and 0 times it (a zero impulse, no excess stiffness) would be NaN: the
    # subgradient 0 there, as softenv._torch_ops.TorchOps.sqrt takes it on the tensor path
    if x > ZERO:
        wp.adjoint[x] += adj_ret * HALF / wp.sqrt(x)


@wp.func
def inverse(x: f64) -> f64:
    """``1 / x``, whose adjoint forms nothing where no gradient flows back (:func:`adj_inverse`)."""
    return ONE / x


@wp.func_grad(inverse)
def adj_inverse(x: f64, adj_ret: f64):
    # Chipmunk's 1 / (d + CPFLOAT_MIN) is finite at d = 0 but its slope overflows: where the clamp after it
    # saturated, 0 flows back, and 0 times that slope would be NaN
    if adj_ret != ZERO:
        r = ONE / x
        wp.adjoint[x] -= adj_ret * r * r


@wp.func
def max0(x: f64) -> f64:
    if x > ZERO:
        return x
    return ZERO


@wp.func
def table_index(x: f64, top: int) -> int:
    if x < f64(top):
        return int(x)
    return top


@wp.func
def world_vertex(local: wp.array(dtype=wp.vec2d), j: int, ca: f64, sa: f64, px: f64, py: f64) -> wp.vec2d:
    lx, ly = local[j][0], local[j][1]
    return wp.vec2d((ca * lx + -sa * ly) + px, (sa * lx + ca * ly) + py)


@wp.func
def world_normal(local_normals: wp.array(dtype=wp.vec2d), j: int, ca: f64, sa: f64) -> wp.vec2d:
    lx, ly = local_normals[j][0], local_normals[j][1]
    return wp.vec2d(ca * lx + -sa * ly, sa * lx + ca * ly)


@wp.func
def world_vertices(local: wp.array(dtype=wp.vec2d), count: int, ca: f64, sa: f64, px: f64, py: f64) -> Outline:
    """The blade's vertices in the world frame, row ``j`` for ``j < count`` (the rows past it repeat the
    last): computed once a substep, read by the collision (a matrix built whole, which Warp differentiates)."""
    last = count - 1
    return wp.matrix_from_rows(
        world_vertex(local, wp.min(0, last), ca, sa, px, py), world_vertex(local, wp.min(1, last), ca, sa, px, py),
        world_vertex(local, wp.min(2, last), ca, sa, px, py), world_vertex(local, wp.min(3, last), ca, sa, px, py),
        world_vertex(local, wp.min(4, last), ca, sa, px, py), world_vertex(local, wp.min(5, last), ca, sa, px, py),
        world_vertex(local, wp.min(6, last), ca, sa, px, py), world_vertex(local, wp.min(7, last), ca, sa, px, py))


@wp.func
def world_normals(local_normals: wp.array(dtype=wp.vec2d), count: int, ca: f64, sa: f64) -> Outline:
    """The blade's edge normals in the world frame, as :func:`world_vertices` lays them out."""
    last = count - 1
    return wp.matrix_from_rows(
        world_normal(local_normals, wp.min(0, last), ca, sa), world_normal(local_normals, wp.min(1, last), ca, sa),
        world_normal(local_normals, wp.min(2, last), ca, sa), world_normal(local_normals, wp.min(3, last), ca, sa),
        world_normal(local_normals, wp.min(4, last), ca, sa), world_normal(local_normals, wp.min(5, last), ca, sa),
        world_normal(local_normals, wp.min(6, last), ca, sa), world_normal(local_normals, wp.min(7, last), ca, sa))


@wp.func
def row(m: Outline, j: int) -> wp.vec2d:
    return wp.vec2d(m[j, 0], m[j, 1])


@wp.func
def closest_t(ax: f64, ay: f64, bx: f64, by: f64) -> f64:
    dx, dy = bx - ax, by - ay
    d2 = dx * dx + dy * dy
    if d2 == ZERO:
        return ZERO
    return -clip((dx * (ax + bx) + dy * (ay + by)) / d2, -ONE, ONE)


@wp.func
def lerp_t(ax: f64, ay: f64, bx: f64, by: f64, t: f64) -> wp.vec2d:
    ht = HALF * t
    return wp.vec2d(ax * (HALF - ht) + bx * (HALF + ht), ay * (HALF - ht) + by * (HALF + ht))


@wp.func
def segment_end(e0: wp.vec2d, e1: wp.vec2d, i: int) -> wp.vec2d:
    if i == 0:
        return e0
    return e1


@wp.func
def outside_an_edge(vw: Outline, nw: Outline, count: int, e0: wp.vec2d, e1: wp.vec2d, gap: f64) -> bool:
    """Whether both segment ends lie further than ``gap`` outside one of the blade's edges."""
    for j in range(wp.static(MAX_VERTICES)):            # constant rows: no store of the matrices
        if j < count:
            v, n = row(vw, j), row(nw, j)
            plane = n[0] * v[0] + n[1] * v[1]
            if n[0] * e0[0] + n[1] * e0[1] - plane > gap and n[0] * e1[0] + n[1] * e1[1] - plane > gap:
                return True
    return False


@wp.func
def separated(vw: Outline, nw: Outline, count: int, e0: wp.vec2d, e1: wp.vec2d, radius: f64) -> bool:
    """Whether the segment lies further than its radius (and a margin far above rounding) outside one of
    the blade's edges: the convex blade then clears the rounded segment, and :func:`collide` would find no
    contact."""
    return outside_an_edge(vw, nw, count, e0, e1, radius * (ONE + f64(1e-9)) + f64(1e-12))


@wp.func_grad(separated)
def adj_separated(vw: Outline, nw: Outline, count: int, e0: wp.vec2d, e1: wp.vec2d, radius: f64, adj_ret: bool):
    pass        # a test: no gradient (and no replay of its loop, which Warp's adjoint does not follow)


@wp.func
def candidate(k: int, count: int) -> wp.vec4i:
    """Candidate edge ``k`` of the difference: (segment end, blade vertex) at its start and its end: the
    blade's edges from end 0 (``k < count``), then from end 1, then the segment from each vertex. Selects,
    not branches or division, so that the vector stays in registers."""
    pair = k < 2 * count
    first = k < count
    j = wp.where(first, k, wp.where(pair, k - count, k - 2 * count))
    i = wp.where(pair and not first, 1, 0)
    return wp.vec4i(i, j, wp.where(pair, i, 1), wp.where(pair, wp.where(j + 1 < count, j + 1, 0), j))


@wp.func
def minkowski(vw: Outline, e0: wp.vec2d, e1: wp.vec2d, i: int, j: int) -> wp.vec2d:
    """Point (segment end ``i``, blade vertex ``j``) of the difference: vertex minus end."""
    e = segment_end(e0, e1, i)
    return wp.vec2d(vw[j, 0] - e[0], vw[j, 1] - e[1])


@wp.func
def point(points: Difference, i: int, j: int) -> wp.vec2d:
    return points[MAX_VERTICES * i + j]


@wp.func
def hull_side(points: Difference, count: int, ax: f64, ay: f64, bx: f64, by: f64) -> int:
    """1 if every point of the difference lies left of ``a -> b``, -1 if right, 0 otherwise."""
    ex, ey = bx - ax, by - ay
    left = int(1)
    right = int(1)
    for i in range(2):
        for j in range(count):
            q = point(points, i, j)
            side = ex * (q[1] - ay) - ey * (q[0] - ax)
            left = left & int(side >= ZERO)
            right = right & int(side <= ZERO)
            if left == 0 and right == 0:
                return 0
    if left == 1:
        return 1
    if right == 1:
        return -1
    return 0


@wp.func
def cores_overlap(points: Difference, count: int) -> bool:
    """Whether the origin lies strictly inside the difference's hull."""
    for k in range(3 * count):
        c = candidate(k, count)
        a = point(points, c[0], c[1])
        b = point(points, c[2], c[3])
        left = hull_side(points, count, a[0], a[1], b[0], b[1])
        origin = (b[0] - a[0]) * -a[1] - (b[1] - a[1]) * -a[0]
        if (left == 1 and not origin > ZERO) or (left == -1 and not origin < ZERO):
            return False
    return True


@wp.struct
class Collision:
    """What :func:`collide` finds: the normal, each contact's points on the segment and on the blade,
    their features and which exist."""

    nx: f64
    ny: f64
    p0: wp.vec4d
    p1: wp.vec4d
    feat: wp.vec4i
    ex: wp.vec2i


@wp.func
def nearest_edge(vw: Outline, nw: Outline, count: int, e0: wp.vec2d, e1: wp.vec2d) -> wp.vec4i:
    """The difference's edge ``SegmentToPoly`` ends on, as (segment end, blade vertex) at its start and
    its end, in the order its normal needs: the nearest of the candidates (GJK's) while the cores are apart,
    the nearest edge of the hull (EPA's) once they overlap. A choice, so it has no gradient
    (:func:`adj_nearest_edge`)."""
    points = wp.zeros(shape=wp.static(2 * MAX_VERTICES), dtype=wp.vec2d)
    for j in range(wp.static(MAX_VERTICES)):            # constant rows: no store of the matrix
        points[j] = minkowski(vw, e0, e1, 0, j)
        points[MAX_VERTICES + j] = minkowski(vw, e0, e1, 1, j)
    # the cores overlap only where the bar's core meets the blade: both ends outside one of its edges (by a
    # margin far above rounding) rule that out without the hull's test
    inside = False
    if not outside_an_edge(vw, nw, count, e0, e1, f64(1e-12)):
        inside = cores_overlap(points, count)
    best_d, best_px, best_py, e_dx, e_dy, best_left = f64(math.inf), f64(0.0), f64(0.0), f64(0.0), f64(0.0), int(0)
    best = wp.vec4i(0, 0, 0, 0)
    for k in range(3 * count):
        c = candidate(k, count)
        a = point(points, c[0], c[1])
        b = point(points, c[2], c[3])
        left = int(0)
        if inside:
            left = hull_side(points, count, a[0], a[1], b[0], b[1])
        if not (inside and left == 0):                   # inside the hull: not where EPA ends
            t = closest_t(a[0], a[1], b[0], b[1])
            q = lerp_t(a[0], a[1], b[0], b[1], t)
            d = q[0] * q[0] + q[1] * q[1]
            if d < best_d:                               # the first of equals, as argmin
                best_d, best_px, best_py, best_left = d, q[0], q[1], left
                best = c
                e_dx, e_dy = b[0] - a[0], b[1] - a[1]
    flip = e_dy * best_px + -e_dx * best_py < ZERO
    if inside:
        flip = best_left == 1
    if flip:
        return wp.vec4i(best[2], best[3], best[0], best[1])
    return best


@wp.func_grad(nearest_edge)
def adj_nearest_edge(vw: Outline, nw: Outline, count: int, e0: wp.vec2d, e1: wp.vec2d, adj_ret: wp.vec4i):
    # Warp's adjoint does not follow a loop it does not unroll, and its replay of this one (the running
    # minimum starts at infinity) formed NaN: the edge is chosen, so nothing flows back
    pass


@wp.func
def support_vertex(vw: Outline, count: int, bx: f64, by: f64) -> int:
    """The first blade vertex furthest along ``(bx, by)`` (``SupportEdgeForPoly``'s); a choice, with no
    gradient (:func:`adj_support_vertex`)."""
    i1p, top = int(0), vw[0, 0] * bx + vw[0, 1] * by
    for j in range(1, count):
        s = vw[j, 0] * bx + vw[j, 1] * by
        if s > top:                                      # the first of equals, as argmax
            i1p, top = j, s
    return i1p


@wp.func_grad(support_vertex)
def adj_support_vertex(vw: Outline, count: int, bx: f64, by: f64, adj_ret: int):
    pass


@wp.func
def collide(p: Params, vw: Outline, nw: Outline) -> Collision:
    """Chipmunk's ``SegmentToPoly`` for one blade: the nearest edge of the difference
    (:func:`nearest_edge`), then its closest points, normal and contact points."""
    count = p.vertices
    e0, e1 = p.end0, p.end1
    edge = nearest_edge(vw, nw, count, e0, e1)
    m0 = minkowski(vw, e0, e1, edge[0], edge[1])
    m1 = minkowski(vw, e0, e1, edge[2], edge[3])
    # ClosestPointsNew
    t = closest_t(m0[0], m0[1], m1[0], m1[1])
    q = lerp_t(m0[0], m0[1], m1[0], m1[1], t)
    rx, ry = m1[1] - m0[1], -(m1[0] - m0[0])
    inv = inverse(root(rx * rx + ry * ry) + TINY_)
    nx, ny = rx * inv, ry * inv
    d = nx * q[0] + ny * q[1]
    if not (d <= ZERO or (-ONE < t and t < ONE)):         # a vertex pair
        d2 = root(q[0] * q[0] + q[1] * q[1])
        inv = inverse(d2 + TINY_)
        nx, ny, d = q[0] * inv, q[1] * inv, d2
    # SupportEdgeForSegment(seg, n) and SupportEdgeForPoly(poly, -n)
    sa_i, sb_i = 1, 0
    if p.seg_normal[0] * nx + p.seg_normal[1] * ny > ZERO:
        sa_i, sb_i = 0, 1
    bx, by = -nx, -ny
    i1p = support_vertex(vw, count, bx, by)
    i0p, i2p = (i1p - 1 + count) % count, (i1p + 1) % count
    n1, n2 = row(nw, i1p), row(nw, i2p)
    qa, qb = i1p, i2p
    if bx * n1[0] + by * n1[1] > bx * n2[0] + by * n2[1]:
        qa, qb = i0p, i1p
    # ContactPoints (the blade has no radius)
    radius = p.radius
    touching = (d - radius) - ZERO <= ZERO and d <= radius + ZERO
    ea, eb = segment_end(e0, e1, sa_i), segment_end(e0, e1, sb_i)
    sax, say, sbx, sby = ea[0], ea[1], eb[0], eb[1]
    va, vb = row(vw, qa), row(vw, qb)
    qax, qay, qbx, qby = va[0], va[1], vb[0], vb[1]
    d1a, d1b = sax * ny - say * nx, sbx * ny - sby * nx
    d2a, d2b = qax * ny - qay * nx, qbx * ny - qby * nx
    e1_denom = inverse(d1b - d1a + TINY_)
    e2_denom = inverse(d2b - d2a + TINY_)
    out = Collision()
    out.nx = nx
    out.ny = ny
    out.feat = wp.vec4i(sa_i, qb, sb_i, qa)
    ex = wp.vec2i(0, 0)
    for slot in range(2):
        first, second = d2b - d1a, d1a - d2a
        if slot == 1:
            first, second = d2a - d1a, d1b - d2a
        fu = clip(first * e1_denom, ZERO, ONE)
        fv = clip(second * e2_denom, ZERO, ONE)
        pts = wp.vec4d(nx * radius + (sax * (ONE - fu) + sbx * fu), ny * radius + (say * (ONE - fu) + sby * fu),
                       nx * -ZERO + (qax * (ONE - fv) + qbx * fv), ny * -ZERO + (qay * (ONE - fv) + qby * fv))
        if slot == 0:
            out.p0 = pts
        else:
            out.p1 = pts
        if touching and (pts[2] - pts[0]) * nx + (pts[3] - pts[1]) * ny <= ZERO:
            ex[slot] = 1
    out.ex = ex
    return out


@wp.func
def jaw_force(p: Params, px: f64, py: f64, ca: f64, sa: f64, vx: f64, vy: f64, w: f64) -> wp.vec3d:
    """The jaw's push on the blade (x, y) and its torque (:func:`~.physics.jaw_force`, the same expressions)."""
    ex = px + ca * p.heel[0] - sa * p.heel[1]
    ey = py + sa * p.heel[0] + ca * p.heel[1]
    dx = (px + ca * p.tip[0] - sa * p.tip[1]) - ex
    dy = (py + sa * p.tip[0] + ca * p.tip[1]) - ey
    t = ((p.jaw[0] - ex) * dx + (p.jaw[1] - ey) * dy) / (dx * dx + dy * dy)
    ux, uy = -sa, ca
    depth = p.jaw_radius - ((ex - p.jaw[0]) * ux + (ey - p.jaw[1]) * uy)
    rx = (ex + t * dx) - px
    ry = (ey + t * dy) - py
    approach = -((vx - w * ry) * ux + (vy + w * rx) * uy)
    F = ZERO
    if depth > ZERO and t >= ZERO and t <= ONE:
        F = max0(p.k_jaw * depth + p.c_jaw * approach)
    fx = F * ux
    fy = F * uy
    return wp.vec3d(fx, fy, rx * fy - ry * fx)


@wp.func
def hand_command(action: wp.vec4d, pitch: f64, p: Params) -> wp.vec4d:
    """The hand's velocities (x, z, pitch rate, lateral) for a normalised action at hand pitch ``pitch``
    (:func:`~.physics.hand_command`, the same expressions)."""
    cos_a, sin_a = wp.cos(pitch), wp.sin(pitch)
    v = p.max_hand_speed
    return wp.vec4d(v * (-action[0] * cos_a + action[1] * sin_a), v * (-action[0] * sin_a - action[1] * cos_a),
                    p.max_pitch_rate * action[3], p.max_sweep_speed * action[2])


@wp.func
def action_of(actions: wp.array2d(dtype=f64), i: int) -> wp.vec4d:
    return wp.vec4d(actions[i, 0], actions[i, 1], actions[i, 2], actions[i, 3])


@wp.func
def substep(d: Device, p: Params, tune: Tune, command: wp.vec4d, loads: wp.array(dtype=f64),
            slopes: wp.array(dtype=f64), d_loads: wp.array(dtype=f64), d_slopes: wp.array(dtype=f64),
            local: wp.array(dtype=wp.vec2d), local_normals: wp.array(dtype=wp.vec2d)) -> Device:
    """One substep of one device: the hand's clipped velocity, the tongue's force, then Chipmunk's step of
    the coupled blade against the incisors (``cpSpaceStep``). ``tune`` is the device's row of the scene
    parameters (:func:`scene_row`): the coupling's stiffness and damping, the factor on the tongue's
    stiffness (its load table and lateral grip), the wrist's rotary stiffness and damping, and the factor
    ``q`` on the stiffening law's depth, which moves the load table to first order along ``d_loads`` and
    ``d_slopes`` (its derivative in ``q``; at ``q = 1`` the table is the scene's bit for bit)."""
    h = p.h
    k_c, c_c, s_t = tune[0], tune[1], tune[2]
    k_rot, c_rot, dq, w_coef = tune[3], tune[4], tune[5] - ONE, tune[6]
    m_inv, i_inv = p.inv_m, p.inv_I
    px, py, a, ca, sa, vx, vy, w = f64(d.px), f64(d.py), f64(d.a), f64(d.ca), f64(d.sa), f64(d.vx), f64(d.vy), f64(d.w)
    gx, gy, pitch = f64(d.gx), f64(d.gy), f64(d.pitch)
    hvx = clip(command[0], (p.low[0] - gx) / h, (p.high[0] - gx) / h)
    hvy = clip(command[1], (p.low[1] - gy) / h, (p.high[1] - gy) / h)
    hw = clip(command[2], (p.low[2] - pitch) / h, (p.high[2] - pitch) / h)
    hl = clip(command[3], (p.low[3] - d.hand_lat) / h, (p.high[3] - d.hand_lat) / h)
    hand_lat = d.hand_lat + h * hl
    # the jaw's push now (physics.jaw_force), which the tongue's barrier predicts with the incisors' last
    jaw = wp.vec3d()
    teeth_x, teeth_y, teeth_t = f64(d.tfx), f64(d.tfy), f64(d.ttq)
    if p.jaw_present == 1:
        jaw = jaw_force(p, px, py, ca, sa, vx, vy, w)
        teeth_x, teeth_y, teeth_t = teeth_x + jaw[0], teeth_y + jaw[1], teeth_t + jaw[2]
    # the tongue (physics.tongue_substep_floats)
    lat_y, lat_v, anchor = f64(d.lat_y), f64(d.lat_v), f64(d.anchor)
    ex_ = px + ca * p.heel[0] - sa * p.heel[1]
    ey_ = py + sa * p.heel[0] + ca * p.heel[1]
    dx = (px + ca * p.tip[0] - sa * p.tip[1]) - ex_
    dy = (py + sa * p.tip[0] + ca * p.tip[1]) - ey_
    t = clip(-(ex_ * dx + ey_ * dy) / (dx * dx + dy * dy), ZERO, ONE)
    cx = ex_ + t * dx
    cy = ey_ + t * dy
    dist = root(cx * cx + cy * cy) + f64(1e-300)
    on_tongue = dist < p.R
    fx, fy, torque, P = f64(0.0), f64(0.0), f64(0.0), f64(0.0)
    if on_tongue:
        depth = p.R - dist
        nx = cx / dist
        ny = cy / dist
        rx = cx - px
        ry = cy - py
        approach = -((vx - w * ry) * nx + (vy + w * rx) * ny)
        rn = rx * ny - ry * nx
        inv_meff = p.inv_m + rn * rn * p.inv_I
        i = table_index(max0(depth) * p.inv_step, p.top)
        slope = s_t * (slopes[i] + dq * d_slopes[i])
        law = s_t * (loads[i] + dq * d_loads[i]) + (depth - f64(i) * p.step) * slope
        k = table_index(max0(depth + h * approach) * p.inv_step, p.top)
        ahead = s_t * (slopes[k] + dq * d_slopes[k])
        if ahead > slope:
            slope = ahead
        excess = max0(slope - p.k_ref)
        stiff = excess * h + TWO * root(excess / inv_meff)
        qx, qy = ca * p.grip[0] - sa * p.grip[1], sa * p.grip[0] + ca * p.grip[1]
        Fx = k_c * (gx - px - qx) + c_c * (hvx - vx + w * qy)
        Fy = k_c * (gy - py - qy) + c_c * (hvy - vy - w * qx)
        tau = qx * Fy - qy * Fx + k_rot * (pitch - a) + c_rot * (hw - w)
        push = -((Fx + teeth_x) * nx + (Fy + teeth_y) * ny) * p.inv_m - (tau + teeth_t) * rn * p.inv_I
        beta = stiff * h * inv_meff
        P = max0((law + (p.damping + stiff) * approach + stiff * h * push) / (ONE + beta))
        fx = P * nx
        fy = P * ny
        torque = rx * fy - ry * fx
    if p.jaw_present == 1:
        fx, fy, torque = fx + jaw[0], fy + jaw[1], torque + jaw[2]
    k_t = s_t * p.k_t
    k_s = k_t * f64(on_tongue)
    lat_v = (lat_v + p.h_over_m * (k_c * (hand_lat - lat_y) + c_c * hl - k_s * (lat_y - anchor))) / \
        (ONE + p.h_over_m * c_c)
    lat_y = lat_y + h * lat_v
    stuck = k_s * (lat_y - anchor)
    Q = clip(stuck, -(p.mu * P), p.mu * P)
    if on_tongue:
        if Q != stuck:
            anchor = lat_y - Q / k_t
    else:
        anchor = lat_y
    # cpSpaceStep: 1. positions, spending the contact's bias velocities
    gx, gy, pitch = gx + hvx * h, gy + hvy * h, pitch + hw * h
    px, py, a = px + (vx + d.bvx) * h, py + (vy + d.bvy) * h, a + (w + d.bw) * h
    bvx, bvy, bw = f64(0.0), f64(0.0), f64(0.0)
    ca, sa, cp, sp = wp.cos(a), wp.sin(a), wp.cos(pitch), wp.sin(pitch)
    # collide, update the arbiter (cpArbiterUpdate), pre-step its contacts (cpArbiterPreStep)
    alive, ticks = int(d.alive), int(d.ticks)
    anx, any_ = f64(d.anx), f64(d.any_)
    ex, feat, jn, jt = wp.vec2i(d.ex), wp.vec4i(d.feat), wp.vec2d(d.jn), wp.vec2d(d.jt)
    touching, first = bool(False), bool(False)
    r2x, r2y = wp.vec2d(), wp.vec2d()          # each contact's offset from the blade's centre
    n_mass, t_mass, bias, j_bias, bounce = wp.vec2d(), wp.vec2d(), wp.vec2d(), wp.vec2d(), wp.vec2d()
    vw = world_vertices(local, p.vertices, ca, sa, px, py)
    nw = world_normals(local_normals, p.vertices, ca, sa)
    if alive == 0 and separated(vw, nw, p.vertices, p.end0, p.end1, p.radius):
        ticks += 1                # no contact, no arbiter: only its age changes, as collide's would
    else:
        hit = collide(p, vw, nw)
        touching = hit.ex[0] == 1 or hit.ex[1] == 1
        jn_new, jt_new = wp.vec2d(), wp.vec2d()
        for new in range(2):
            for old in range(2):
                if (alive == 1 and ex[old] == 1 and hit.feat[2 * new] == feat[2 * old]
                        and hit.feat[2 * new + 1] == feat[2 * old + 1]):
                    jn_new = put(jn_new, new, jn[old])
                    jt_new = put(jt_new, new, jt[old])
        first = touching and not (alive == 1 and ticks == 0)
        ticks = wp.where(touching, 0, ticks + 1)
        alive = wp.where(touching or (alive == 1 and ticks < PERSISTENCE), 1, 0)
        if touching:              # the arbiter's normal and pre-step: read only while touching
            ex, feat, jn, jt = wp.vec2i(hit.ex), wp.vec4i(hit.feat), jn_new, jt_new
            anx, any_ = f64(hit.nx), f64(hit.ny)
            for s in range(2):
                pts = wp.vec4d(hit.p0)
                if s == 1:
                    pts = wp.vec4d(hit.p1)
                r1x, r1y = pts[0] - ZERO, pts[1] - ZERO
                rx, ry = pts[2] - px, pts[3] - py
                r2x = put(r2x, s, rx)
                r2y = put(r2y, s, ry)
                rcn = rx * any_ - ry * anx
                n_mass = put(n_mass, s, ONE / (ZERO + (m_inv + i_inv * rcn * rcn)))
                rct = rx * anx - ry * -any_
                t_mass = put(t_mass, s, ONE / (ZERO + (m_inv + i_inv * rct * rct)))
                dist_s = ((rx - r1x) + px) * anx + ((ry - r1y) + py) * any_
                low = dist_s + p.slop
                lowest = low
                if ZERO < low:
                    lowest = ZERO
                bias = put(bias, s, -p.bias_coef * lowest / h)
                j_bias = put(j_bias, s, ZERO)
                # the bounce velocity (no elasticity)
                bounce = put(bounce, s, ((vx + -ry * w) * anx + (vy + rx * w) * any_) * (ZERO * ZERO))
    # 2. the springs' explicit impulses
    gqx, gqy = ca * p.grip[0] + -sa * p.grip[1], sa * p.grip[0] + ca * p.grip[1]
    # each spring's hand anchor (world frame), normal, mass, damping coefficient, target velocity, impulse
    spring_r1x, spring_r1y, spring_nx, spring_ny = wp.vec2d(), wp.vec2d(), wp.vec2d(), wp.vec2d()
    spring_mass, spring_coef, spring_target, spring_j = wp.vec2d(), wp.vec2d(), wp.vec2d(), wp.vec2d()
    for s in range(2):
        anchor_s = ANCHOR_0
        if s == 1:
            anchor_s = ANCHOR_1
        ax_, ay_ = anchor_s[0], anchor_s[1]
        r1x, r1y = cp * ax_ + -sp * ay_, sp * ax_ + cp * ay_
        sdx, sdy = (px + gqx) - (gx + r1x), (py + gqy) - (gy + r1y)
        sdist = root(sdx * sdx + sdy * sdy)
        inv = ONE / sdist
        nx, ny = sdx * inv, sdy * inv
        rcn = gqx * ny - gqy * nx
        kk = m_inv + i_inv * rcn * rcn
        j = (f64(SPRING_LENGTH) - sdist) * k_c * h
        vx, vy = vx + nx * j * m_inv, vy + ny * j * m_inv
        w = w + i_inv * (gqx * (ny * j) - gqy * (nx * j))
        spring_r1x, spring_r1y = put(spring_r1x, s, r1x), put(spring_r1y, s, r1y)
        spring_nx, spring_ny = put(spring_nx, s, nx), put(spring_ny, s, ny)
        spring_mass = put(spring_mass, s, ONE / kk)
        spring_coef = put(spring_coef, s, ONE - wp.exp(-c_c * h * kk))
        spring_j = put(spring_j, s, j)
    j_rot = ((pitch - a) - ZERO) * k_rot * h
    w = w + j_rot * i_inv
    target_wrn = f64(0.0)
    # 3. velocities
    vx, vy = vx * ONE + (ZERO + fx * m_inv) * h, vy * ONE + (ZERO + fy * m_inv) * h
    w = w * ONE + torque * i_inv * h
    for s in range(2):                                   # cpArbiterApplyCachedImpulse
        if touching and not first and ex[s] == 1:
            jx, jy = anx * jn[s] - any_ * jt[s], anx * jt[s] + any_ * jn[s]
            jx, jy = jx * p.dt_coef, jy * p.dt_coef
            vx, vy = vx + jx * m_inv, vy + jy * m_inv
            w = w + i_inv * (r2x[s] * jy - r2y[s] * jx)
    # 4. the implicit impulses: the contact's, then the springs' in the order added
    i_sum = ONE / i_inv
    for _pass in range(wp.static(SOLVER_ITERATIONS)):
        for s in range(2):                               # cpArbiterApplyImpulse
            if touching and ex[s] == 1:
                rx, ry = r2x[s], r2y[s]
                vbn = (bvx + -ry * bw) * anx + (bvy + rx * bw) * any_
                vr_x, vr_y = vx + -ry * w, vy + rx * w
                vrn = vr_x * anx + vr_y * any_
                vrt = vr_x * -any_ + vr_y * anx
                jbn = (bias[s] - vbn) * n_mass[s]
                jbn_old = j_bias[s]
                jb = max0(jbn_old + jbn)
                jn_old = jn[s]
                jn_acc = max0(jn_old + -(bounce[s] + vrn) * n_mass[s])
                jt_max = p.friction * jn_acc
                jt_old = jt[s]
                x = jt_old + -vrt * t_mass[s]
                if not x > -jt_max:                      # Chipmunk's cpfclamp: the lower bound first
                    x = -jt_max
                jt_acc = x
                if not x < jt_max:
                    jt_acc = jt_max
                bx, by = anx * (jb - jbn_old), any_ * (jb - jbn_old)
                dn, dt = jn_acc - jn_old, jt_acc - jt_old
                jx, jy = anx * dn - any_ * dt, anx * dt + any_ * dn
                bvx, bvy = bvx + bx * m_inv, bvy + by * m_inv
                bw = bw + i_inv * (rx * by - ry * bx)
                vx, vy = vx + jx * m_inv, vy + jy * m_inv
                w = w + i_inv * (rx * jy - ry * jx)
                j_bias, jn, jt = put(j_bias, s, jb), put(jn, s, jn_acc), put(jt, s, jt_acc)
        for s in range(2):
            r1x, r1y, nx, ny = spring_r1x[s], spring_r1y[s], spring_nx[s], spring_ny[s]
            rel_x = (vx + -gqy * w) - (hvx + -r1y * hw)
            rel_y = (vy + gqx * w) - (hvy + r1x * hw)
            vrn = rel_x * nx + rel_y * ny
            v_damp = (spring_target[s] - vrn) * spring_coef[s]
            spring_target = put(spring_target, s, vrn + v_damp)
            acc = spring_j[s]
            j = (acc + v_damp * spring_mass[s]) - acc
            spring_j = put(spring_j, s, acc + j)
            vx, vy = vx + nx * j * m_inv, vy + ny * j * m_inv
            w = w + i_inv * (gqx * (ny * j) - gqy * (nx * j))
        wrn = hw - w
        w_damp = (target_wrn - wrn) * w_coef
        target_wrn = wrn + w_damp
        j = j_rot - (j_rot - w_damp * i_sum)
        j_rot = j_rot - j
        w = w - j * i_inv
    impulse = f64(d.impulse)
    tfx, tfy, ttq = f64(0.0), f64(0.0), f64(0.0)
    if alive == 1 and ticks == 0:                        # cpArbiterTotalImpulse
        tx, ty = f64(0.0), f64(0.0)
        for s in range(2):
            if ex[s] == 1:
                tx, ty = tx + (anx * jn[s] - any_ * jt[s]), ty + (anx * jt[s] + any_ * jn[s])
        impulse = impulse + root(tx * tx + ty * ty)
        # the incisors' force and torque on the blade, for the next substep (physics.teeth_force)
        for s in range(2):
            if ex[s] == 1:
                jx, jy = anx * jn[s] - any_ * jt[s], anx * jt[s] + any_ * jn[s]
                tfx, tfy, ttq = tfx + jx, tfy + jy, ttq + (r2x[s] * jy - r2y[s] * jx)
        tfx, tfy, ttq = tfx / h, tfy / h, ttq / h
    out = Device()
    out.px = px
    out.py = py
    out.a = a
    out.ca = ca
    out.sa = sa
    out.vx = vx
    out.vy = vy
    out.w = w
    out.gx = gx
    out.gy = gy
    out.pitch = pitch
    out.lat_y = lat_y
    out.lat_v = lat_v
    out.hand_lat = hand_lat
    out.anchor = anchor
    out.hvx = hvx
    out.hvy = hvy
    out.hw = hw
    out.hl = hl
    out.P = P
    out.Q = Q
    out.cx = cx
    out.cy = cy
    out.bvx = bvx
    out.bvy = bvy
    out.bw = bw
    out.alive = alive
    out.ticks = ticks
    out.anx = anx
    out.any_ = any_
    out.ex = ex
    out.feat = feat
    out.jn = jn
    out.jt = jt
    out.impulse = impulse
    out.tfx = tfx
    out.tfy = tfy
    out.ttq = ttq
    return out


@wp.func
def scene_row(scene: wp.array2d(dtype=f64), i: int, p: Params) -> Tune:
    """Device ``i``'s scene parameters (:data:`~.params.SCENE_COLUMNS`): the coupling's stiffness (N/m) and damping
    (N s/m), the factor on the tongue's stiffness (1: the scene's), the wrist's rotary stiffness (N m/rad)
    and damping (N m s/rad), the factor on the stiffening law's depth (1: the scene's); then the wrist
    damper's velocity coefficient, 1 - exp(-c_rot h / I), as Chipmunk's damped rotary spring computes it
    (the same roundings: it equals pymunk bit for bit)."""
    c_rot = scene[i, 4]
    return Tune(scene[i, 0], scene[i, 1], scene[i, 2], scene[i, 3], c_rot, scene[i, 5],
                ONE - wp.exp(-c_rot * p.h * p.inv_I))


@wp.func
def start(blade: wp.array2d(dtype=f64), hand: wp.array2d(dtype=f64), lateral: wp.array2d(dtype=f64),
          i: int) -> Device:
    """Device ``i`` at the start of a control period: no arbiter, no bias velocity, no impulse yet."""
    d = Device()
    d.px = blade[i, 0]
    d.py = blade[i, 1]
    d.a = blade[i, 2]
    d.vx = blade[i, 3]
    d.vy = blade[i, 4]
    d.w = blade[i, 5]
    d.ca = wp.cos(d.a)
    d.sa = wp.sin(d.a)
    d.gx = hand[i, 0]
    d.gy = hand[i, 1]
    d.pitch = hand[i, 2]
    d.lat_y = lateral[i, 0]
    d.lat_v = lateral[i, 1]
    d.hand_lat = lateral[i, 2]
    d.anchor = lateral[i, 3]
    return d


@wp.func
def finish(d: Device, count: int, p: Params, blade: wp.array2d(dtype=f64), hand: wp.array2d(dtype=f64),
           lateral: wp.array2d(dtype=f64), hand_v: wp.array2d(dtype=f64), contact: wp.array2d(dtype=f64),
           incisor: wp.array(dtype=f64), i: int):
    """Device ``i``'s rows of the state arrays as a period of ``count`` substeps leaves them (the
    incisors' force: the period's summed impulse over its duration)."""
    blade[i, 0] = d.px
    blade[i, 1] = d.py
    blade[i, 2] = d.a
    blade[i, 3] = d.vx
    blade[i, 4] = d.vy
    blade[i, 5] = d.w
    hand[i, 0] = d.gx
    hand[i, 1] = d.gy
    hand[i, 2] = d.pitch
    lateral[i, 0] = d.lat_y
    lateral[i, 1] = d.lat_v
    lateral[i, 2] = d.hand_lat
    lateral[i, 3] = d.anchor
    hand_v[i, 0] = d.hvx
    hand_v[i, 1] = d.hvy
    hand_v[i, 2] = d.hw
    hand_v[i, 3] = d.hl
    contact[i, 0] = d.P
    contact[i, 1] = d.Q
    contact[i, 2] = d.cx
    contact[i, 3] = d.cy
    incisor[i] = d.impulse / (f64(count) * p.h)


# -O3 (Warp's CPU default is -O2; docs/performance.md) and no fused multiply-add: the C library's roundings
@wp.kernel(enable_backward=False, module="unique", module_options={"optimization_level": 3, "fuse_fp": False})
def control_period(blade: wp.array2d(dtype=f64), hand: wp.array2d(dtype=f64), lateral: wp.array2d(dtype=f64),
                   hand_v: wp.array2d(dtype=f64), contact: wp.array2d(dtype=f64), incisor: wp.array(dtype=f64),
                   actions: wp.array2d(dtype=f64), scene: wp.array2d(dtype=f64), count: int, p: Params,
                   loads: wp.array(dtype=f64), slopes: wp.array(dtype=f64), d_loads: wp.array(dtype=f64),
                   d_slopes: wp.array(dtype=f64), local: wp.array(dtype=wp.vec2d),
                   local_normals: wp.array(dtype=wp.vec2d)):
    """``count`` substeps of device ``i`` (its rows of the state arrays, updated in place), its hand
    commanded by ``actions[i]`` (normalised, in the hand's frame at the period's start), with its row of
    ``scene`` (:func:`scene_row`)."""
    i = wp.tid()
    d = start(blade, hand, lateral, i)
    order = hand_command(action_of(actions, i), d.pitch, p)
    tune = scene_row(scene, i, p)
    for _ in range(count):
        d = substep(d, p, tune, order, loads, slopes, d_loads, d_slopes, local, local_normals)
    finish(d, count, p, blade, hand, lateral, hand_v, contact, incisor, i)


@wp.kernel(module="unique", module_options={"fuse_fp": False})
def open_period(blade: wp.array2d(dtype=f64), hand: wp.array2d(dtype=f64), lateral: wp.array2d(dtype=f64),
                actions: wp.array2d(dtype=f64), p: Params, devices: wp.array(dtype=Device),
                command: wp.array(dtype=wp.vec4d)):
    """The devices as :func:`start` opens a period and their hands' commands, for :func:`one_substep`
    (the differentiable path)."""
    i = wp.tid()
    d = start(blade, hand, lateral, i)
    devices[i] = d
    command[i] = hand_command(action_of(actions, i), d.pitch, p)


@wp.kernel(module="unique", module_options={"fuse_fp": False})
def close_period(devices: wp.array(dtype=Device), count: int, p: Params, blade: wp.array2d(dtype=f64),
                 hand: wp.array2d(dtype=f64), lateral: wp.array2d(dtype=f64), hand_v: wp.array2d(dtype=f64),
                 contact: wp.array2d(dtype=f64), incisor: wp.array(dtype=f64)):
    """The state arrays as the period of ``count`` substeps that :func:`one_substep` ran leaves them."""
    i = wp.tid()
    finish(devices[i], count, p, blade, hand, lateral, hand_v, contact, incisor, i)


@wp.kernel(module="unique", module_options={"fuse_fp": False})
def one_substep(before: wp.array(dtype=Device), command: wp.array(dtype=wp.vec4d), scene: wp.array2d(dtype=f64),
                p: Params, loads: wp.array(dtype=f64), slopes: wp.array(dtype=f64), d_loads: wp.array(dtype=f64),
                d_slopes: wp.array(dtype=f64), local: wp.array(dtype=wp.vec2d),
                local_normals: wp.array(dtype=wp.vec2d), after: wp.array(dtype=Device)):
    """One substep of device ``i`` from ``before`` into ``after``: a launch a substep, so that a
    :class:`warp.Tape` keeps every intermediate state for the adjoint."""
    i = wp.tid()
    after[i] = substep(before[i], p, scene_row(scene, i, p), command[i], loads, slopes, d_loads, d_slopes, local,
                       local_normals)
