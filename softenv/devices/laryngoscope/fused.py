"""The laryngoscope's control period as one Triton kernel, for the torch twin on a GPU: the float twin of
:func:`.warp_kernel.control_period` with one GPU thread a device, each device's whole period in registers.

A branch of the Warp kernel is a ``tl.where`` here (both sides are computed; the one the device takes is
kept), and its skip of the collision for a blade far from the incisors (:func:`.warp_kernel.separated`)
is gone: the collision finds no contact there, so the result is the same; and one pass over the
collision's candidate edges serves both of :func:`.warp_kernel.collide`'s (each hull side computed
once). The expressions are the Warp kernel's; this one is launched without fused multiply-add, so where
the GPU's ``cos``, ``sin``, ``exp`` round as the host's the result is the Warp kernel's bit for bit.
``tests/test_laryngoscope_fused.py`` holds it to the Warp kernel in Triton's interpreter
(``TRITON_INTERPRET=1``, on CPU tensors) and on a GPU.

The scene's constants (:func:`constants`) are compiled in as float64 literals, which take no registers
(as arguments Triton would read them as float32), so the kernel is compiled once for each set of
constants. ``scripts/fused_kernel_profile.py`` shows what it compiles to on a GPU, found without one.
"""

from __future__ import annotations

from dataclasses import fields
from typing import Any

import numpy as np
import torch
import triton
import triton.language as tl

from ..contact import TongueContact
from .params import SPRING_LENGTH, LaryngoscopeParams
from .state import HAND_ANCHORS, PERSISTENCE, SOLVER_ITERATIONS, TINY
from .tensors import LaryngoscopeTensors

BLOCK = 128            # devices a program (one thread each)
JAW_FIELDS = ("jaw", "jaw_radius", "k_jaw", "c_jaw")   # Constants' last fields: their own group, after the blade
COMPILE_OPTIONS = {"enable_fp_fusion": False}     # no fused multiply-add: the host's roundings

# where :func:`constants` puts each group: the tongue's (:class:`.physics.Constants` flattened, but the jaw's) at
# 0, then the coupling's, the contact's scalars, the springs' hand anchors, the segment's ends and normal, the
# blade's vertices and their plane normals, and last the jaw's (edge x, y, radius, spring, damper: at
# _LOCAL + 4 V; zeros without one)
_COUPLING: tl.constexpr = tl.constexpr(30)
_SOLVER: tl.constexpr = tl.constexpr(38)
_ANCHORS: tl.constexpr = tl.constexpr(47)
_ENDS: tl.constexpr = tl.constexpr(51)
_SEG_NORMAL: tl.constexpr = tl.constexpr(55)
_LOCAL: tl.constexpr = tl.constexpr(57)


def constants(dev: LaryngoscopeTensors) -> tuple[float, ...]:
    """The kernel's constants in the layout :func:`_control_period` reads (``C``)."""
    c, s, k = dev.c, dev.incisors, dev.coupling
    tongue = [float(v) for f in fields(c) if f.name not in JAW_FIELDS
              for x in [getattr(c, f.name)] for v in (x if isinstance(x, tuple) else (x,))]
    jaw = [*(c.jaw or (0.0, 0.0)), c.jaw_radius, c.k_jaw, c.c_jaw]
    coupling = [k.m_inv, k.i_inv, k.grip[0], k.grip[1], k.k, k.c, k.k_rot, k.c_rot]
    solver = [s.radius, s.friction, s.slop, s.bias_coef, s.dt_coef, TINY, 1e-300, SPRING_LENGTH,
              float("inf")]
    anchors = [v for xy in HAND_ANCHORS for v in xy]
    geometry = [np.asarray(a, dtype=np.float64).ravel() for a in (s.ends, s.seg_normal, s.local, s.local_normals)]
    groups = [np.array(tongue), np.array(coupling), np.array(solver), np.array(anchors), *geometry, np.array(jaw)]
    starts = np.cumsum([0] + [len(g) for g in groups])
    assert [int(x) for x in starts[1:7]] == [x.value for x in (_COUPLING, _SOLVER, _ANCHORS, _ENDS, _SEG_NORMAL, _LOCAL)]
    return tuple(float(x) for x in np.concatenate(groups))


@triton.jit
def _k(C: tl.constexpr, i: tl.constexpr):
    """Constant ``i`` of :func:`constants`' layout, a float64 literal in the compiled kernel."""
    return tl.full((), C[i], tl.float64)


@triton.jit
def _pick(C: tl.constexpr, start: tl.constexpr, j, count: tl.constexpr):
    """Constant ``start + 2 j`` (a point's coordinate) for ``j`` below ``count``: a constant, or one index a
    device, then picked among the ``count`` literals."""
    value = _k(C, start)
    for m in tl.static_range(1, count):
        value = tl.where(j == m, _k(C, start + 2 * m), value)
    return value


@triton.jit
def _clip(x, low, high):
    return tl.where(x < low, low, tl.where(x > high, high, x))


@triton.jit
def _max0(x):
    return tl.where(x > 0.0, x, 0.0)


