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
