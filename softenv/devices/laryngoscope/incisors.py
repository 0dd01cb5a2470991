"""The blade against the upper incisors as Chipmunk collides them, on numpy arrays (``n`` devices).

The second piece of the laryngoscope on arrays (issue 37, after :mod:`.rigid`): Chipmunk's
``SegmentToPoly`` for the incisors (a static rounded segment) and the blade (a convex polygon without
radius), without its iterative search. Chipmunk finds the edge of the Minkowski difference
``blade - incisors`` nearest the origin by GJK; while the two cores are apart (the blade never sinks
the incisors' 4 mm radius deep) that edge is the nearest of the difference's candidate edges, each
vertex of one shape against each edge of the other, so every candidate is measured at once and the
nearest taken. Its closest points, normal and distance, then the contact points clipped from the two
support edges, follow Chipmunk's expressions (``ClosestPointsNew``, ``SupportEdgeFor*``,
``ContactPoints``), so the same IEEE operations run in the same order
(``tests/test_laryngoscope_arrays.py`` holds them to Chipmunk's ``cpShapesCollide``, bit for bit).
"""

from __future__ import annotations

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


def transformed(local: np.ndarray, x: np.ndarray, y: np.ndarray, cos_a: np.ndarray, sin_a: np.ndarray,
                offset: bool = True) -> np.ndarray:
    """``local`` ``(V, 2)`` points (or, without ``offset``, vectors) in the world frame of ``n`` bodies:
    ``(n, V, 2)``, as ``cpTransformPoint`` / ``cpTransformVect`` compute them."""
    lx, ly = local[None, :, 0], local[None, :, 1]
    c, s = cos_a[:, None], sin_a[:, None]
    wx, wy = c * lx + -s * ly, s * lx + c * ly
    if offset:
        wx, wy = wx + x[:, None], wy + y[:, None]
    return np.stack([wx, wy], axis=-1)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _lerp_t(a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
    ht = (0.5 * t)[..., None]
    return a * (0.5 - ht) + b * (0.5 + ht)


def _closest_t(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    delta = b - a
    d2 = _dot(delta, delta)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = -np.clip(_dot(delta, a + b) / d2, -1.0, 1.0)
    return np.where(d2 != 0.0, t, 0.0)


def collide(segment: tuple[tuple[float, float], tuple[float, float]], radius: float, vertices: np.ndarray,
            normals: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The contacts of a static segment ``(a, b)`` of ``radius`` with ``n`` polygons (world ``vertices``
    and plane ``normals``, ``(n, V, 2)``). Returns the normal ``(n, 2)`` (from the segment toward the
    blade), the contact points on the segment's surface and on the blade ``(n, 2, 2)`` each, and which
    of the (at most two) contacts exist ``(n, 2)``."""
    n_dev, count = vertices.shape[:2]
    ends = np.array(segment, dtype=np.float64)                       # (2, 2): ta, tb
    # the Minkowski points blade vertex j - segment end i: (n, 2, V, 2)
    ab = vertices[:, None, :, :] - ends[None, :, None, :]
    # candidate edges: each segment end against each blade edge (j, j + 1), each blade vertex against the segment
    v0 = np.concatenate([ab.reshape(n_dev, 2 * count, 2), ab[:, 0]], axis=1)
    v1 = np.concatenate([np.roll(ab, -1, axis=2).reshape(n_dev, 2 * count, 2), ab[:, 1]], axis=1)
    ia = np.concatenate([np.repeat([0, 1], count), np.zeros(count, dtype=int)])          # segment end of v0
    ja = np.concatenate([np.tile(np.arange(count), 2), np.arange(count)])               # blade vertex of v0
    ib = np.concatenate([np.repeat([0, 1], count), np.ones(count, dtype=int)])
    jb = np.concatenate([np.tile((np.arange(count) + 1) % count, 2), np.arange(count)])
    t_all = _closest_t(v0, v1)
    p_all = _lerp_t(v0, v1, t_all)
    best = np.argmin(_dot(p_all, p_all), axis=1)                      # ClosestDist; the first of equals
    rows = np.arange(n_dev)
    # Chipmunk's GJK leaves the edge oriented with the origin on its inner side: d > 0 apart
    e0, e1 = v0[rows, best], v1[rows, best]
    delta = e1 - e0
    flip = _dot(np.stack([delta[:, 1], -delta[:, 0]], axis=1), p_all[rows, best]) < 0.0
    m0 = ab[rows, np.where(flip, ib[best], ia[best]), np.where(flip, jb[best], ja[best])]
    m1 = ab[rows, np.where(flip, ia[best], ib[best]), np.where(flip, ja[best], jb[best])]
    # ClosestPointsNew
    t = _closest_t(m0, m1)
    p = _lerp_t(m0, m1, t)
    d_ab = m1 - m0
    rp = np.stack([d_ab[:, 1], -d_ab[:, 0]], axis=1)
    normal = rp * (1.0 / (np.sqrt(_dot(rp, rp)) + TINY))[:, None]
    d = _dot(normal, p)
    vertex_pair = ~((d <= 0.0) | ((-1.0 < t) & (t < 1.0)))
    d2 = np.sqrt(_dot(p, p))
    normal = np.where(vertex_pair[:, None], p * (1.0 / (d2 + TINY))[:, None], normal)
    d = np.where(vertex_pair, d2, d)
    # SupportEdgeForSegment(seg, n) and SupportEdgeForPoly(poly, -n)
    tn = _segment_normal(ends)
    forward = _dot(tn[None], normal) > 0.0
    s_a = np.where(forward[:, None], ends[0], ends[1])
    s_b = np.where(forward[:, None], ends[1], ends[0])
    back = -normal
    i1p = np.argmax(_dot(vertices, back[:, None, :]), axis=1)
    i0p, i2p = (i1p - 1 + count) % count, (i1p + 1) % count
    keep = _dot(back, normals[rows, i1p]) > _dot(back, normals[rows, i2p])
    q_a = np.where(keep[:, None], vertices[rows, i0p], vertices[rows, i1p])
    q_b = np.where(keep[:, None], vertices[rows, i1p], vertices[rows, i2p])
    # ContactPoints (the blade has no radius: its offset is n * -0.0)
    touching = (d - radius) - 0.0 <= 0.0
    touching &= d <= radius + 0.0
    d1a, d1b, d2a, d2b = _cross(s_a, normal), _cross(s_b, normal), _cross(q_a, normal), _cross(q_b, normal)
    e1_denom = 1.0 / (d1b - d1a + TINY)
    e2_denom = 1.0 / (d2b - d2a + TINY)
    points_a, points_b, exists = [], [], []
    for first, second in ((d2b - d1a, d1a - d2a), (d2a - d1a, d1b - d2a)):
        u = np.clip(first * e1_denom, 0.0, 1.0)[:, None]
        v = np.clip(second * e2_denom, 0.0, 1.0)[:, None]
        p1 = normal * radius + (s_a * (1.0 - u) + s_b * u)
        p2 = normal * -0.0 + (q_a * (1.0 - v) + q_b * v)
        points_a.append(p1)
        points_b.append(p2)
        exists.append(touching & (_dot(p2 - p1, normal) <= 0.0))
    return normal, np.stack(points_a, axis=1), np.stack(points_b, axis=1), np.stack(exists, axis=1)


def _segment_normal(ends: np.ndarray) -> np.ndarray:
    """``cpSegmentShape``'s normal: ``rperp`` of the unit direction from ``a`` to ``b``."""
    delta = ends[1] - ends[0]
    unit = delta * (1.0 / (np.sqrt(_dot(delta, delta)) + TINY))
    return np.array([unit[1], -unit[0]])
