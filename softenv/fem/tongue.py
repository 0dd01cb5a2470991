"""The finite-element tongue: a nearly incompressible neo-Hookean ball, its base fixed, pressed by the
blade's contact patch, solved with load steps and a Newton method that never accepts an inverted
element.

Model
-----
* Body: the scene's sphere (radius ``R``), hexahedra from :func:`softenv.fem.mesh.ball_mesh`.
* Material: neo-Hookean, ``psi = mu / 2 (I1_bar - 3) + K / 2 (J - 1)^2`` with ``mu = E / (2 (1 + nu))``
  and ``K = E / (3 (1 - 2 nu))`` (so the small-strain limit is Hooke's law with ``E``, ``nu``).
* Elements: trilinear hexahedra with a constant pressure and volume ratio per cell (the
  three-field "mean dilatation" Q1/P0/P0 element of FElupe's ``SolidBodyNearlyIncompressible``), a
  mixed u-p element that does not lock as ``nu -> 0.5``.
* Base: the surface within ``cap_deg`` (90 deg: the lower hemisphere) of the pole opposite the
  dorsum is fixed. The tongue's lower half lies in the floor of the mouth (genioglossus and
  hyoglossus on the mandible and hyoid), which holds it against the blade's torque. Measured here, a
  45 deg cap let the ball rock on its base: 1 N sideways moved the top 3.9 mm (1 N downward: 0.4 mm)
  and Newton lost the solution from ~6 N off-centre, a tipping-over the tongue in the mouth does not do.
* Load: the blade's force ``F`` (normal and tangential parts alike) as a uniform dead traction on the
  geodesic disc of ``patch_radius`` around the contact point (the analytic tissue's patch), applied
  at the surface's Gauss points (at least 8 across the patch's radius on any mesh) and scaled so
  that it sums to ``F`` exactly. Limit measured here: on 16 cells a side the design force (40 N,
  10 load steps) is not reached (the last step's Newton updates invert elements under the patch's
  rim); 8 cells a side reach it, and 16 reach 20 N.
* Solve: ``steps`` equal load steps, each by Newton's method on the free degrees of freedom. A Newton
  update moves no node more than a quarter cell (a trust region: far from the solution, full steps
  overshoot into folded states) and is halved until every quadrature point's ``det F`` and every
  cell's volume ratio stay positive; a load step whose Newton solve fails is cut into halves (``cutbacks`` times at most,
  intermediate loads are not samples); a step that still does not converge raises
  :class:`NonConvergence` naming the case and the load step reached, and nothing is returned for it.

This module imports FElupe (the ``fem`` extra); nothing on an env's path imports it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import felupe as fe
import numpy as np

from .._validation import check_finite, check_int, real_array
from .mesh import ball_mesh, ball_to_cube, base_cap, interpolate_nodal, surface_nodes
from .params import FEParams



class NonConvergence(RuntimeError):
    """A finite-element solve that did not converge (never written as data)."""


@dataclass
class FESolution:
    """A load ramp's converged states: ``fractions[i]`` of the load gave ``displacements[i]``."""

    fractions: np.ndarray        # (steps,)
    displacements: np.ndarray    # (steps, m, 3) m, at the mesh's points
    support: np.ndarray          # (steps, 3) N, total force of the base on the tongue
    iterations: list[int]        # Newton iterations per step


def _values(field: fe.FieldContainer) -> np.ndarray:
    return np.concatenate([f.values.ravel() for f in field.fields])


def _inverted(body: fe.SolidBodyNearlyIncompressible) -> bool:
    """Whether any quadrature point's ``det F`` or any cell's volume ratio is <= 0 (after an assembly)."""
    F = body.results.kinematics[0]
    return not (np.all(np.linalg.det(F.transpose(2, 3, 0, 1)) > 0) and np.all(body.results.state.J > 0))


