"""Surface sampling of a sphere: the paper's latitude-longitude grid and a quasi-uniform icosphere.

Coordinates: the sphere is centred at the origin; ``+z`` is up (the tongue's dorsum), ``+x`` points
to the front of the mouth (the tip of the tongue) and ``+y`` to the patient's side toward which the
laryngoscope sweeps the tongue.

The paper sampled its sphere on 21 x 21 = 441 and 31 x 31 = 961 points. MATLAB's ``sphere(n-1)``,
the likely source, repeats the poles ``n`` times and the seam twice; here the ``n x n`` grid has
``n`` distinct latitude rings placed at cell centres (no pole points) and ``n`` longitudes per ring,
so every coordinate carries information and no triangle is degenerate. The two polar holes are
closed by fans, so the triangulation is a closed, outward-oriented surface.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ._validation import check_array, check_choice, check_int, check_real

MESH_KINDS = ("latlong", "icosphere")


@dataclass(frozen=True, eq=False)
class SphereMesh:
    """Points on a sphere of ``radius`` (metres) with an outward-oriented triangulation.

    Attributes:
        kind: ``"latlong"`` (``resolution`` = points per ring = number of rings) or
            ``"icosphere"`` (``resolution`` = subdivision level).
        vertices: ``(n_vertices, 3)`` rest positions, read-only.
        triangles: ``(n_triangles, 3)`` vertex indices, counter-clockwise seen from outside.
    """

    kind: str
    resolution: int
    radius: float
    vertices: np.ndarray = field(repr=False)
    triangles: np.ndarray = field(repr=False)

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @cached_property
    def normals(self) -> np.ndarray:
        """Outward unit normals, ``(n_vertices, 3)`` (on a sphere: position / radius)."""
        n = self.vertices / np.linalg.norm(self.vertices, axis=1, keepdims=True)
        n.flags.writeable = False
        return n

    @cached_property
    def fingerprint(self) -> str:
        """Identifies the mesh (kind, resolution, radius and a digest of the vertices)."""
        digest = hashlib.sha256(np.ascontiguousarray(self.vertices, dtype="<f8").tobytes()).hexdigest()[:16]
        return f"{self.kind}-{self.resolution}-r{self.radius:.6g}-{digest}"

    def spec(self) -> dict:
        """JSON-able description from which :func:`mesh_from_spec` rebuilds (and verifies) the mesh."""
        return {"kind": self.kind, "resolution": self.resolution, "radius": self.radius, "fingerprint": self.fingerprint}

    def geodesic_distance(self, points: np.ndarray) -> np.ndarray:
        """Great-circle distance (metres) from each of ``points`` ``(m, 3)`` to every vertex: ``(m, n_vertices)``.

        Points need not lie on the sphere; their directions are used.
        """
        pts = check_array(points, "points", ndim=(1, 2), shape=(3,))
        return geodesic_distance(pts.reshape(-1, 3), self.vertices, self.radius)


def geodesic_distance(a: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray:
    """Great-circle distance between the directions of ``a`` ``(m, 3)`` and ``b`` ``(n, 3)``: ``(m, n)``.

    Uses ``atan2(|u x v|, u . v)``, accurate for tiny and near-antipodal angles alike.
    """
    u = a / np.linalg.norm(a, axis=-1, keepdims=True)
    v = b / np.linalg.norm(b, axis=-1, keepdims=True)
    cross = np.linalg.norm(np.cross(u[:, None, :], v[None, :, :]), axis=-1)
    return radius * np.arctan2(cross, u @ v.T)


def latlong_mesh(n: int, radius: float = 0.03) -> SphereMesh:
    """The paper's latitude-longitude grid: ``n`` rings of ``n`` points (441 for n=21, 961 for n=31)."""
    n = check_int(n, "n", 3, 2000)
    radius = check_real(radius, "radius", 0.0, None, low_open=True)
    lat = -np.pi / 2 + (np.arange(n) + 0.5) * np.pi / n
    lon = 2 * np.pi * np.arange(n) / n
    cl, sl = np.cos(lat)[:, None], np.sin(lat)[:, None]
    vertices = radius * np.stack([cl * np.cos(lon)[None, :], cl * np.sin(lon)[None, :],
                                  np.broadcast_to(sl, (n, n))], axis=-1).reshape(-1, 3)
    ring = np.arange(n)
    nxt = (ring + 1) % n
    tris = []
    for i in range(n - 1):  # band between ring i (south) and ring i + 1 (north)
        a, b = i * n + ring, i * n + nxt
        c, d = (i + 1) * n + nxt, (i + 1) * n + ring
        tris.append(np.stack([a, b, c], axis=1))
        tris.append(np.stack([a, c, d], axis=1))
    fan = np.arange(1, n - 1)
    south = np.stack([np.zeros_like(fan), fan + 1, fan], axis=1)  # seen from below: reversed
    north = (n - 1) * n + np.stack([np.zeros_like(fan), fan, fan + 1], axis=1)
    triangles = np.concatenate(tris + [south, north]).astype(np.int32)
    return _frozen_mesh("latlong", n, radius, vertices, triangles)


