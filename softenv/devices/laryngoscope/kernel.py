"""The array engine's control period compiled for one device at a time (numba): the float twin of
:mod:`.rigid` and :mod:`.incisors`, with the tongue's substep (:func:`~.physics.tongue_substep_floats`)
compiled from its own source.

numpy spends a substep of :class:`~.batch.LaryngoscopeArrays` in some five hundred calls on short
arrays, so its speed is set by the count of calls, not by the batch; a loop over the devices, each
running its whole period (some 20 substeps) in registers, is ten times faster (figures in
``docs/laryngoscope.md``). The loop runs Chipmunk's expressions as :func:`~.rigid.coupling_step` and
:mod:`.incisors` write them, the same IEEE operations in the same order (no fast-math, no fused
multiply-add), and ``tests/test_laryngoscope_arrays.py`` holds every device of
:class:`LaryngoscopeKernel` to a single pymunk device bit for bit. Where a blade without contact lies
clear of the incisors, the collision is skipped (:func:`_separated`).

numba compiles on the first call in a process (10-16 s on a 2-core VM), without a disk cache: numba's
cache tracks the source file of the function it caches, not those of the functions it calls
(:func:`~.physics.tongue_substep_floats`), so a cached kernel could outlive a change to them.

No contact state crosses a control period (:mod:`.space`): each device's arbiter with the incisors
and its bias velocity start empty at every call, so the kernel keeps them in local variables.
"""

from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import astuple, fields
from typing import Any

import numba
import numpy as np

from ..contact import TongueContact
from .batch import LaryngoscopeArrays
from .incisors import PERSISTENCE, TINY
from .params import SPRING_LENGTH, LaryngoscopeParams
from .physics import Constants, tongue_substep_floats
from .rigid import HAND_ANCHORS, Coupling
from .space import SOLVER_ITERATIONS

SubstepConstants = namedtuple("SubstepConstants", [f.name for f in fields(Constants)])  # type: ignore[misc]  # numba reads namedtuples

_tongue_substep: Any = numba.njit(tongue_substep_floats)


def substep_tuple(c: Constants) -> tuple[Any, ...]:
    """:class:`~.physics.Constants` as the kernel reads them (a namedtuple of floats, ints and tuples)."""
    return SubstepConstants(*(tuple(float(v) for v in x) if isinstance(x, tuple) else x for x in astuple(c)))


def coupling_tuple(c: Coupling) -> tuple[float, ...]:
    """:class:`~.rigid.Coupling` as the kernel reads it."""
    return (c.m_inv, c.i_inv, c.grip[0], c.grip[1], c.k, c.c, c.k_rot, c.c_rot)


@numba.njit(inline="always")
def _clip(x: float, low: float, high: float) -> float:
    return low if x < low else (high if x > high else x)


@numba.njit(inline="always")
def _closest_t(ax: float, ay: float, bx: float, by: float) -> float:
    dx, dy = bx - ax, by - ay
    d2 = dx * dx + dy * dy
    if d2 == 0.0:
        return 0.0
    return -_clip((dx * (ax + bx) + dy * (ay + by)) / d2, -1.0, 1.0)


@numba.njit(inline="always")
def _lerp_t(ax: float, ay: float, bx: float, by: float, t: float) -> tuple[float, float]:
    ht = 0.5 * t
    return ax * (0.5 - ht) + bx * (0.5 + ht), ay * (0.5 - ht) + by * (0.5 + ht)


@numba.njit(inline="always")
def _separated(ends: np.ndarray, radius: float, vw: np.ndarray, nw: np.ndarray) -> bool:
    """Whether the segment's two ends lie further than ``radius`` (and a margin far above rounding)
    outside one of the blade's edges: the blade, convex, then clears the rounded segment, and
    :func:`_collide` would find no contact."""
    gap = radius * (1.0 + 1e-9) + 1e-12
    for j in range(vw.shape[0]):
        nx, ny = nw[j, 0], nw[j, 1]
        plane = nx * vw[j, 0] + ny * vw[j, 1]
        if nx * ends[0, 0] + ny * ends[0, 1] - plane > gap and nx * ends[1, 0] + ny * ends[1, 1] - plane > gap:
            return True
    return False


