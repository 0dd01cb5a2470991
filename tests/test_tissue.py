import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from softenv.geometry import icosphere_mesh, latlong_mesh, triangle_orientation
from softenv.tissue import AnalyticTissue, TissueParams, effective_modulus

TOP = np.array([0.0, 0.0, 1.0])


def tissue_on(mesh, **params):
    return AnalyticTissue(mesh, TissueParams(radius=mesh.radius, **params))


def radial_and_tangential(t, contact_dir, force):
    """Radial (inward) and along-drag displacement of every vertex, and its geodesic distance."""
    R = t.params.radius
    u = t.displacements(R * contact_dir[None], force[None])[0]
    n = t.mesh.normals
    s = R * np.arccos(np.clip(n @ contact_dir, -1, 1))
    return -(u * n).sum(1), u, s


def test_centre_deflection_is_the_uniform_pressure_patch_value():
    # Johnson, Contact Mechanics 3.4: centre deflection under pressure P / (pi a^2) on a circle of radius a
    mesh = icosphere_mesh(4, radius=0.03)
    t = tissue_on(mesh, E=50e3, nu=0.3, patch_radius=0.01)
    contact = mesh.normals[0]
    inward, _, _ = radial_and_tangential(t, contact, -2.0 * contact)
    expected = 2 * (1 - 0.3 ** 2) * 2.0 / (math.pi * 50e3 * 0.01)
    assert inward[0] == pytest.approx(expected, rel=1e-12)


def test_far_field_is_boussinesq_point_load():
    # u_z(r) = P (1 - nu^2) / (pi E r) for a << r << R: a large sphere with a small patch
    mesh = icosphere_mesh(6, radius=1.0)
    t = tissue_on(mesh, E=1e6, nu=0.45, patch_radius=1e-3)
    contact = mesh.normals[0]
    inward, _, s = radial_and_tangential(t, contact, -1.0 * contact)
    ring = (s > 0.02) & (s < 0.05)
    boussinesq = 1.0 * (1 - 0.45 ** 2) / (math.pi * 1e6 * s[ring])
    np.testing.assert_allclose(inward[ring], boussinesq, rtol=2e-3)


def test_far_field_drag_is_direction_averaged_cerruti():
    # Cerruti: in-plane displacement along Q averaged over direction is Q (1 + nu)(2 - nu) / (2 pi E r)
    mesh = icosphere_mesh(6, radius=1.0)
    nu, E = 0.4, 2e6
    t = tissue_on(mesh, E=E, nu=nu, patch_radius=1e-3)
    contact = mesh.normals[0]
    drag = np.cross(contact, [1.0, 0.0, 0.0])
    drag /= np.linalg.norm(drag)
    _, u, s = radial_and_tangential(t, contact, 1.0 * drag)
    ring = (s > 0.02) & (s < 0.05)
    along = u[ring] @ drag
    expected = (1 + nu) * (2 - nu) / (2 * math.pi * E * s[ring])
    np.testing.assert_allclose(along, expected, rtol=3e-3)


def test_clinical_scaling_maps_40N_to_40_percent_of_the_radius():
    p = TissueParams()
    assert p.E == pytest.approx(effective_modulus(40.0, 0.4))
    assert p.normal_compliance * 40.0 == pytest.approx(0.4 * p.radius)
    p2 = TissueParams.for_clinical_forces(max_force=20.0, indentation=0.25, nu=0.49)
    assert p2.normal_compliance * 20.0 == pytest.approx(0.25 * p2.radius)
    # with E_eff, the dimensionless load at the design force is pi a f / (2 R), whatever nu
    assert p.dimensionless_load(40.0) == pytest.approx(math.pi * 0.015 * 0.4 / (2 * 0.03))


def test_linear_law_is_exactly_linear_below_saturation():
    mesh = latlong_mesh(21)
    t = AnalyticTissue(mesh)
    c = 0.03 * np.array([[0.3, 0.1, math.sqrt(1 - 0.1)]])
    f = np.array([[0.2, 0.3, -2.0]])
    x0 = t.rest_shape
    d1 = t.surfaces(c, f) - x0
    d3 = t.surfaces(c, 3 * f) - x0
    amp = t.amplitudes(c, 3 * f)
    assert amp["normal_saturation"][0] == 1.0 and amp["tangential_saturation"][0] == 1.0
    np.testing.assert_allclose(d3, 3 * d1, rtol=1e-9, atol=1e-15)


def test_stiffening_law_follows_fung_and_widens_like_hertz():
    mesh = icosphere_mesh(4)
    lin, stiff = AnalyticTissue(mesh), AnalyticTissue(mesh, TissueParams(law="stiffening"))
    c = mesh.vertices[:1]
    n = mesh.normals[:1]
    small, large = -0.01 * n, -30.0 * n
    # same compliance at small loads
    assert stiff.amplitudes(c, small)["indentation"][0] == pytest.approx(lin.amplitudes(c, small)["indentation"][0], rel=1e-3)
    # Fung law: P = (delta_s / C_n)(exp(W / delta_s) - 1), inverted from the measured indentation
    p = stiff.params
    W = -(stiff.displacements(c, large)[0, 0] @ n[0])
    ds = p.stiffening_depth * p.radius
    assert ds / p.normal_compliance * math.expm1(W / ds) == pytest.approx(30.0, rel=1e-9)
    assert W < lin.amplitudes(c, large)["indentation"][0]           # stiffer than linear
    h = stiff.amplitudes(c, large)["half_width"][0]
    assert h == pytest.approx(math.sqrt(p.patch_radius ** 2 + p.radius * W) / 2)   # Hertz a = sqrt(R d)