@triton.jit
def _closest_t(ax, ay, bx, by):
    dx, dy = bx - ax, by - ay
    d2 = dx * dx + dy * dy
    zero = d2 == 0.0
    q = (dx * (ax + bx) + dy * (ay + by)) / tl.where(zero, 1.0, d2)     # 0/0 kept out, same bits elsewhere
    return tl.where(zero, 0.0, -_clip(q, -1.0, 1.0))


@triton.jit
def _lerp_t(ax, ay, bx, by, t):
    ht = 0.5 * t
    return ax * (0.5 - ht) + bx * (0.5 + ht), ay * (0.5 - ht) + by * (0.5 + ht)


@triton.jit
def _vertex(C: tl.constexpr, j, ca, sa, px, py, V: tl.constexpr):
    """The blade's vertex ``j`` (a constant or one index a device) in the world."""
    lx, ly = _pick(C, _LOCAL, j, V), _pick(C, _LOCAL + 1, j, V)
    return (ca * lx + -sa * ly) + px, (sa * lx + ca * ly) + py


@triton.jit
def _normal(C: tl.constexpr, j, ca, sa, V: tl.constexpr):
    """The plane normal of the blade's vertex ``j`` in the world."""
    lx, ly = _pick(C, _LOCAL + 2 * V, j, V), _pick(C, _LOCAL + 2 * V + 1, j, V)
    return ca * lx + -sa * ly, sa * lx + ca * ly


@triton.jit
def _end(C: tl.constexpr, i):
    """End ``i`` (0 or 1) of the incisors' segment."""
    return _pick(C, _ENDS, i, 2), _pick(C, _ENDS + 1, i, 2)


@triton.jit
def _point(C: tl.constexpr, i, j, ca, sa, px, py, V: tl.constexpr):
    """The difference's point (blade vertex ``j``) - (segment end ``i``)."""
    vx, vy = _vertex(C, j, ca, sa, px, py, V)
    ex, ey = _end(C, i)
    return vx - ex, vy - ey


