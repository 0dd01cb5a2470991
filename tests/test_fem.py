"""The finite-element tongue against closed forms: homogeneous neo-Hookean stretch, Hooke's law in the
small-strain limit, equilibrium of the base with the load, mesh convergence, and refused solves."""

import dataclasses
import math

import numpy as np
import pytest

fe = pytest.importorskip("felupe")
from softenv.fem.mesh import (ball_mesh, ball_to_cube, base_cap, cube_hexahedra, cube_to_ball,  # noqa: E402
                              interpolate_nodal, surface_nodes)
from softenv.fem.tongue import FEParams, FETongue, NonConvergence  # noqa: E402
from softenv.fem.verification import stretch_unit_cube, uniaxial_closed_form  # noqa: E402
from softenv.geometry import paper_mesh  # noqa: E402

E, NU = 1.0e5, 0.49
PARAMS = FEParams(E=E, nu=NU)


@pytest.mark.parametrize("stretch", [1.6, 0.7])
def test_homogeneous_stretch_of_a_cube_matches_the_closed_form(stretch):
    lateral, force = stretch_unit_cube(stretch, PARAMS)
    want_lateral, want_stress = uniaxial_closed_form(stretch, PARAMS)
    assert lateral == pytest.approx(want_lateral, rel=1e-9)
    assert force == pytest.approx(want_stress, rel=1e-9)


def test_small_strain_limit_is_hookes_law():
    eps = 1e-6
    lateral, force = stretch_unit_cube(1.0 + eps, PARAMS, steps=1)
    assert force / eps == pytest.approx(E, rel=1e-5)                 # Young's modulus
    assert -(lateral - 1.0) / eps == pytest.approx(NU, rel=1e-4)      # Poisson's ratio


def test_ball_mesh_fills_the_ball_and_marks_surface_and_base():
    R = 0.03
    points, cells = ball_mesh(R, 8)
    region = fe.RegionHexahedron(fe.Mesh(points, cells, "hexahedron"))
    assert (region.dV > 0).all()                                          # no inverted or degenerate cell
    assert region.dV.sum() == pytest.approx(4 / 3 * math.pi * R ** 3, rel=0.03)
    surface = surface_nodes(points, R)
    assert surface.sum() == 6 * 8 * 8 + 2                                 # the cube's boundary nodes
    for cap_deg in (45.0, 90.0):
        cap = base_cap(points, R, cap_deg)
        angle = np.degrees(np.arccos(np.clip(-points[cap, 2] / R, -1, 1)))
        assert cap.any() and angle.max() <= cap_deg + 1e-9
        assert (points[~cap & surface, 2] > -R * math.cos(math.radians(cap_deg)) + 1e-12).all()


def test_paper_grid_points_are_found_in_the_mesh_and_fields_interpolate_as_the_elements_do():
    R = 0.03
    grid = paper_mesh(441, R).vertices
    cube = ball_to_cube(grid, R)
    assert np.abs(cube_to_ball(cube, R) - grid).max() < 1e-15
    assert np.allclose(np.abs(cube).max(axis=1), 1.0, atol=1e-12)             # on the cube's faces
    # a trilinear field is reproduced exactly; a smooth one converges at second order
    points, _ = cube_hexahedra(4)
    trilinear = np.stack([points[:, 0] * points[:, 1] * points[:, 2] - points[:, 1], 2.0 * points[:, 2]], axis=1)
    want = np.stack([cube[:, 0] * cube[:, 1] * cube[:, 2] - cube[:, 1], 2.0 * cube[:, 2]], axis=1)
    assert np.abs(interpolate_nodal(trilinear, cube, 4) - want).max() < 1e-14
    errors = []
    for n in (4, 8, 16):
        nodes = cube_to_ball(cube_hexahedra(n)[0], R)
        smooth = lambda x: np.sin(60.0 * x) * 1e-3  # noqa: E731  (a displacement field, m)
        errors.append(np.abs(interpolate_nodal(smooth(nodes), cube, n) - smooth(grid)).max())
    assert errors[1] < errors[0] / 3.0 and errors[2] < errors[1] / 3.0