def newton(body: fe.SolidBodyNearlyIncompressible, field: fe.FieldContainer, free: np.ndarray, fixed: np.ndarray,
           external: np.ndarray, imposed: np.ndarray | None, tol: float, max_iterations: int, what: str,
           max_move: float = math.inf) -> tuple[int, np.ndarray]:
    """Solve ``f_int(u) = external`` on the ``free`` dofs, the ``fixed`` ones moved to ``imposed``
    (their current values where None), in place. The imposed motion enters through the first Newton
    update, so the free dofs follow it at once.

    Converged when the free dofs' residual is ``tol`` of the forces in play (the load, or the fixed
    dofs' reactions). Globalisation: once the fixed dofs are in place an update is scaled so that no
    node moves more than ``max_move`` (m), then halved until no element inverts (every quadrature
    point's ``det F > 0`` and every cell's volume ratio ``J > 0``). Returns the iterations taken and
    the converged internal force vector (its fixed dofs are the supports' reactions); raises
    :class:`NonConvergence` naming ``what`` otherwise.
    """
    imposed = _values(field)[fixed] if imposed is None else imposed
    norm = scale = math.nan
    for iteration in range(max_iterations + 1):
        internal = np.asarray(body.assemble.vector(field).todense()).ravel()
        residual = internal - external
        # relative to the forces in play: the load, or the supports' reactions under imposed motion
        scale = max(float(np.linalg.norm(external[free])), float(np.linalg.norm(internal[fixed])), 1e-300)
        norm = float(np.linalg.norm(residual[free]))
        in_place = np.allclose(_values(field)[fixed], imposed, rtol=1e-12, atol=1e-300)
        if not math.isfinite(norm) or iteration == max_iterations:
            break
        if norm <= tol * scale and in_place:
            return iteration, internal
        system = fe.solve.partition(field, body.assemble.matrix(field), free, fixed, r=residual)
        du = fe.solve.solve(*system, ext0=imposed)
        saved = body.checkpoint()
        # a trust region: no node moves more than max_move in one update (far from the solution, full
        # Newton steps overshoot into folded states that no halving recovers from)
        alpha = min(1.0, max_move / max(float(np.abs(du[free]).max()), 1e-300)) if in_place else 1.0
        while True:
            field += alpha * du
            with np.errstate(invalid="ignore"):                 # an inverted trial is refused just below
                body.assemble.vector(field)                     # updates F, J and the cell pressures
            if not _inverted(body):
                break
            body.restore(saved)
            alpha /= 2.0
            if alpha < 1.0 / 1024:
                raise NonConvergence(f"{what}: every Newton update inverts an element (residual {norm:.3g} of "
                                     f"{scale:.3g} N)")
    raise NonConvergence(f"{what}: Newton did not converge in {max_iterations} iterations (residual "
                         f"{norm:.3g} of {scale:.3g} N, tol {tol:g})")