@numba.njit(inline="always")
def _candidate(k: int, count: int) -> tuple[int, int, int, int]:
    """Candidate edge ``k`` of the difference: (segment end, blade vertex) at its start and its end."""
    if k < 2 * count:
        return k // count, k % count, k // count, (k % count + 1) % count
    return 0, k - 2 * count, 1, k - 2 * count


@numba.njit(inline="always")
def _hull_side(ax: float, ay: float, bx: float, by: float, ends: np.ndarray, vw: np.ndarray) -> int:
    """:func:`.incisors._hull_sides` for the edge ``a -> b``: 1 (every point of the difference on its left),
    -1 (right) or 0 (points on both sides: not a hull edge)."""
    ex, ey = bx - ax, by - ay
    left = right = True
    for i in range(2):
        for j in range(vw.shape[0]):
            side = ex * ((vw[j, 1] - ends[i, 1]) - ay) - ey * ((vw[j, 0] - ends[i, 0]) - ax)
            left &= side >= 0.0
            right &= side <= 0.0
    return 1 if left else (-1 if right else 0)


@numba.njit
def _cores_overlap(ends: np.ndarray, vw: np.ndarray, sides: np.ndarray) -> bool:
    """Whether the origin lies strictly inside the difference's hull (:func:`.incisors._hull_sides`); when
    it does, every candidate's :func:`_hull_side` is left in ``sides``."""
    count = vw.shape[0]
    for k in range(3 * count):
        ia, ja, ib, jb = _candidate(k, count)
        ax, ay = vw[ja, 0] - ends[ia, 0], vw[ja, 1] - ends[ia, 1]
        bx, by = vw[jb, 0] - ends[ib, 0], vw[jb, 1] - ends[ib, 1]
        left = sides[k] = _hull_side(ax, ay, bx, by, ends, vw)
        origin = (bx - ax) * -ay - (by - ay) * -ax
        if (left == 1 and not origin > 0.0) or (left == -1 and not origin < 0.0):
            return False
    return True