@pytest.fixture(scope="module")
def tongue():
    return FETongue(FEParams(cells_per_side=4))


def test_the_base_balances_the_blade_and_the_patch_load_sums_to_the_force(tongue):
    force = np.array([6.0, -3.0, -30.0])
    contact = np.array([0.3, 0.1, 1.0])
    load = tongue.patch_load(contact, force)
    assert load.sum(axis=0) == pytest.approx(force, rel=1e-12)
    loaded = np.flatnonzero(np.abs(load).sum(axis=1))
    tip = tongue.points[loaded] / tongue.params.radius
    c = contact / np.linalg.norm(contact)
    assert np.degrees(np.arccos(tip @ c)).max() < np.degrees(tongue.params.patch_radius / tongue.params.radius) + 25
    solution = tongue.solve(contact, force, steps=4)
    for fraction, support in zip(solution.fractions, solution.support):
        assert support == pytest.approx(-fraction * force, abs=1e-8 * np.linalg.norm(force))
    assert np.all(solution.displacements[:, tongue.cap] == 0.0)


def test_indentation_converges_under_mesh_refinement():
    """Indentation of the patch's centre at half the design force on 2, 4 and 8 cells a side: the
    differences shrink (the observed order is in results/fem.md)."""
    depth = []
    for n in (2, 4, 8):
        t = FETongue(FEParams(cells_per_side=n))
        s = t.solve([0, 0, 1], [0, 0, -20.0], steps=2)
        depth.append(-s.displacements[-1, np.argmax(t.points[:, 2]), 2])
    assert abs(depth[2] - depth[1]) < 0.6 * abs(depth[1] - depth[0])
    assert 0.1 * t.params.radius < depth[-1] < 0.5 * t.params.radius


def test_a_solve_that_fails_names_the_case_and_the_load_step(tongue):
    with pytest.raises(NonConvergence, match=r"load step 1/5.*did not converge in 1 iterations"):
        FETongue(FEParams(cells_per_side=2, max_iterations=1)).solve([0, 0, 1], [0, 0, -40.0])
    with pytest.raises(NonConvergence, match=r"force \[0.0, 0.0, -100000.0\] N at \[0.0, 0.0, 1.0\], load step 1/2"):
        tongue.solve([0, 0, 1], [0.0, 0.0, -1e5], steps=2)


def test_bad_loads_are_refused_by_name(tongue):
    with pytest.raises(ValueError, match="force must be finite"):
        tongue.solve([0, 0, 1], [0.0, np.inf, -1.0])
    with pytest.raises(ValueError, match="contact"):
        tongue.solve([0, 0], [0.0, 0.0, -1.0])
    with pytest.raises(ValueError, match=r"contact=\[0.0, 0.0, 0.0\] must be a nonzero direction"):
        tongue.solve([0, 0, 0], [0.0, 0.0, -1.0])


@pytest.mark.parametrize("field, value, allowed", [("nu", 0.5, r"\[0, 0.4999\]"), ("E", -1.0, r"\[1, 1e\+09\]"),
                                                   ("cells_per_side", 1, r"\[2, 64\]"), ("cap_deg", 95.0, r"\[10, 90\]")])
def test_out_of_range_parameters_are_refused(field, value, allowed):
    with pytest.raises(ValueError, match=rf"{field}.*{allowed}"):
        FEParams(**{field: value})