class FETongue:
    """The finite-element tongue of :class:`FEParams`; :meth:`solve` presses it once."""

    def __init__(self, params: FEParams = FEParams()) -> None:
        self.params = p = params
        points, cells = ball_mesh(p.radius, p.cells_per_side)
        self.mesh = fe.Mesh(points, cells, "hexahedron")
        self.region = fe.RegionHexahedron(self.mesh)
        self.points = points
        self.surface = surface_nodes(points, p.radius)
        self.cap = base_cap(points, p.radius, p.cap_deg)
        # Gauss points on each surface face, enough (>= 8 across the patch's radius) that the patch's
        # sharp rim falls between points a fraction of its radius apart on every mesh
        face_edge = math.pi * p.radius / (2 * p.cells_per_side)
        per_edge = min(max(math.ceil(8 * face_edge / p.patch_radius), 2), 12)
        boundary = fe.RegionHexahedronBoundary(self.mesh, quadrature=fe.GaussLegendreBoundary(order=per_edge - 1, dim=3),
                                               mask=self.surface)
        # the surface's quadrature points: hexahedron shape functions at its faces' Gauss points
        self._face_cells = boundary.mesh.cells                               # (faces, 8)
        self._face_h = boundary.h[:, :, 0]                                   # (8, q)
        face_x = np.einsum("aq,fai->fqi", self._face_h, points[self._face_cells])
        self._face_dir = face_x / np.linalg.norm(face_x, axis=-1, keepdims=True)  # (faces, q, 3) unit
        self._face_area = np.linalg.norm(boundary.dA, axis=0).T             # (faces, q)

    def patch_load(self, contact: np.ndarray, force: np.ndarray) -> np.ndarray:
        """Nodal forces ``(m, 3)`` of ``force`` (N) spread uniformly over the patch around ``contact``."""
        p = self.params
        c = np.asarray(contact, dtype=float)
        c = c / np.linalg.norm(c)
        cosine = np.clip(self._face_dir @ c, -1.0, 1.0)
        inside = np.arccos(cosine) * p.radius <= p.patch_radius
        weight = self._face_area * inside
        total = weight.sum()
        if total <= 0.0:
            raise ValueError(f"patch_radius={p.patch_radius:g} m covers no surface quadrature point of a mesh with "
                             f"cells_per_side={p.cells_per_side}: refine the mesh or widen the patch")
        nodal = np.einsum("aq,fq->fa", self._face_h, weight) / total        # shares of the force, sum 1
        load = np.zeros_like(self.points)
        np.add.at(load, self._face_cells, nodal[:, :, None] * np.asarray(force, dtype=float))
        return load

    def solve(self, contact: np.ndarray, force: np.ndarray, steps: int = 5) -> FESolution:
        """Ramp ``force`` (N) on the patch at ``contact`` (a direction from the centre) in ``steps``."""
        steps = check_int(steps, "steps", 1, 1000)
        contact = real_array(contact, "contact", (3,)).astype(float)
        force = real_array(force, "force", (3,)).astype(float)
        check_finite(contact, "contact")
        check_finite(force, "force")
        if not np.linalg.norm(contact) > 0.0:
            raise ValueError(f"contact={contact.tolist()} must be a nonzero direction from the centre")
        p = self.params
        field = fe.FieldContainer([fe.Field(self.region, dim=3)])
        body = fe.SolidBodyNearlyIncompressible(fe.NeoHooke(mu=p.mu), field, bulk=p.bulk)
        fixed_dofs, free_dofs = fe.dof.partition(field, {"base": fe.Boundary(field[0], mask=self.cap)})
        load = self.patch_load(contact, force).ravel()
        fractions = np.arange(1, steps + 1) / steps
        out, support, iterations = [], [], []

        def advance(start: float, end: float, what: str, cutbacks: int) -> tuple[int, np.ndarray]:
            """Newton from the converged load ``start`` to ``end``; where it fails, the increment is halved
            (``cutbacks`` times at most) and the halves are solved in turn: only ``end`` is a sample.
            Returns the iterations and the internal forces at ``end``."""
            saved = body.checkpoint()
            try:
                return newton(body, field, free_dofs, fixed_dofs, end * load, None, p.tol, p.max_iterations, what,
                              max_move=0.25 * 2.0 * p.radius / p.cells_per_side)
            except NonConvergence:
                if cutbacks == 0:
                    raise
                body.restore(saved)
                middle = (start + end) / 2
                first, _ = advance(start, middle, what, cutbacks - 1)
                second, internal = advance(middle, end, what, cutbacks - 1)
                return first + second, internal

        for i, fraction in enumerate(fractions):
            what = (f"force {force.tolist()} N at {contact.tolist()}, load step {i + 1}/{steps} "
                    f"(increments down to 1/{2 ** p.cutbacks} of a step)")
            count, internal = advance(fraction - 1 / steps, fraction, what, p.cutbacks)
            iterations.append(count)
            support.append(internal.reshape(-1, 3)[self.cap].sum(axis=0))
            out.append(field[0].values.copy())
        return FESolution(fractions, np.array(out), np.array(support), iterations)

    def displacements_at(self, displacements: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Displacements ``(..., len(points), 3)`` at points of the undeformed ball (the paper's surface
        grids, say) from nodal ``displacements`` ``(..., m, 3)``: the elements' own interpolation."""
        cube = ball_to_cube(points, self.params.radius)
        return interpolate_nodal(displacements, cube, self.params.cells_per_side)