@numba.njit
def _collide(ends: np.ndarray, seg_normal: np.ndarray, radius: float, vw: np.ndarray, nw: np.ndarray,
             out: np.ndarray, feat: np.ndarray, sides: np.ndarray) -> tuple[float, float, bool, bool]:
    """:func:`.incisors.collide` for one blade at world vertices ``vw`` and plane normals ``nw``: writes
    the two contacts' points on the segment and on the blade to ``out`` ``(2, 4)`` and their features
    to ``feat`` ``(2, 2)`` (``sides``: room for each candidate edge's hull side); returns the normal and which
    contacts exist."""
    count = vw.shape[0]
    inside = _cores_overlap(ends, vw, sides)
    best_d, best_px, best_py, e_dx, e_dy, best_left = np.inf, 0.0, 0.0, 0.0, 0.0, 0
    best_ia = best_ja = best_ib = best_jb = 0
    for k in range(3 * count):
        ia, ja, ib, jb = _candidate(k, count)
        ax, ay = vw[ja, 0] - ends[ia, 0], vw[ja, 1] - ends[ia, 1]
        bx, by = vw[jb, 0] - ends[ib, 0], vw[jb, 1] - ends[ib, 1]
        left = sides[k] if inside else 0
        if inside and left == 0:                         # inside the hull: not where EPA ends
            continue
        t = _closest_t(ax, ay, bx, by)
        px, py = _lerp_t(ax, ay, bx, by, t)
        d = px * px + py * py
        if d < best_d:                                   # the first of equals, as argmin
            best_d, best_px, best_py, best_left = d, px, py, left
            best_ia, best_ja, best_ib, best_jb = ia, ja, ib, jb
            e_dx, e_dy = bx - ax, by - ay
    flip = best_left == 1 if inside else e_dy * best_px + -e_dx * best_py < 0.0
    i0, j0, i1, j1 = (best_ib, best_jb, best_ia, best_ja) if flip else (best_ia, best_ja, best_ib, best_jb)
    m0x, m0y = vw[j0, 0] - ends[i0, 0], vw[j0, 1] - ends[i0, 1]
    m1x, m1y = vw[j1, 0] - ends[i1, 0], vw[j1, 1] - ends[i1, 1]
    # ClosestPointsNew
    t = _closest_t(m0x, m0y, m1x, m1y)
    px, py = _lerp_t(m0x, m0y, m1x, m1y, t)
    rx, ry = m1y - m0y, -(m1x - m0x)
    inv = 1.0 / (math.sqrt(rx * rx + ry * ry) + TINY)
    nx, ny = rx * inv, ry * inv
    d = nx * px + ny * py
    if not (d <= 0.0 or (-1.0 < t and t < 1.0)):        # a vertex pair
        d2 = math.sqrt(px * px + py * py)
        inv = 1.0 / (d2 + TINY)
        nx, ny, d = px * inv, py * inv, d2
    # SupportEdgeForSegment(seg, n) and SupportEdgeForPoly(poly, -n)
    forward = seg_normal[0] * nx + seg_normal[1] * ny > 0.0
    sa, sb = (0, 1) if forward else (1, 0)
    bx, by = -nx, -ny
    i1p, top = 0, vw[0, 0] * bx + vw[0, 1] * by
    for j in range(1, count):
        v = vw[j, 0] * bx + vw[j, 1] * by
        if v > top:                                      # the first of equals, as argmax
            i1p, top = j, v
    i0p, i2p = (i1p - 1 + count) % count, (i1p + 1) % count
    keep = bx * nw[i1p, 0] + by * nw[i1p, 1] > bx * nw[i2p, 0] + by * nw[i2p, 1]
    qa, qb = (i0p, i1p) if keep else (i1p, i2p)
    # ContactPoints (the blade has no radius)
    touching = (d - radius) - 0.0 <= 0.0 and d <= radius + 0.0
    sax, say, sbx, sby = ends[sa, 0], ends[sa, 1], ends[sb, 0], ends[sb, 1]
    qax, qay, qbx, qby = vw[qa, 0], vw[qa, 1], vw[qb, 0], vw[qb, 1]
    d1a, d1b = sax * ny - say * nx, sbx * ny - sby * nx
    d2a, d2b = qax * ny - qay * nx, qbx * ny - qby * nx
    e1_denom = 1.0 / (d1b - d1a + TINY)
    e2_denom = 1.0 / (d2b - d2a + TINY)
    feat[0, 0], feat[0, 1], feat[1, 0], feat[1, 1] = sa, qb, sb, qa
    exists0 = exists1 = False
    for slot in range(2):
        first, second = (d2b - d1a, d1a - d2a) if slot == 0 else (d2a - d1a, d1b - d2a)
        u = _clip(first * e1_denom, 0.0, 1.0)
        v = _clip(second * e2_denom, 0.0, 1.0)
        p1x, p1y = nx * radius + (sax * (1.0 - u) + sbx * u), ny * radius + (say * (1.0 - u) + sby * u)
        p2x, p2y = nx * -0.0 + (qax * (1.0 - v) + qbx * v), ny * -0.0 + (qay * (1.0 - v) + qby * v)
        out[slot, 0], out[slot, 1], out[slot, 2], out[slot, 3] = p1x, p1y, p2x, p2y
        exists = touching and (p2x - p1x) * nx + (p2y - p1y) * ny <= 0.0
        if slot == 0:
            exists0 = exists
        else:
            exists1 = exists
    return nx, ny, exists0, exists1