@settings(max_examples=40, deadline=None)
@given(law=st.sampled_from(["linear", "stiffening"]), f1=st.floats(0.01, 1e5), ratio=st.floats(1.01, 100.0),
       polar=st.floats(0.0, 3.1), azimuth=st.floats(0.0, 6.28), tilt=st.floats(0.0, 1.5))
def test_contact_displacement_grows_with_force_and_moves_along_it(law, f1, ratio, polar, azimuth, tilt):
    mesh = latlong_mesh(15)
    t = AnalyticTissue(mesh, TissueParams(law=law))
    aim = np.array([math.sin(polar) * math.cos(azimuth), math.sin(polar) * math.sin(azimuth), math.cos(polar)])
    i = int(np.argmax(mesh.normals @ aim))             # contact exactly at a vertex
    n = mesh.normals[i]
    side = np.cross(n, [0.3, 0.5, 0.8])
    side /= np.linalg.norm(side)
    direction = -math.cos(tilt) * n + math.sin(tilt) * side
    c = 0.03 * n[None]
    u1 = t.surfaces(c, f1 * direction[None])[0] - 0   # positions
    u2 = t.surfaces(c, ratio * f1 * direction[None])[0]
    d1 = u1.reshape(-1, 3)[i] - mesh.vertices[i]
    d2 = u2.reshape(-1, 3)[i] - mesh.vertices[i]
    assert np.linalg.norm(d2) >= np.linalg.norm(d1) * (1 - 1e-12)
    assert d1 @ direction > 0 and d2 @ direction > 0


def test_normal_load_displacement_decays_with_distance():
    mesh = icosphere_mesh(4)
    for law in ("linear", "stiffening"):
        t = AnalyticTissue(mesh, TissueParams(law=law))
        contact = mesh.normals[5]
        inward, _, s = radial_and_tangential(t, contact, -25.0 * contact)
        order = np.argsort(s)
        assert (np.diff(inward[order]) <= 1e-15).all()
        assert inward[order[-1]] == pytest.approx(0.0, abs=1e-12)   # anchored opposite the contact


@pytest.mark.parametrize("law", ["linear", "stiffening"])
@pytest.mark.parametrize("mesh", [latlong_mesh(21), latlong_mesh(31), icosphere_mesh(4)], ids=["441", "961", "ico4"])
def test_extreme_loads_never_cross_the_centre_or_invert_a_triangle(law, mesh):
    rng = np.random.default_rng(7)
    for E, patch in [(1.0, 0.002), (113e3, 0.015), (1e9, 0.03)]:
        t = AnalyticTissue(mesh, TissueParams(law=law, E=E, patch_radius=patch))
        B = 200
        c = rng.standard_normal((B, 3))
        c = 0.03 * c / np.linalg.norm(c, axis=1, keepdims=True)
        f = rng.standard_normal((B, 3)) * 10.0 ** rng.uniform(-3, 12, (B, 1))
        X = t.surfaces(c, f).reshape(B, -1, 3)
        assert np.isfinite(X).all()
        assert np.linalg.norm(X, axis=2).min() >= 0.2 * 0.03 * (1 - 1e-9)
        assert (triangle_orientation(X, mesh.triangles) > 0).all()


def test_saturation_keeps_the_field_shape_for_the_linear_law():
    mesh = latlong_mesh(21)
    t = AnalyticTissue(mesh)
    c, n = mesh.vertices[200:201], mesh.normals[200:201]
    small = t.displacements(c, -1.0 * n)[0]
    huge = t.displacements(c, -1e6 * n)[0]
    ratio = huge[np.abs(small) > 1e-9] / small[np.abs(small) > 1e-9]
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-9)           # same shape, saturated amplitude
    assert t.amplitudes(c, -1e6 * n)["indentation"][0] <= t.params.max_indentation * t.params.radius


@pytest.mark.parametrize("kwargs, match", [
    ({"E": 0.0}, r"E=0 is out of range"),
    ({"E": -5.0}, r"E=-5 is out of range"),
    ({"nu": 0.5}, r"nu=0.5 is out of range; allowed range \[0, 0.5\)"),
    ({"nu": float("nan")}, r"nu must be finite"),
    ({"law": "plastic"}, r"law='plastic' is not allowed"),
    ({"patch_radius": 0.1}, r"patch_radius=0.1 is out of range"),
])
def test_bad_tissue_parameters(kwargs, match):
    with pytest.raises(ValueError, match=match):
        TissueParams(**kwargs)


def test_bad_loads_are_refused():
    t = AnalyticTissue(latlong_mesh(9))
    good_c, good_f = np.array([[0, 0, 0.03]]), np.array([[0, 0, -1.0]])
    with pytest.raises(ValueError, match=r"forces must be finite; found nan"):
        t.surfaces(good_c, [[0, np.nan, -1.0]])
    with pytest.raises(ValueError, match=r"contacts\[0\].*must lie on the sphere of radius 0.03"):
        t.surfaces([[0, 0, 0.05]], good_f)
    with pytest.raises(ValueError, match=r"contacts has 1 rows but forces has 2"):
        t.surfaces(good_c, np.repeat(good_f, 2, axis=0))
    with pytest.raises(ValueError, match=r"forces must have trailing shape \(3\)"):
        t.surfaces(good_c, [[0, -1.0]])
    with pytest.raises(ValueError, match=r"mesh radius 0.05 m does not match params.radius 0.03 m"):
        AnalyticTissue(latlong_mesh(9, radius=0.05))