@triton.jit
def _candidate(k, V: tl.constexpr):
    """:func:`.warp_kernel.candidate`: (segment end, blade vertex) at the start and the end of candidate edge
    ``k`` of the difference (a constant, or one index a device)."""
    edge = k < 2 * V
    return (tl.where(edge, k // V, 0), tl.where(edge, k % V, k - 2 * V),
            tl.where(edge, k // V, 1), tl.where(edge, (k % V + 1) % V, k - 2 * V))


@triton.jit
def _hull_side(C: tl.constexpr, ax, ay, bx, by, ca, sa, px, py, V: tl.constexpr):
    """:func:`.warp_kernel.hull_side`: 1 (every point of the difference on the left of ``a -> b``), -1 (right)
    or 0 (points on both sides: not a hull edge)."""
    ex, ey = bx - ax, by - ay
    left = tl.full(px.shape, 1, tl.int1)
    right = left
    for i in tl.static_range(2):
        for j in tl.static_range(V):
            qx, qy = _point(C, i, j, ca, sa, px, py, V)
            side = ex * (qy - ay) - ey * (qx - ax)
            left, right = left & (side >= 0.0), right & (side <= 0.0)
    return tl.where(left, 1, tl.where(right, -1, 0))


@triton.jit
def _collide(C: tl.constexpr, ca, sa, px, py, V: tl.constexpr):
    """:func:`.warp_kernel.collide` for every device of the program: the normal, which contacts exist, their
    points (on the segment, on the blade) and features."""
    radius, tiny, far = _k(C, _SOLVER), _k(C, _SOLVER + 5), _k(C, _SOLVER + 8)
    zero = tl.zeros(px.shape, tl.float64)
    none = tl.zeros(px.shape, tl.int32)
    # One pass over the candidates finds whether the origin is inside the hull (warp_kernel.cores_overlap)
    # and the nearest candidate for either answer, so each hull side is computed once: inside, the
    # nearest hull edge and its side; outside, the nearest of all and its direction. A search that
    # finds none keeps its distance at infinity (d < far is false for inf and nan).
    inside = tl.full(px.shape, 1, tl.int1)
    in_d, in_left, in_k = zero + far, none, none
    out_d, out_px, out_py, out_dx, out_dy, out_k = zero + far, zero, zero, zero, zero, none
    for k in tl.static_range(3 * V):
        ia, ja, ib, jb = _candidate(k, V)
        ax, ay = _point(C, ia, ja, ca, sa, px, py, V)
        bx, by = _point(C, ib, jb, ca, sa, px, py, V)
        side = _hull_side(C, ax, ay, bx, by, ca, sa, px, py, V)
        origin = (bx - ax) * -ay - (by - ay) * -ax
        inside = inside & ~(((side == 1) & ~(origin > 0.0)) | ((side == -1) & ~(origin < 0.0)))
        t = _closest_t(ax, ay, bx, by)
        qx, qy = _lerp_t(ax, ay, bx, by, t)
        d = qx * qx + qy * qy
        better = (side != 0) & (d < in_d)                # inside the hull only hull edges; the first of equals
        in_d, in_left, in_k = tl.where(better, d, in_d), tl.where(better, side, in_left), tl.where(better, k, in_k)
        better = d < out_d
        out_d, out_px, out_py = tl.where(better, d, out_d), tl.where(better, qx, out_px), tl.where(better, qy, out_py)
        out_dx, out_dy = tl.where(better, bx - ax, out_dx), tl.where(better, by - ay, out_dy)
        out_k = tl.where(better, k, out_k)
    flip = tl.where(inside, in_left == 1, out_dy * out_px + -out_dx * out_py < 0.0)
    found = tl.where(inside, in_d, out_d) < far           # else the kernel's first guess, all indices 0
    ia, ja, ib, jb = _candidate(tl.where(inside, in_k, out_k), V)
    ia, ja, ib, jb = tl.where(found, ia, 0), tl.where(found, ja, 0), tl.where(found, ib, 0), tl.where(found, jb, 0)
    m0x, m0y = _point(C, tl.where(flip, ib, ia), tl.where(flip, jb, ja), ca, sa, px, py, V)
    m1x, m1y = _point(C, tl.where(flip, ia, ib), tl.where(flip, ja, jb), ca, sa, px, py, V)
    # ClosestPointsNew
    t = _closest_t(m0x, m0y, m1x, m1y)
    qx, qy = _lerp_t(m0x, m0y, m1x, m1y, t)
    rx, ry = m1y - m0y, -(m1x - m0x)
    inv = 1.0 / (tl.sqrt(rx * rx + ry * ry) + tiny)
    nx, ny = rx * inv, ry * inv
    d = nx * qx + ny * qy
    pair = ~((d <= 0.0) | ((-1.0 < t) & (t < 1.0)))    # a vertex pair
    d2 = tl.sqrt(qx * qx + qy * qy)
    inv = 1.0 / (d2 + tiny)
    nx, ny, d = tl.where(pair, qx * inv, nx), tl.where(pair, qy * inv, ny), tl.where(pair, d2, d)
    # SupportEdgeForSegment(seg, n) and SupportEdgeForPoly(poly, -n)
    forward = _k(C, _SEG_NORMAL) * nx + _k(C, _SEG_NORMAL + 1) * ny > 0.0
    s_a, s_b = tl.where(forward, 0, 1), tl.where(forward, 1, 0)
    bx, by = -nx, -ny
    vx, vy = _vertex(C, 0, ca, sa, px, py, V)
    i1p, top = none, vx * bx + vy * by
    for j in tl.static_range(1, V):
        vx, vy = _vertex(C, j, ca, sa, px, py, V)
        v = vx * bx + vy * by
        i1p, top = tl.where(v > top, j, i1p), tl.where(v > top, v, top)    # the first of equals
    i0p, i2p = (i1p - 1 + V) % V, (i1p + 1) % V
    n1x, n1y = _normal(C, i1p, ca, sa, V)
    n2x, n2y = _normal(C, i2p, ca, sa, V)
    keep = bx * n1x + by * n1y > bx * n2x + by * n2y
    q_a, q_b = tl.where(keep, i0p, i1p), tl.where(keep, i1p, i2p)
    # ContactPoints (the blade has no radius)
    touching = ((d - radius) - 0.0 <= 0.0) & (d <= radius + 0.0)
    sax, say = _end(C, s_a)
    sbx, sby = _end(C, s_b)
    qax, qay = _vertex(C, q_a, ca, sa, px, py, V)
    qbx, qby = _vertex(C, q_b, ca, sa, px, py, V)
    d1a, d1b = sax * ny - say * nx, sbx * ny - sby * nx
    d2a, d2b = qax * ny - qay * nx, qbx * ny - qby * nx
    e1_denom = 1.0 / (d1b - d1a + tiny)
    e2_denom = 1.0 / (d2b - d2a + tiny)
    u = _clip((d2b - d1a) * e1_denom, 0.0, 1.0)
    v = _clip((d1a - d2a) * e2_denom, 0.0, 1.0)
    p1x0, p1y0 = nx * radius + (sax * (1.0 - u) + sbx * u), ny * radius + (say * (1.0 - u) + sby * u)
    p2x0, p2y0 = nx * -0.0 + (qax * (1.0 - v) + qbx * v), ny * -0.0 + (qay * (1.0 - v) + qby * v)
    exists0 = touching & ((p2x0 - p1x0) * nx + (p2y0 - p1y0) * ny <= 0.0)
    u = _clip((d2a - d1a) * e1_denom, 0.0, 1.0)
    v = _clip((d1b - d2a) * e2_denom, 0.0, 1.0)
    p1x1, p1y1 = nx * radius + (sax * (1.0 - u) + sbx * u), ny * radius + (say * (1.0 - u) + sby * u)
    p2x1, p2y1 = nx * -0.0 + (qax * (1.0 - v) + qbx * v), ny * -0.0 + (qay * (1.0 - v) + qby * v)
    exists1 = touching & ((p2x1 - p1x1) * nx + (p2y1 - p1y1) * ny <= 0.0)
    return (nx, ny, exists0, exists1, p1x0, p1y0, p2x0, p2y0, p1x1, p1y1, p2x1, p2y1,
            s_a, q_b, s_b, q_a)


@triton.jit
def _jaw(C: tl.constexpr, px, py, ca, sa, vx, vy, w, V: tl.constexpr):
    """:func:`.physics.jaw_force` for every device of the program."""
    hx, hy, tx, ty = _k(C, 18), _k(C, 19), _k(C, 20), _k(C, 21)
    jaw = _LOCAL + 4 * V
    jx, jy, radius, k_jaw, c_jaw = _k(C, jaw), _k(C, jaw + 1), _k(C, jaw + 2), _k(C, jaw + 3), _k(C, jaw + 4)
    ex = px + ca * hx - sa * hy
    ey = py + sa * hx + ca * hy
    dx = (px + ca * tx - sa * ty) - ex
    dy = (py + sa * tx + ca * ty) - ey
    t = ((jx - ex) * dx + (jy - ey) * dy) / (dx * dx + dy * dy)
    ux, uy = -sa, ca
    depth = radius - ((ex - jx) * ux + (ey - jy) * uy)
    rx = (ex + t * dx) - px
    ry = (ey + t * dy) - py
    approach = -((vx - w * ry) * ux + (vy + w * rx) * uy)
    F = tl.where((depth > 0.0) & (t >= 0.0) & (t <= 1.0), _max0(k_jaw * depth + c_jaw * approach), 0.0)
    fx = F * ux
    fy = F * uy
    return fx, fy, rx * fy - ry * fx


@triton.jit
def _tongue(C: tl.constexpr, loads, slopes, top, px, py, a, ca, sa, vx, vy, w, gx, gy, pitch, hvx, hvy, hw,
            lat_y, lat_v, hand_lat, anchor, hl, tfx, tfy, ttq):
    """:func:`.physics.tongue_substep_floats` for every device of the program."""
    R, h, inv_m, inv_I, h_over_m = _k(C, 0), _k(C, 1), _k(C, 2), _k(C, 3), _k(C, 4)
    k, cc, k_t, mu, k_ref = _k(C, 5), _k(C, 6), _k(C, 7), _k(C, 8), _k(C, 9)
    damping, step, inv_step = _k(C, 10), _k(C, 11), _k(C, 12)
    k_rot, c_rot, qa, qb = _k(C, 14), _k(C, 15), _k(C, 16), _k(C, 17)
    hx, hy, tx, ty = _k(C, 18), _k(C, 19), _k(C, 20), _k(C, 21)
    ex = px + ca * hx - sa * hy
    ey = py + sa * hx + ca * hy
    dx = (px + ca * tx - sa * ty) - ex
    dy = (py + sa * tx + ca * ty) - ey
    t = -(ex * dx + ey * dy) / (dx * dx + dy * dy)
    t = tl.where(t < 0.0, 0.0, tl.where(t > 1.0, 1.0, t))
    cx = ex + t * dx
    cy = ey + t * dy
    dist = tl.sqrt(cx * cx + cy * cy) + _k(C, _SOLVER + 6)
    touching = dist < R
    depth = R - dist
    nx = cx / dist
    ny = cy / dist
    rx = cx - px
    ry = cy - py
    approach = -((vx - w * ry) * nx + (vy + w * rx) * ny)
    rn = rx * ny - ry * nx
    inv_meff = inv_m + rn * rn * inv_I
    x = _max0(depth) * inv_step
    i = tl.where(x < top, x.to(tl.int32), top)
    slope = tl.load(slopes + i)
    law = tl.load(loads + i) + (depth - i.to(tl.float64) * step) * slope
    x = depth + h * approach
    x = _max0(x) * inv_step
    ahead = tl.load(slopes + tl.where(x < top, x.to(tl.int32), top))
    slope = tl.where(ahead > slope, ahead, slope)
    excess = _max0(slope - k_ref)
    stiff = excess * h + 2.0 * tl.sqrt(excess / inv_meff)
    qx, qy = ca * qa - sa * qb, sa * qa + ca * qb
    Fx = k * (gx - px - qx) + cc * (hvx - vx + w * qy)
    Fy = k * (gy - py - qy) + cc * (hvy - vy - w * qx)
    tau = qx * Fy - qy * Fx + k_rot * (pitch - a) + c_rot * (hw - w)
    push = -((Fx + tfx) * nx + (Fy + tfy) * ny) * inv_m - (tau + ttq) * rn * inv_I
    beta = stiff * h * inv_meff
    P = (law + (damping + stiff) * approach + stiff * h * push) / (1.0 + beta)
    P = tl.where(touching, _max0(P), 0.0)             # off the tongue P is 0
    fx = tl.where(touching, P * nx, 0.0)
    fy = tl.where(touching, P * ny, 0.0)
    torque = tl.where(touching, rx * fy - ry * fx, 0.0)
    k_s = tl.where(touching, k_t, 0.0)
    lat_v = (lat_v + h_over_m * (k * (hand_lat - lat_y) + cc * hl - k_s * (lat_y - anchor))) / (1.0 + h_over_m * cc)
    lat_y = lat_y + h * lat_v
    stuck = k_s * (lat_y - anchor)
    limit = mu * P
    Q = tl.where(stuck < -limit, -limit, tl.where(stuck > limit, limit, stuck))
    anchor = tl.where(touching, tl.where(Q != stuck, lat_y - Q / k_t, anchor), lat_y)
    return fx, fy, torque, P, Q, cx, cy, lat_y, lat_v, anchor


@triton.jit
def _prestep(C: tl.constexpr, anx, any_, px, py, vx, vy, w, p1x, p1y, p2x, p2y):
    """The pre-step of one contact (cpArbiterPreStep): its lever, masses, bias and bounce."""
    m_inv, i_inv, h = _k(C, _COUPLING), _k(C, _COUPLING + 1), _k(C, 1)
    slop, bias_coef = _k(C, _SOLVER + 2), _k(C, _SOLVER + 3)
    r1x, r1y = p1x - 0.0, p1y - 0.0
    r2x, r2y = p2x - px, p2y - py
    rcn = r2x * any_ - r2y * anx
    n_mass = 1.0 / (0.0 + (m_inv + i_inv * rcn * rcn))
    rct = r2x * anx - r2y * -any_
    t_mass = 1.0 / (0.0 + (m_inv + i_inv * rct * rct))
    dist = ((r2x - r1x) + px) * anx + ((r2y - r1y) + py) * any_
    low = dist + slop
    bias = -bias_coef * tl.where(0.0 < low, 0.0, low) / h
    bounce = ((vx + -r2y * w) * anx + (vy + r2x * w) * any_) * (0.0 * 0.0)
    return r2x, r2y, n_mass, t_mass, bias, bounce


@triton.jit
def _spring(C: tl.constexpr, s: tl.constexpr, cp, sp, gqx, gqy, px, py, gx, gy, vx, vy, w):
    """Spring ``s``'s explicit impulse: the new velocities and what its implicit damping reads."""
    m_inv, i_inv, h = _k(C, _COUPLING), _k(C, _COUPLING + 1), _k(C, 1)
    k_lin, c_lin = _k(C, _COUPLING + 4), _k(C, _COUPLING + 5)
    ax, ay = _k(C, _ANCHORS + 2 * s), _k(C, _ANCHORS + 1 + 2 * s)
    r1x, r1y = cp * ax + -sp * ay, sp * ax + cp * ay
    dx, dy = (px + gqx) - (gx + r1x), (py + gqy) - (gy + r1y)
    dist = tl.sqrt(dx * dx + dy * dy)
    inv = 1.0 / dist
    nx, ny = dx * inv, dy * inv
    rcn = gqx * ny - gqy * nx
    kk = m_inv + i_inv * rcn * rcn
    j = (_k(C, _SOLVER + 7) - dist) * k_lin * h
    vx, vy = vx + nx * j * m_inv, vy + ny * j * m_inv
    w = w + i_inv * (gqx * (ny * j) - gqy * (nx * j))
    return vx, vy, w, r1x, r1y, nx, ny, 1.0 / kk, 1.0 - tl.exp(-c_lin * h * kk), j


@triton.jit
def _contact_impulse(C: tl.constexpr, on, rx, ry, n_mass, t_mass, bias, bounce, j_bias, jn, jt, anx, any_,
                     vx, vy, w, bvx, bvy, bw):
    """One iteration of one contact's impulse (cpArbiterApplyImpulse), where ``on``."""
    m_inv, i_inv, friction = _k(C, _COUPLING), _k(C, _COUPLING + 1), _k(C, _SOLVER + 1)
    vbn = (bvx + -ry * bw) * anx + (bvy + rx * bw) * any_
    vr_x, vr_y = vx + -ry * w, vy + rx * w
    vrn = vr_x * anx + vr_y * any_
    vrt = vr_x * -any_ + vr_y * anx
    jbn = (bias - vbn) * n_mass
    jb = _max0(j_bias + jbn)
    jn_acc = _max0(jn + -(bounce + vrn) * n_mass)
    jt_max = friction * jn_acc
    x = jt + -vrt * t_mass
    x = tl.where(x > -jt_max, x, -jt_max)
    jt_acc = tl.where(x < jt_max, x, jt_max)
    bx, by = anx * (jb - j_bias), any_ * (jb - j_bias)
    dn, dt = jn_acc - jn, jt_acc - jt
    jx, jy = anx * dn - any_ * dt, anx * dt + any_ * dn
    new_bvx, new_bvy = bvx + bx * m_inv, bvy + by * m_inv
    new_bw = bw + i_inv * (rx * by - ry * bx)
    new_vx, new_vy = vx + jx * m_inv, vy + jy * m_inv
    new_w = w + i_inv * (rx * jy - ry * jx)
    return (tl.where(on, new_vx, vx), tl.where(on, new_vy, vy), tl.where(on, new_w, w),
            tl.where(on, new_bvx, bvx), tl.where(on, new_bvy, bvy), tl.where(on, new_bw, bw),
            tl.where(on, jb, j_bias), tl.where(on, jn_acc, jn), tl.where(on, jt_acc, jt))


@triton.jit
def _spring_damping(C: tl.constexpr, r1x, r1y, nx, ny, n_mass, v_coef, target, acc, gqx, gqy, hvx, hvy, hw, vx, vy, w):
    """One iteration of one spring's implicit damping."""
    m_inv, i_inv = _k(C, _COUPLING), _k(C, _COUPLING + 1)
    rel_x = (vx + -gqy * w) - (hvx + -r1y * hw)
    rel_y = (vy + gqx * w) - (hvy + r1x * hw)
    vrn = rel_x * nx + rel_y * ny
    v_damp = (target - vrn) * v_coef
    target = vrn + v_damp
    j = (acc + v_damp * n_mass) - acc
    acc = acc + j
    vx, vy = vx + nx * j * m_inv, vy + ny * j * m_inv
    w = w + i_inv * (gqx * (ny * j) - gqy * (nx * j))
    return vx, vy, w, target, acc


@triton.jit
def _control_period(blade, hand, lateral, hand_v, contact, incisor, command, n, count, loads, slopes, top,
                    iterations, persistence, C: tl.constexpr, V: tl.constexpr, JAW: tl.constexpr,
                    BLOCK_SIZE: tl.constexpr):
    """``count`` substeps of every device (the rows of the state tensors, updated in place) with the hands
    commanded at ``command`` ``(4, n)``: :func:`.warp_kernel.control_period`, one thread a device."""
    rows = tl.program_id(0) * BLOCK_SIZE + tl.arange(0, BLOCK_SIZE)
    live = rows < n
    px, py, a = tl.load(blade + 6 * rows, live), tl.load(blade + 6 * rows + 1, live), tl.load(blade + 6 * rows + 2, live)
    vx, vy, w = tl.load(blade + 6 * rows + 3, live), tl.load(blade + 6 * rows + 4, live), tl.load(blade + 6 * rows + 5, live)
    gx, gy, pitch = tl.load(hand + 3 * rows, live), tl.load(hand + 3 * rows + 1, live), tl.load(hand + 3 * rows + 2, live)
    lat_y, lat_v = tl.load(lateral + 4 * rows, live), tl.load(lateral + 4 * rows + 1, live)
    hand_lat, anchor = tl.load(lateral + 4 * rows + 2, live), tl.load(lateral + 4 * rows + 3, live)
    vX, vY = tl.load(command + rows, live), tl.load(command + n + rows, live)
    spin, v_lat = tl.load(command + 2 * n + rows, live), tl.load(command + 3 * n + rows, live)
    h, m_inv, i_inv = _k(C, 1), _k(C, _COUPLING), _k(C, _COUPLING + 1)
    qx, qy = _k(C, _COUPLING + 2), _k(C, _COUPLING + 3)
    k_rot, c_rot, dt_coef = _k(C, _COUPLING + 6), _k(C, _COUPLING + 7), _k(C, _SOLVER + 4)
    i_sum = 1.0 / i_inv
    w_coef = 1.0 - tl.exp(-c_rot * h * i_inv)
    zero = tl.zeros([BLOCK_SIZE], tl.float64)
    no = tl.zeros([BLOCK_SIZE], tl.int1)
    none = tl.zeros([BLOCK_SIZE], tl.int32)
    # the arbiter with the incisors: it starts empty at every period (no contact state crosses one)
    alive, ticks = no, none
    ex0, ex1, f00, f01, f10, f11 = no, no, none, none, none, none
    jn0, jn1, jt0, jt1 = zero, zero, zero, zero
    bvx, bvy, bw, impulse = zero, zero, zero, zero
    tfx, tfy, ttq = zero, zero, zero                     # the incisors' push on the blade, last substep
    hvx, hvy, hw, hl, P, Q, cx, cy = zero, zero, zero, zero, zero, zero, zero, zero
    ca, sa = tl.cos(a), tl.sin(a)
    for _ in range(count):
        hvx = _clip(vX, (_k(C, 22) - gx) / h, (_k(C, 26) - gx) / h)
        hvy = _clip(vY, (_k(C, 23) - gy) / h, (_k(C, 27) - gy) / h)
        hw = _clip(spin, (_k(C, 24) - pitch) / h, (_k(C, 28) - pitch) / h)
        hl = _clip(v_lat, (_k(C, 25) - hand_lat) / h, (_k(C, 29) - hand_lat) / h)
        hand_lat = hand_lat + h * hl
        if JAW:                                          # the jaw's push now, with the incisors' last
            jfx, jfy, jtq = _jaw(C, px, py, ca, sa, vx, vy, w, V)
            fx, fy, torque, P, Q, cx, cy, lat_y, lat_v, anchor = _tongue(
                C, loads, slopes, top, px, py, a, ca, sa, vx, vy, w, gx, gy, pitch, hvx, hvy, hw,
                lat_y, lat_v, hand_lat, anchor, hl, tfx + jfx, tfy + jfy, ttq + jtq)
            fx, fy, torque = fx + jfx, fy + jfy, torque + jtq
        else:
            fx, fy, torque, P, Q, cx, cy, lat_y, lat_v, anchor = _tongue(
                C, loads, slopes, top, px, py, a, ca, sa, vx, vy, w, gx, gy, pitch, hvx, hvy, hw,
                lat_y, lat_v, hand_lat, anchor, hl, tfx, tfy, ttq)
        # cpSpaceStep: 1. positions, spending the contact's bias velocities
        gx, gy, pitch = gx + hvx * h, gy + hvy * h, pitch + hw * h
        px, py, a = px + (vx + bvx) * h, py + (vy + bvy) * h, a + (w + bw) * h
        bvx, bvy, bw = zero, zero, zero
        ca, sa, cp, sp = tl.cos(a), tl.sin(a), tl.cos(pitch), tl.sin(pitch)
        # collide, update the arbiter (cpArbiterUpdate), pre-step its contacts
        (nnx, nny, new0, new1, p1x0, p1y0, p2x0, p2y0, p1x1, p1y1, p2x1, p2y1,
         g00, g01, g10, g11) = _collide(C, ca, sa, px, py, V)
        touching = new0 | new1
        # a new contact keeps the impulses of an old one with its features (the later old one wins)
        same00 = alive & ex0 & (g00 == f00) & (g01 == f01)
        same01 = alive & ex1 & (g00 == f10) & (g01 == f11)
        same10 = alive & ex0 & (g10 == f00) & (g11 == f01)
        same11 = alive & ex1 & (g10 == f10) & (g11 == f11)
        jn_new0 = tl.where(same01, jn1, tl.where(same00, jn0, zero))
        jt_new0 = tl.where(same01, jt1, tl.where(same00, jt0, zero))
        jn_new1 = tl.where(same11, jn1, tl.where(same10, jn0, zero))
        jt_new1 = tl.where(same11, jt1, tl.where(same10, jt0, zero))
        first = touching & ~(alive & (ticks == 0))
        ticks = tl.where(touching, 0, ticks + 1)
        alive = touching | (alive & (ticks < persistence))
        # the arbiter's normal and pre-step: read only while touching
        ex0, ex1 = tl.where(touching, new0, ex0), tl.where(touching, new1, ex1)
        f00, f01 = tl.where(touching, g00, f00), tl.where(touching, g01, f01)
        f10, f11 = tl.where(touching, g10, f10), tl.where(touching, g11, f11)
        jn0, jt0 = tl.where(touching, jn_new0, jn0), tl.where(touching, jt_new0, jt0)
        jn1, jt1 = tl.where(touching, jn_new1, jn1), tl.where(touching, jt_new1, jt1)
        # the normal and the pre-step are read only where touching, so they are not carried from the
        # substep before (the Warp kernel keeps them; a device not touching never reads them)
        anx, any_ = nnx, nny
        r2x0, r2y0, n_mass0, t_mass0, bias0, bounce0 = _prestep(C, anx, any_, px, py, vx, vy, w,
                                                                p1x0, p1y0, p2x0, p2y0)
        r2x1, r2y1, n_mass1, t_mass1, bias1, bounce1 = _prestep(C, anx, any_, px, py, vx, vy, w,
                                                                p1x1, p1y1, p2x1, p2y1)
        j_bias0, j_bias1 = zero, zero
        # 2. the springs' explicit impulses
        gqx, gqy = ca * qx + -sa * qy, sa * qx + ca * qy
        vx, vy, w, s_r1x0, s_r1y0, s_nx0, s_ny0, s_mass0, s_coef0, s_acc0 = _spring(
            C, 0, cp, sp, gqx, gqy, px, py, gx, gy, vx, vy, w)
        vx, vy, w, s_r1x1, s_r1y1, s_nx1, s_ny1, s_mass1, s_coef1, s_acc1 = _spring(
            C, 1, cp, sp, gqx, gqy, px, py, gx, gy, vx, vy, w)
        s_target0, s_target1 = zero, zero
        j_rot = ((pitch - a) - 0.0) * k_rot * h
        w = w + j_rot * i_inv
        target_wrn = zero
        # 3. velocities
        vx, vy = vx * 1.0 + (0.0 + fx * m_inv) * h, vy * 1.0 + (0.0 + fy * m_inv) * h
        w = w * 1.0 + torque * i_inv * h
        cached = touching & ~first                        # cpArbiterApplyCachedImpulse
        jx, jy = (anx * jn0 - any_ * jt0) * dt_coef, (anx * jt0 + any_ * jn0) * dt_coef
        on = cached & ex0
        vx, vy = tl.where(on, vx + jx * m_inv, vx), tl.where(on, vy + jy * m_inv, vy)
        w = tl.where(on, w + i_inv * (r2x0 * jy - r2y0 * jx), w)
        jx, jy = (anx * jn1 - any_ * jt1) * dt_coef, (anx * jt1 + any_ * jn1) * dt_coef
        on = cached & ex1
        vx, vy = tl.where(on, vx + jx * m_inv, vx), tl.where(on, vy + jy * m_inv, vy)
        w = tl.where(on, w + i_inv * (r2x1 * jy - r2y1 * jx), w)
        # 4. the implicit impulses: the contact's, then the springs' in the order added
        for _pass in range(iterations):
            vx, vy, w, bvx, bvy, bw, j_bias0, jn0, jt0 = _contact_impulse(
                C, touching & ex0, r2x0, r2y0, n_mass0, t_mass0, bias0, bounce0, j_bias0, jn0, jt0, anx, any_,
                vx, vy, w, bvx, bvy, bw)
            vx, vy, w, bvx, bvy, bw, j_bias1, jn1, jt1 = _contact_impulse(
                C, touching & ex1, r2x1, r2y1, n_mass1, t_mass1, bias1, bounce1, j_bias1, jn1, jt1, anx, any_,
                vx, vy, w, bvx, bvy, bw)
            vx, vy, w, s_target0, s_acc0 = _spring_damping(C, s_r1x0, s_r1y0, s_nx0, s_ny0, s_mass0, s_coef0,
                                                           s_target0, s_acc0, gqx, gqy, hvx, hvy, hw, vx, vy, w)
            vx, vy, w, s_target1, s_acc1 = _spring_damping(C, s_r1x1, s_r1y1, s_nx1, s_ny1, s_mass1, s_coef1,
                                                           s_target1, s_acc1, gqx, gqy, hvx, hvy, hw, vx, vy, w)
            wrn = hw - w
            w_damp = (target_wrn - wrn) * w_coef
            target_wrn = wrn + w_damp
            j = j_rot - (j_rot - w_damp * i_sum)
            j_rot = j_rot - j
            w = w - j * i_inv
        # the incisors' total impulse this substep (cpArbiterTotalImpulse)
        tx = tl.where(ex0, zero + (anx * jn0 - any_ * jt0), zero)
        ty = tl.where(ex0, zero + (anx * jt0 + any_ * jn0), zero)
        tx = tl.where(ex1, tx + (anx * jn1 - any_ * jt1), tx)
        ty = tl.where(ex1, ty + (anx * jt1 + any_ * jn1), ty)
        solved = alive & (ticks == 0)
        impulse = tl.where(solved, impulse + tl.sqrt(tx * tx + ty * ty), impulse)
        # the incisors' force and torque on the blade, for the next substep (physics.teeth_force)
        jx, jy = anx * jn0 - any_ * jt0, anx * jt0 + any_ * jn0
        tfx = tl.where(ex0, zero + jx, zero)
        tfy = tl.where(ex0, zero + jy, zero)
        ttq = tl.where(ex0, zero + (r2x0 * jy - r2y0 * jx), zero)
        jx, jy = anx * jn1 - any_ * jt1, anx * jt1 + any_ * jn1
        tfx = tl.where(ex1, tfx + jx, tfx)
        tfy = tl.where(ex1, tfy + jy, tfy)
        ttq = tl.where(ex1, ttq + (r2x1 * jy - r2y1 * jx), ttq)
        tfx = tl.where(solved, tfx / h, zero)
        tfy = tl.where(solved, tfy / h, zero)
        ttq = tl.where(solved, ttq / h, zero)
    tl.store(blade + 6 * rows, px, live)
    tl.store(blade + 6 * rows + 1, py, live)
    tl.store(blade + 6 * rows + 2, a, live)
    tl.store(blade + 6 * rows + 3, vx, live)
    tl.store(blade + 6 * rows + 4, vy, live)
    tl.store(blade + 6 * rows + 5, w, live)
    tl.store(hand + 3 * rows, gx, live)
    tl.store(hand + 3 * rows + 1, gy, live)
    tl.store(hand + 3 * rows + 2, pitch, live)
    tl.store(lateral + 4 * rows, lat_y, live)
    tl.store(lateral + 4 * rows + 1, lat_v, live)
    tl.store(lateral + 4 * rows + 2, hand_lat, live)
    tl.store(lateral + 4 * rows + 3, anchor, live)
    tl.store(hand_v + 4 * rows, hvx, live)
    tl.store(hand_v + 4 * rows + 1, hvy, live)
    tl.store(hand_v + 4 * rows + 2, hw, live)
    tl.store(hand_v + 4 * rows + 3, hl, live)
    tl.store(contact + 4 * rows, P, live)
    tl.store(contact + 4 * rows + 1, Q, live)
    tl.store(contact + 4 * rows + 2, cx, live)
    tl.store(contact + 4 * rows + 3, cy, live)
    tl.store(incisor + rows, impulse / (count * h), live)


class LaryngoscopeFused(LaryngoscopeTensors):
    """:class:`~.tensors.LaryngoscopeTensors` with each control period run by one Triton kernel
    (:func:`_control_period`), the state updated in place: the same state and readings, one launch a
    step. Triton compiles the kernel at its first launch for a scene's constants (cached on disk by Triton)."""

    def __init__(self, params: LaryngoscopeParams, contact: TongueContact, n: int,
                 torch_device: torch.device | str = "cpu") -> None:
        super().__init__(params, contact, n, torch_device)
        self._constants = constants(self)
        self._loads, self._slopes = (x.contiguous() for x in (self._loads, self._slopes))
        self._top = int(self.c.top)
        self._vertices = int(self.incisors.local.shape[0])
        # Triton's options for the kernel: keep enable_fp_fusion off; softenv bench tries register caps (maxnreg)
        self.launch_options: dict[str, Any] = dict(COMPILE_OPTIONS)

    def kernel_arguments(self, command: torch.Tensor, count: int) -> dict[str, Any]:
        """What :func:`_control_period` is launched with for ``count`` substeps at ``command`` ``(4, n)``
        (``scripts/fused_kernel_profile.py`` compiles it with the same, for a GPU it does not have)."""
        return dict(blade=self._blade, hand=self._hand, lateral=self._lateral, hand_v=self._hand_v,
                    contact=self._contact, incisor=self._incisor, command=command, n=self.n, count=count,
                    loads=self._loads, slopes=self._slopes, top=self._top, iterations=SOLVER_ITERATIONS,
                    persistence=PERSISTENCE, C=self._constants, V=self._vertices, JAW=self.c.jaw is not None,
                    BLOCK_SIZE=BLOCK)

    def substeps(self, vX: Any, vY: Any, spin: Any, v_lat: Any, count: int) -> None:
        command = torch.stack(torch.broadcast_tensors(vX, vY, spin, v_lat)).to(torch.float64).contiguous()
        _control_period[(triton.cdiv(self.n, BLOCK),)](**self.kernel_arguments(command, count), **self.launch_options)
        self._forget()