@numba.njit
def control_period(blade: np.ndarray, hand: np.ndarray, lateral: np.ndarray, hand_v: np.ndarray,
                   contact: np.ndarray, incisor: np.ndarray, command: np.ndarray, count: int, c: Any,
                   loads: np.ndarray, slopes: np.ndarray, coupling: tuple[float, ...], local: np.ndarray,
                   local_normals: np.ndarray, ends: np.ndarray, seg_normal: np.ndarray, radius: float,
                   friction: float, slop: float, bias_coef: float, iterations: int, dt_coef: float) -> None:
    """``count`` substeps of every device (the rows of the state arrays, updated in place) with the
    hands commanded at ``command`` ``(4, n)``: :meth:`.batch.ArrayLaryngoscopes.substeps` with
    :class:`~.batch.LaryngoscopeArrays`' engine, one device after another."""
    h = c.h
    lo, hi = c.low, c.high
    m_inv, i_inv, qx, qy, k_lin, c_lin, k_rot, c_rot = coupling
    count_v = local.shape[0]
    i_sum = 1.0 / i_inv
    w_coef = 1.0 - math.exp(-c_rot * h * i_inv)
    vw, nw = np.empty((count_v, 2)), np.empty((count_v, 2))
    points, feat_new, sides = np.empty((2, 4)), np.empty((2, 2), dtype=np.int64), np.empty(3 * count_v, dtype=np.int64)
    feat = np.empty((2, 2), dtype=np.int64)
    jn, jt, jn_new, jt_new = np.empty(2), np.empty(2), np.empty(2), np.empty(2)
    r2x, r2y, n_mass, t_mass = np.empty(2), np.empty(2), np.empty(2), np.empty(2)
    bias, j_bias, bounce = np.empty(2), np.empty(2), np.empty(2)
    ex, ex_new = np.zeros(2, dtype=np.bool_), np.zeros(2, dtype=np.bool_)
    springs = np.empty((2, 8))         # r1x, r1y, nx, ny, n_mass, v_coef, target, jAcc
    for i in range(blade.shape[0]):
        px, py, a, vx, vy, w = blade[i, 0], blade[i, 1], blade[i, 2], blade[i, 3], blade[i, 4], blade[i, 5]
        gx, gy, pitch = hand[i, 0], hand[i, 1], hand[i, 2]
        lat_y, lat_v, hand_lat, anchor = lateral[i, 0], lateral[i, 1], lateral[i, 2], lateral[i, 3]
        vX, vY, spin, v_lat = command[0, i], command[1, i], command[2, i], command[3, i]
        alive, ticks, anx, any_ = False, 0, 0.0, 0.0
        ex[:] = False
        bvx = bvy = bw = 0.0
        impulse = 0.0
        hvx = hvy = hw = hl = P = Q = cx = cy = 0.0
        ca, sa = math.cos(a), math.sin(a)
        for _ in range(count):
            hvx = _clip(vX, (lo[0] - gx) / h, (hi[0] - gx) / h)
            hvy = _clip(vY, (lo[1] - gy) / h, (hi[1] - gy) / h)
            hw = _clip(spin, (lo[2] - pitch) / h, (hi[2] - pitch) / h)
            hl = _clip(v_lat, (lo[3] - hand_lat) / h, (hi[3] - hand_lat) / h)
            hand_lat = hand_lat + h * hl
            fx, fy, torque, P, Q, cx, cy, lat_y, lat_v, anchor = _tongue_substep(
                (px, py, a, ca, sa, vx, vy, w), (gx, gy, pitch, hvx, hvy, hw), (lat_y, lat_v, hand_lat, anchor), hl,
                loads, slopes, c)
            # rigid.coupling_step: 1. positions, spending the contact's bias velocities
            gx, gy, pitch = gx + hvx * h, gy + hvy * h, pitch + hw * h
            px, py, a = px + (vx + bvx) * h, py + (vy + bvy) * h, a + (w + bw) * h
            bvx = bvy = bw = 0.0
            ca, sa, cp, sp = math.cos(a), math.sin(a), math.cos(pitch), math.sin(pitch)    # the next tongue's too
            # incisors.prestep: collide, update the arbiter, pre-step its contacts
            for j in range(count_v):
                lx, ly = local[j, 0], local[j, 1]
                vw[j, 0], vw[j, 1] = (ca * lx + -sa * ly) + px, (sa * lx + ca * ly) + py
                lx, ly = local_normals[j, 0], local_normals[j, 1]
                nw[j, 0], nw[j, 1] = ca * lx + -sa * ly, sa * lx + ca * ly
            if not alive and _separated(ends, radius, vw, nw):
                touching = first = False        # no contact, no arbiter: only its age changes, as _collide's would
                ticks += 1
            else:
                nnx, nny, ex_new[0], ex_new[1] = _collide(ends, seg_normal, radius, vw, nw, points, feat_new, sides)
                touching = ex_new[0] or ex_new[1]
                jn_new[:], jt_new[:] = 0.0, 0.0
                for new in range(2):
                    for old in range(2):
                        if alive and ex[old] and feat_new[new, 0] == feat[old, 0] and feat_new[new, 1] == feat[old, 1]:
                            jn_new[new], jt_new[new] = jn[old], jt[old]
                first = touching and not (alive and ticks == 0)
                ticks = 0 if touching else ticks + 1
                alive = touching or (alive and ticks < PERSISTENCE)
                if touching:                    # the arbiter's normal and pre-step: read only while touching
                    ex[:], feat[:, :], jn[:], jt[:] = ex_new, feat_new, jn_new, jt_new
                    anx, any_ = nnx, nny
                    for s in range(2):
                        r1x, r1y = points[s, 0] - 0.0, points[s, 1] - 0.0
                        r2x[s], r2y[s] = points[s, 2] - px, points[s, 3] - py
                        rcn = r2x[s] * any_ - r2y[s] * anx
                        n_mass[s] = 1.0 / (0.0 + (m_inv + i_inv * rcn * rcn))
                        rct = r2x[s] * anx - r2y[s] * -any_
                        t_mass[s] = 1.0 / (0.0 + (m_inv + i_inv * rct * rct))
                        dist = ((r2x[s] - r1x) + px) * anx + ((r2y[s] - r1y) + py) * any_
                        low = dist + slop
                        bias[s] = -bias_coef * (0.0 if 0.0 < low else low) / h
                        j_bias[s] = 0.0
                        # incisors.bounce_velocity
                        bounce[s] = ((vx + -r2y[s] * w) * anx + (vy + r2x[s] * w) * any_) * (0.0 * 0.0)
            # 2. the springs' explicit impulses
            gqx, gqy = ca * qx + -sa * qy, sa * qx + ca * qy
            for s in range(2):
                ax, ay = HAND_ANCHORS[s]
                r1x, r1y = cp * ax + -sp * ay, sp * ax + cp * ay
                dx, dy = (px + gqx) - (gx + r1x), (py + gqy) - (gy + r1y)
                dist = math.sqrt(dx * dx + dy * dy)
                inv = 1.0 / dist
                nx, ny = dx * inv, dy * inv
                rcn = gqx * ny - gqy * nx
                kk = m_inv + i_inv * rcn * rcn
                j = (SPRING_LENGTH - dist) * k_lin * h
                vx, vy = vx + nx * j * m_inv, vy + ny * j * m_inv
                w = w + i_inv * (gqx * (ny * j) - gqy * (nx * j))
                springs[s, 0], springs[s, 1], springs[s, 2], springs[s, 3] = r1x, r1y, nx, ny
                springs[s, 4], springs[s, 5], springs[s, 6], springs[s, 7] = 1.0 / kk, 1.0 - math.exp(-c_lin * h * kk), 0.0, j
            j_rot = ((pitch - a) - 0.0) * k_rot * h
            w = w + j_rot * i_inv
            target_wrn = 0.0
            # 3. velocities
            vx, vy = vx * 1.0 + (0.0 + fx * m_inv) * h, vy * 1.0 + (0.0 + fy * m_inv) * h
            w = w * 1.0 + torque * i_inv * h
            for s in range(2):                           # incisors.apply_cached
                if touching and not first and ex[s]:
                    jx, jy = anx * jn[s] - any_ * jt[s], anx * jt[s] + any_ * jn[s]
                    jx, jy = jx * dt_coef, jy * dt_coef
                    vx, vy = vx + jx * m_inv, vy + jy * m_inv
                    w = w + i_inv * (r2x[s] * jy - r2y[s] * jx)
            # 4. the implicit impulses: the contact's, then the springs' in the order added
            for _pass in range(iterations):
                for s in range(2):                       # incisors.apply_impulse
                    if not (touching and ex[s]):
                        continue
                    rx, ry = r2x[s], r2y[s]
                    vbn = (bvx + -ry * bw) * anx + (bvy + rx * bw) * any_
                    vr_x, vr_y = vx + -ry * w, vy + rx * w
                    vrn = vr_x * anx + vr_y * any_
                    vrt = vr_x * -any_ + vr_y * anx
                    jbn = (bias[s] - vbn) * n_mass[s]
                    jbn_old = j_bias[s]
                    jb = jbn_old + jbn
                    jb = jb if jb > 0.0 else 0.0
                    jn_old = jn[s]
                    jn_acc = jn_old + -(bounce[s] + vrn) * n_mass[s]
                    jn_acc = jn_acc if jn_acc > 0.0 else 0.0
                    jt_max = friction * jn_acc
                    jt_old = jt[s]
                    x = jt_old + -vrt * t_mass[s]
                    x = x if x > -jt_max else -jt_max
                    jt_acc = x if x < jt_max else jt_max
                    bx, by = anx * (jb - jbn_old), any_ * (jb - jbn_old)
                    dn, dt = jn_acc - jn_old, jt_acc - jt_old
                    jx, jy = anx * dn - any_ * dt, anx * dt + any_ * dn
                    bvx, bvy = bvx + bx * m_inv, bvy + by * m_inv
                    bw = bw + i_inv * (rx * by - ry * bx)
                    vx, vy = vx + jx * m_inv, vy + jy * m_inv
                    w = w + i_inv * (rx * jy - ry * jx)
                    j_bias[s], jn[s], jt[s] = jb, jn_acc, jt_acc
                for s in range(2):
                    r1x, r1y, nx, ny = springs[s, 0], springs[s, 1], springs[s, 2], springs[s, 3]
                    rel_x = (vx + -gqy * w) - (hvx + -r1y * hw)
                    rel_y = (vy + gqx * w) - (hvy + r1x * hw)
                    vrn = rel_x * nx + rel_y * ny
                    v_damp = (springs[s, 6] - vrn) * springs[s, 5]
                    springs[s, 6] = vrn + v_damp
                    acc = springs[s, 7]
                    j = (acc + v_damp * springs[s, 4]) - acc
                    springs[s, 7] = acc + j
                    vx, vy = vx + nx * j * m_inv, vy + ny * j * m_inv
                    w = w + i_inv * (gqx * (ny * j) - gqy * (nx * j))
                wrn = hw - w
                w_damp = (target_wrn - wrn) * w_coef
                target_wrn = wrn + w_damp
                j = j_rot - (j_rot - w_damp * i_sum)
                j_rot = j_rot - j
                w = w - j * i_inv
            # the incisors' total impulse this substep (cpArbiterTotalImpulse)
            if alive and ticks == 0:
                tx = ty = 0.0
                for s in range(2):
                    if ex[s]:
                        tx, ty = tx + (anx * jn[s] - any_ * jt[s]), ty + (anx * jt[s] + any_ * jn[s])
                impulse += math.sqrt(tx * tx + ty * ty)
        blade[i, 0], blade[i, 1], blade[i, 2], blade[i, 3], blade[i, 4], blade[i, 5] = px, py, a, vx, vy, w
        hand[i, 0], hand[i, 1], hand[i, 2] = gx, gy, pitch
        lateral[i, 0], lateral[i, 1], lateral[i, 2], lateral[i, 3] = lat_y, lat_v, hand_lat, anchor
        hand_v[i, 0], hand_v[i, 1], hand_v[i, 2], hand_v[i, 3] = hvx, hvy, hw, hl
        contact[i, 0], contact[i, 1], contact[i, 2], contact[i, 3] = P, Q, cx, cy
        incisor[i] = impulse / (count * h)


