import math

import numpy as np
import pytest

from softenv.geometry import (geodesic_distance, icosphere_mesh, latlong_mesh, make_mesh, mesh_from_spec,
                              paper_mesh, triangle_orientation)


@pytest.mark.parametrize("n_points", [441, 961])
def test_paper_grids_have_the_papers_point_counts(n_points):
    mesh = paper_mesh(n_points, radius=0.03)
    assert mesh.n_vertices == n_points
    np.testing.assert_allclose(np.linalg.norm(mesh.vertices, axis=1), 0.03, rtol=1e-14)
    assert len(np.unique(np.round(mesh.vertices, 12), axis=0)) == n_points  # no duplicated points


@pytest.mark.parametrize("mesh", [latlong_mesh(5), latlong_mesh(21), icosphere_mesh(0), icosphere_mesh(3)],
                         ids=["latlong5", "latlong21", "ico0", "ico3"])
def test_triangulation_is_closed_and_outward(mesh):
    tris = mesh.triangles
    edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert (counts == 2).all()                                     # every edge joins exactly two triangles
    assert mesh.n_vertices - len(counts) + len(tris) == 2          # Euler characteristic of a sphere
    assert (triangle_orientation(mesh.vertices, tris) > 0).all()   # all face outward
    # directed edges appear once each: consistent orientation
    directed = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    assert len(np.unique(directed, axis=0)) == len(directed)


def test_icosphere_counts_and_quasi_uniformity():
    for level, count in [(0, 12), (1, 42), (2, 162), (3, 642)]:
        assert icosphere_mesh(level).n_vertices == count
    mesh = icosphere_mesh(3, radius=1.0)
    p = mesh.vertices[mesh.triangles]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    assert area.max() / area.min() < 2.5
    assert area.sum() == pytest.approx(4 * math.pi, rel=0.02)


def test_normals_are_unit_radial():
    mesh = latlong_mesh(11, radius=2.0)
    np.testing.assert_allclose(mesh.normals * 2.0, mesh.vertices, atol=1e-14)


def test_geodesic_distance_against_known_arcs():
    R = 0.05
    a = np.array([[0.0, 0.0, 1.0]])
    b = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, math.sin(1e-7), math.cos(1e-7)]])
    np.testing.assert_allclose(geodesic_distance(a, b, R)[0], [0.0, R * math.pi / 2, R * math.pi, R * 1e-7],
                               rtol=1e-9, atol=1e-18)


def test_mesh_spec_round_trip_and_mismatch():
    mesh = make_mesh("icosphere", 2, 0.03)
    assert mesh_from_spec(mesh.spec()).fingerprint == mesh.fingerprint
    spec = dict(mesh.spec(), fingerprint="icosphere-2-r0.03-0000000000000000")
    with pytest.raises(ValueError, match="recorded in the file"):
        mesh_from_spec(spec)


@pytest.mark.parametrize("call, match", [
    (lambda: latlong_mesh(2), "n=2 is out of range"),
    (lambda: latlong_mesh(10, radius=-1.0), "radius=-1 is out of range"),
    (lambda: paper_mesh(440), "not a square"),
    (lambda: make_mesh("cube", 3), "kind='cube' is not allowed"),
    (lambda: icosphere_mesh(9), "subdivisions=9 is out of range"),
])
def test_bad_mesh_arguments_name_the_argument(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_latlong_interpolation_is_exact_for_constants_and_second_order_for_smooth_fields():
    from softenv.geometry import interpolate_latlong, latlong_mesh

    rng = np.random.default_rng(0)
    points = rng.normal(size=(500, 3))
    points = points[np.abs(points[:, 2]) / np.linalg.norm(points, axis=1) < 0.9]   # away from the polar caps
    unit = points / np.linalg.norm(points, axis=1, keepdims=True)
    np.testing.assert_allclose(interpolate_latlong(np.tile([1.0, -2.0, 3.0], 31 * 31), 31, points),
                               np.tile([1.0, -2.0, 3.0], (len(points), 1)), rtol=1e-12)
    errors = []
    for n in (31, 61):
        field = latlong_mesh(n, radius=1.0).vertices        # the direction field itself
        errors.append(np.abs(interpolate_latlong(field, n, points) - unit).max())
    # linear interpolation of a unit-curvature field: error <= h^2 / 8 summed over both directions
    assert errors[0] <= ((np.pi / 31) ** 2 + (2 * np.pi / 31) ** 2) / 8
    assert errors[1] < errors[0] / 3                              # halving the spacing cuts the error ~4x