def test_fe_paper_dataset_follows_the_paper_protocol_on_the_fe_tongue(tmp_path, monkeypatch):
    from softenv.datasets import ForceShapeData, paper_dataset
    from softenv.fem.data import fe_paper_dataset

    monkeypatch.setenv("SOFTENV_CACHE_DIR", str(tmp_path / "cache"))
    params = FEParams(cells_per_side=4)
    data = fe_paper_dataset(49, 2, 3, params=params, noise=0.0, echo=None)
    analytic = paper_dataset(49, 2, 3, noise=0.0, cache=False)
    assert np.array_equal(data.forces, analytic.forces)                  # same contacts and magnitudes
    assert data.shapes.shape == (6, 3 * 49) and data.contact_ids.tolist() == [0, 0, 0, 1, 1, 1]
    # each load step of a ramp is a sample: the second deformation's last sample, solved directly
    contact = data.forces[3, :3]
    tongue = FETongue(params)
    direct = tongue.solve(contact, [0.0, 0.0, -data.forces[5, 3]], steps=3)
    want = paper_mesh(49, params.radius).vertices + tongue.displacements_at(direct.displacements[-1],
                                                                            paper_mesh(49, params.radius).vertices)
    assert np.allclose(data.shapes[5].reshape(-1, 3), want, rtol=0, atol=1e-15)
    data.save(tmp_path / "fe.npz")
    again = ForceShapeData.load(tmp_path / "fe.npz")
    assert again.fe == data.fe and again.fe["cells_per_side"] == 4 and np.array_equal(again.shapes, data.shapes)


def test_ramps_resume_from_the_cache_and_workers_agree_bit_for_bit(tmp_path, monkeypatch):
    from softenv.fem import data as fe_data

    monkeypatch.setenv("SOFTENV_CACHE_DIR", str(tmp_path / "a"))
    params = FEParams(cells_per_side=2)
    grid = paper_mesh(49, params.radius)
    contacts = np.array([[0.0, 0.0, 0.03], [0.0, 0.01, 0.028]])
    solves = []
    original = FETongue.solve
    monkeypatch.setattr(FETongue, "solve", lambda self, *a, **k: solves.append(a) or original(self, *a, **k))
    failed = r"(?s)1 of 2 FE ramps failed .*ramp 1: \[0.0, 0.0, nan\] N.*ValueError: force must be finite"
    with pytest.raises(NonConvergence, match=failed):
        fe_data.solve_ramps(params, contacts, np.array([[0.0, 0.0, -5.0], [0.0, 0.0, np.nan]]), 3, grid, echo=None)
    assert len(solves) == 2
    # a "killed" generation rerun: the finished ramp is read back, only the other one is solved
    forces = np.array([[0.0, 0.0, -5.0], [1.0, 0.0, -5.0]])
    first = fe_data.solve_ramps(params, contacts, forces, 3, grid, echo=None)
    assert len(solves) == 3
    monkeypatch.setenv("SOFTENV_CACHE_DIR", str(tmp_path / "b"))           # nothing cached: two workers solve
    monkeypatch.setattr(FETongue, "solve", original)
    assert np.array_equal(fe_data.solve_ramps(params, contacts, forces, 3, grid, jobs=2, echo=None), first)


def test_fe_workspace_dataset_ramps_each_load_at_its_contact_point(tmp_path, monkeypatch):
    from softenv.fem.data import fe_workspace_dataset
    from softenv.forces import Workspace

    monkeypatch.setenv("SOFTENV_CACHE_DIR", str(tmp_path))
    params = FEParams(cells_per_side=4)
    workspace = Workspace((-0.005, -0.004, 5.0, -2.0), (0.005, 0.004, 15.0, 2.0))
    grid = paper_mesh(49, params.radius)
    data = fe_workspace_dataset(workspace, grid, params, n_contacts=2, n_loads=2, steps=2, echo=None)
    assert data.forces.shape == (8, 4) and data.contact_ids.tolist() == [0, 0, 0, 0, 1, 1, 1, 1]
    ends = data.forces[1::2]                                             # each ramp's last step: inside the box
    assert (ends >= np.array(workspace.low)).all() and (ends <= np.array(workspace.high)).all()
    assert np.array_equal(data.forces[0::2, :2], ends[:, :2]) and np.allclose(data.forces[0::2, 2:], ends[:, 2:] / 2)
    contact, force = data.layout.to_loads(ends[:1])
    direct = FETongue(params).solve(contact[0], force[0], steps=2)
    want = grid.vertices + FETongue(params).displacements_at(direct.displacements, grid.vertices)
    assert np.allclose(data.shapes[:2].reshape(2, -1, 3), want, rtol=0, atol=1e-15)