class LaryngoscopeKernel(LaryngoscopeArrays):
    """:class:`~.batch.LaryngoscopeArrays` with each control period run by :func:`control_period`, one
    compiled loop over the devices: the same state, readings and results bit for bit, at the speed of
    compiled code (numba compiles it at the first step of a process, about 10 s)."""

    def __init__(self, params: LaryngoscopeParams, contact: TongueContact, n: int) -> None:
        super().__init__(params, contact, n)
        s = self._teeth.solver
        self._kernel_args = (substep_tuple(self.c), np.asarray(contact.loads, dtype=np.float64),
                             np.asarray(contact.slopes, dtype=np.float64), coupling_tuple(self._coupling), s.local,
                             s.local_normals, s.ends, s.seg_normal,
                             s.radius, s.friction, s.slop, s.bias_coef, SOLVER_ITERATIONS, self._teeth.dt_coef)

    def substeps(self, vX: np.ndarray, vY: np.ndarray, spin: np.ndarray, v_lat: np.ndarray, count: int) -> None:
        command = np.stack(np.broadcast_arrays(vX, vY, spin, v_lat)).astype(np.float64)
        control_period(self._blade, self._hand, self._lateral, self._hand_v, self._contact, self._incisor, command,
                       count, *self._kernel_args)
        self._touched[:] = False                   # the kernel starts every device's contact afresh
        self._forget()
