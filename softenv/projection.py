"""Orthographic projection of a triangulated surface and the 2-D outlines drawn of a scene, in numpy only:
shared by the matplotlib frames (:mod:`softenv.render`) and ``softenv play``'s pygame window, so
neither drawing library needs the other."""

from __future__ import annotations

import math
from typing import Any

import numpy as np


class View:
    """Orthographic camera: ``elevation`` above the x-y plane and ``azimuth`` around z, in degrees."""

    def __init__(self, elevation: float = 30.0, azimuth: float = -50.0) -> None:
        el, az = math.radians(elevation), math.radians(azimuth)
        forward = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])  # toward viewer
        right = np.array([-math.sin(az), math.cos(az), 0.0])
        up = np.cross(forward, right)
        self.basis = np.stack([right, up, forward])  # rows: screen x, screen y, depth (toward viewer)
        self.light = forward * 0.6 + up * 0.6 + right * 0.3
        self.light /= np.linalg.norm(self.light)

    def project(self, points: np.ndarray) -> np.ndarray:
        """``(n, 3)`` world points -> ``(n, 3)`` screen x, screen y, depth."""
        return points @ self.basis.T


def shaded_faces(points: np.ndarray, triangles: np.ndarray, values: np.ndarray, view: View, cmap: Any,
                 vmin: float, vmax: float) -> tuple[np.ndarray, np.ndarray]:
    """Front-facing triangles in 2-D, back to front, and their shaded RGBA colours."""
    screen = view.project(points)
    tri = screen[triangles]                                   # (t, 3, 3)
    world = points[triangles]
    normal = np.cross(world[:, 1] - world[:, 0], world[:, 2] - world[:, 0])
    facing = normal @ view.basis[2] > 0
    order = np.argsort(tri[facing, :, 2].mean(axis=1))
    keep = np.flatnonzero(facing)[order]
    unit = normal[keep] / np.maximum(np.linalg.norm(normal[keep], axis=1, keepdims=True), 1e-300)
    lambert = 0.6 + 0.4 * np.clip(unit @ view.light, 0.0, 1.0)
    face_value = values[triangles[keep]].mean(axis=1)
    span = vmax - vmin if vmax > vmin else 1.0
    rgba = cmap(np.clip((face_value - vmin) / span, 0.0, 1.0))
    rgba[:, :3] *= lambert[:, None]
    return tri[keep, :, :2], rgba


def visible_edges(points: np.ndarray, triangles: np.ndarray, view: View) -> np.ndarray:
    """2-D segments of the front-facing triangles' edges (a wireframe), ``(m, 2, 2)``."""
    world = points[triangles]
    normal = np.cross(world[:, 1] - world[:, 0], world[:, 2] - world[:, 0])
    front = triangles[normal @ view.basis[2] > 0]
    edges = np.unique(np.sort(np.concatenate([front[:, [0, 1]], front[:, [1, 2]], front[:, [2, 0]]]), axis=1), axis=0)
    screen = view.project(points)[:, :2]
    return screen[edges]


def capsule(a: np.ndarray, b: np.ndarray, radius: float, n: int = 12) -> np.ndarray:
    """Outline ``(2 n + 2, 2)`` of a rounded bar from ``a`` to ``b``."""
    angle = math.atan2(b[1] - a[1], b[0] - a[0])
    ends = [(b, np.linspace(angle - math.pi / 2, angle + math.pi / 2, n + 1)),
            (a, np.linspace(angle + math.pi / 2, angle + 3 * math.pi / 2, n + 1))]
    return np.concatenate([c + radius * np.stack([np.cos(t), np.sin(t)], axis=1) for c, t in ends])


def midline_profile(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The surface's section by the sagittal plane ``y = 0``: ``(m, 2)`` points ``(x, z)`` ordered by
    angle (edges that cross the plane, cut by linear interpolation)."""
    edges = np.unique(np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]),
                              axis=1), axis=0)
    a, b = points[edges[:, 0]], points[edges[:, 1]]
    cross = (a[:, 1] * b[:, 1] < 0) | ((a[:, 1] == 0) & (b[:, 1] != 0))
    t = a[cross, 1] / (a[cross, 1] - b[cross, 1])
    cut = a[cross] + t[:, None] * (b[cross] - a[cross])
    order = np.argsort(np.arctan2(cut[:, 2], cut[:, 0]))
    return cut[order][:, [0, 2]]