def test_a_failing_load_step_is_cut_back_and_reaches_the_same_equilibrium():
    force, contact = [-30.0, 0.0, -30.0], [0.8, 0.0, 0.6]
    with pytest.raises(NonConvergence, match="load step 1/1"):
        FETongue(FEParams(cells_per_side=4, cutbacks=0, max_iterations=8)).solve(contact, force, steps=1)
    one_step = FETongue(FEParams(cells_per_side=4, cutbacks=3, max_iterations=8)).solve(contact, force, steps=1)
    ramp = FETongue(FEParams(cells_per_side=4, cutbacks=0)).solve(contact, force, steps=4)
    assert len(one_step.fractions) == 1                                   # intermediate loads are not samples
    assert np.abs(one_step.displacements[-1] - ramp.displacements[-1]).max() < 1e-9 * 0.03   # hyperelastic: same state


def test_an_fe_scenes_data_regenerate_bit_for_bit_and_its_curve_is_the_patch_centres_indentation(tmp_path, monkeypatch):
    from softenv.fem.data import fe_scene_data
    from softenv.fem.scene_data import FERequest, FESceneData
    from softenv.geometry import make_mesh

    params = FEParams(cells_per_side=2)
    request = FERequest(params, make_mesh("latlong", 5, params.radius).spec(), (0.02, -0.008, 0.0, -5.0),
                        (0.05, 0.008, 20.0, 5.0), n_contacts=2, n_loads=1, seed=0, steps=2, n_test_contacts=1,
                        curve_steps=3)
    runs = []
    for name, jobs in (("a", 1), ("b", 2)):                      # from nothing each time, 1 and 2 workers
        monkeypatch.setenv("SOFTENV_CACHE_DIR", str(tmp_path / name))
        fe_scene_data(request, jobs=jobs, echo=None).save(tmp_path / f"{name}.npz")
        runs.append(np.load(tmp_path / f"{name}.npz"))
    for key in runs[0].files:
        if key != "__meta__":
            assert np.array_equal(runs[0][key], runs[1][key]), key
    data = FESceneData.load(tmp_path / "a.npz", request)
    assert data.train.n_samples == 4 and data.test.n_samples == 2
    # the contact curve: the solver's own displacement of the patch's centre under the press at the top
    tongue = FETongue(params)
    top = np.array([0.0, 0.0, params.radius])
    solution = tongue.solve(top, np.array([0.0, 0.0, -20.0]), 3)
    depth = -tongue.displacements_at(solution.displacements, top[None])[:, 0, 2]
    np.testing.assert_allclose(data.curve_depths, depth, rtol=1e-12)
    np.testing.assert_allclose(data.curve_loads, [20 / 3, 40 / 3, 20.0])


def test_a_tongue_s_times_as_stiff_deforms_under_a_force_as_the_tongue_under_that_force_over_s():
    """What the torch twin's ``tissue_stiffness`` rests on for the FE tongue: its neo-Hookean energy is
    proportional to E at a fixed Poisson ratio, so the solve at (F, s E) is the solve at (F / s, E)."""
    force, contact, s = np.array([5.0, -2.0, -30.0]), np.array([0.3, 0.1, 1.0]), 1.6
    base = FEParams(cells_per_side=2)
    stiff = FETongue(dataclasses.replace(base, E=base.E * s)).solve(contact, force, steps=2)
    scaled = FETongue(base).solve(contact, force / s, steps=2)
    np.testing.assert_allclose(stiff.displacements[-1], scaled.displacements[-1], rtol=0,
                               atol=1e-7 * np.abs(scaled.displacements[-1]).max())
