"""Hexahedral meshes of the tongue's ball, and where its base and the blade's patch lie on them.

Plain numpy: nothing here needs the finite-element library.

The ball is a cube of ``n^3`` hexahedra mapped onto it by the volume-filling form of the
cube-to-sphere map (``x' = x sqrt(1 - y^2/2 - z^2/2 + y^2 z^2 / 3)`` and cyclically; its restriction
to the cube's faces is the well-known equal-area-like map onto the sphere). It keeps every cell's
Jacobian positive, it has no degenerate (collapsed) cells at any pole, and a refinement ``2 n`` nests
its points in those of ``n`` on the cube, so mesh studies compare like with like.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._validation import check_int, check_real


def cube_hexahedra(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Points ``((n+1)^3, 3)`` of ``[-1, 1]^3`` and ``(n^3, 8)`` hexahedra (VTK node order)."""
    n = check_int(n, "cells_per_side", 1, 64)
    s = np.linspace(-1.0, 1.0, n + 1)
    z, y, x = np.meshgrid(s, s, s, indexing="ij")          # x varies fastest
    points = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    i, j, k = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    node = lambda di, dj, dk: ((k + dk) * (n + 1) + (j + dj)) * (n + 1) + (i + di)  # noqa: E731
    # z, y, x cell order (k slowest), nodes bottom face counter-clockwise, then top face
    cells = np.stack([node(0, 0, 0), node(1, 0, 0), node(1, 1, 0), node(0, 1, 0),
                      node(0, 0, 1), node(1, 0, 1), node(1, 1, 1), node(0, 1, 1)], axis=-1)
    return points, cells.transpose(2, 1, 0, 3).reshape(-1, 8)


def cube_to_ball(points: np.ndarray, radius: float) -> np.ndarray:
    """Map points of ``[-1, 1]^3`` into the ball of ``radius`` (the cube's faces onto the sphere)."""
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    x2, y2, z2 = x * x, y * y, z * z
    return radius * np.stack([x * np.sqrt(1.0 - y2 / 2 - z2 / 2 + y2 * z2 / 3),
                              y * np.sqrt(1.0 - z2 / 2 - x2 / 2 + z2 * x2 / 3),
                              z * np.sqrt(1.0 - x2 / 2 - y2 / 2 + x2 * y2 / 3)], axis=1)


def ball_mesh(radius: float, cells_per_side: int) -> tuple[np.ndarray, np.ndarray]:
    """Points ``(m, 3)`` (m) and hexahedra ``(n^3, 8)`` of a ball of ``radius`` centred at the origin."""
    check_real(radius, "radius", 1e-4, 1.0)
    points, cells = cube_hexahedra(cells_per_side)
    return cube_to_ball(points, radius), cells


def surface_nodes(points: np.ndarray, radius: float) -> np.ndarray:
    """Mask of the points on the sphere."""
    return np.abs(np.linalg.norm(points, axis=1) - radius) <= 1e-9 * radius


def base_cap(points: np.ndarray, radius: float, cap_deg: float) -> np.ndarray:
    """Mask of the surface points within ``cap_deg`` of the bottom pole ``(0, 0, -R)``: where the
    tongue is attached (fixed)."""
    return surface_nodes(points, radius) & (points[:, 2] <= -radius * math.cos(math.radians(cap_deg)) + 1e-12)


def ball_to_cube(points: np.ndarray, radius: float, iterations: int = 30) -> np.ndarray:
    """Inverse of :func:`cube_to_ball`: cube coordinates ``(m, 3)`` of points in the ball, by Newton's
    method on the map (its Jacobian in closed form); exact to ~1e-15 of the radius."""
    q = np.asarray(points, dtype=float) / radius
    p = q * np.linalg.norm(q, axis=1, keepdims=True) / np.maximum(np.abs(q).max(axis=1, keepdims=True), 1e-300)
    for _ in range(iterations):
        r = cube_to_ball(p, 1.0) - q
        if np.abs(r).max() <= 1e-15:
            break
        p = p - np.linalg.solve(_map_jacobian(p), r[:, :, None])[:, :, 0]
        p = np.clip(p, -1.0, 1.0)
    if np.abs(cube_to_ball(p, 1.0) - q).max() > 1e-12:
        raise ValueError("points outside the ball: no cube coordinates")
    return p


def _map_jacobian(p: np.ndarray) -> np.ndarray:
    """``d cube_to_ball / d p`` at points ``(m, 3)``: ``(m, 3, 3)``."""
    J = np.empty(p.shape + (3,))
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        x, y, z = p[:, i], p[:, j], p[:, k]
        s = np.sqrt(1.0 - y * y / 2 - z * z / 2 + y * y * z * z / 3)
        J[:, i, i] = s
        J[:, i, j] = x * (-y + 2 * y * z * z / 3) / (2 * s)
        J[:, i, k] = x * (-z + 2 * z * y * y / 3) / (2 * s)
    return J


def interpolate_nodal(values: np.ndarray, cube_points: np.ndarray, n: int) -> np.ndarray:
    """Values ``(..., m_nodes, d)`` of a field on the nodes of :func:`cube_hexahedra` (``n`` a side) at
    cube coordinates ``(m, 3)``: the hexahedra's own trilinear shape functions, so the result is the
    finite-element field itself, with no error added."""
    t = (np.asarray(cube_points, dtype=float) + 1.0) * (n / 2.0)
    cell = np.clip(np.floor(t), 0, n - 1).astype(np.int64)
    f = t - cell
    out: Any = 0.0
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                w = ((f[:, 0] if dx else 1 - f[:, 0]) * (f[:, 1] if dy else 1 - f[:, 1])
                     * (f[:, 2] if dz else 1 - f[:, 2]))
                node = ((cell[:, 2] + dz) * (n + 1) + cell[:, 1] + dy) * (n + 1) + cell[:, 0] + dx
                out = out + w[:, None] * values[..., node, :]
    return out