def icosphere_mesh(subdivisions: int, radius: float = 0.03) -> SphereMesh:
    """Quasi-uniform icosphere: ``10 * 4**subdivisions + 2`` points (12, 42, 162, 642, 2562, ...)."""
    subdivisions = check_int(subdivisions, "subdivisions", 0, 7)
    radius = check_real(radius, "radius", 0.0, None, low_open=True)
    t = (1 + 5 ** 0.5) / 2
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
             (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    points = [np.array(v, dtype=float) / np.linalg.norm(v) for v in verts]
    for _ in range(subdivisions):
        midpoint: dict[tuple[int, int], int] = {}

        def middle(i: int, j: int) -> int:
            key = (min(i, j), max(i, j))
            if key not in midpoint:
                m = points[i] + points[j]
                points.append(m / np.linalg.norm(m))
                midpoint[key] = len(points) - 1
            return midpoint[key]

        new_faces = []
        for a, b, c in faces:
            ab, bc, ca = middle(a, b), middle(b, c), middle(c, a)
            new_faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new_faces
    vertices = radius * np.array(points)
    return _frozen_mesh("icosphere", subdivisions, radius, vertices, np.array(faces, dtype=np.int32))


def interpolate_latlong(field: np.ndarray, n: int, points: np.ndarray) -> np.ndarray:
    """A vector field on an ``n x n`` lat-long grid (``latlong_mesh(n)`` order, ``(n * n * 3,)`` or
    ``(n * n, 3)``) at the directions of ``points`` ``(m, 3)``: bilinear in latitude and periodic
    longitude. For comparing fields (such as PCA components) between resolutions."""
    f = np.asarray(field, dtype=np.float64).reshape(n, n, 3)
    lat = np.arcsin(np.clip(points[:, 2] / np.linalg.norm(points, axis=1), -1, 1))
    lon = np.mod(np.arctan2(points[:, 1], points[:, 0]), 2 * np.pi)
    r = np.clip((lat + np.pi / 2) / (np.pi / n) - 0.5, 0, n - 1)
    q = lon / (2 * np.pi / n)
    r0 = np.minimum(np.floor(r).astype(int), n - 2)
    fr, fq = (r - r0)[:, None], (q - np.floor(q))[:, None]
    q0 = np.floor(q).astype(int) % n
    q1 = (q0 + 1) % n
    lower = (1 - fq) * f[r0, q0] + fq * f[r0, q1]
    upper = (1 - fq) * f[r0 + 1, q0] + fq * f[r0 + 1, q1]
    return (1 - fr) * lower + fr * upper


def make_mesh(kind: str = "latlong", resolution: int = 31, radius: float = 0.03) -> SphereMesh:
    """Build a mesh by name (``"latlong"`` or ``"icosphere"``)."""
    check_choice(kind, "kind", MESH_KINDS)
    return latlong_mesh(resolution, radius) if kind == "latlong" else icosphere_mesh(resolution, radius)


def mesh_from_spec(spec: dict) -> SphereMesh:
    """Rebuild a mesh from :meth:`SphereMesh.spec`, refusing one whose vertices differ from the record."""
    try:
        mesh = make_mesh(spec["kind"], spec["resolution"], spec["radius"])
        recorded = spec["fingerprint"]
    except (KeyError, TypeError) as exc:
        raise ValueError(f"invalid mesh description {spec!r}: {exc}") from exc
    if mesh.fingerprint != recorded:
        raise ValueError(f"mesh {recorded!r} recorded in the file is not what this softenv builds "
                         f"({mesh.fingerprint!r}); re-create the file")
    return mesh


def paper_mesh(n_points: int = 441, radius: float = 0.03) -> SphereMesh:
    """The paper's grids by point count: 441 (21 x 21) or 961 (31 x 31); any square count works."""
    n_points = check_int(n_points, "n_points", 9)
    n = int(round(n_points ** 0.5))
    if n * n != n_points:
        raise ValueError(f"n_points={n_points} is not a square n*n (the paper used 441 = 21x21 and 961 = 31x31)")
    return latlong_mesh(n, radius)


def triangle_orientation(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Signed volume ``det[p1, p2, p3]`` of each triangle with the centre: positive = outward-facing.

    ``points`` is ``(..., n_vertices, 3)``; the result is ``(..., n_triangles)``. Used to check that
    a deformation never turns a surface triangle inside out.
    """
    p = np.asarray(points)
    p1, p2, p3 = (p[..., triangles[:, i], :] for i in range(3))
    return np.einsum("...i,...i->...", p1, np.cross(p2, p3))


def _frozen_mesh(kind: str, resolution: int, radius: float, vertices: np.ndarray,
                 triangles: np.ndarray) -> SphereMesh:
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    vertices.flags.writeable = False
    triangles = np.ascontiguousarray(triangles)
    triangles.flags.writeable = False
    return SphereMesh(kind, resolution, radius, vertices, triangles)
