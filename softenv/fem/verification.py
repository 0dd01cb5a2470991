"""Closed-form cases the finite-element tongue is checked against (tests and ``results/fem.md``)."""

from __future__ import annotations

import felupe as fe
import numpy as np
from scipy.optimize import brentq

from .mesh import cube_hexahedra
from .tongue import FEParams, newton


def uniaxial_closed_form(stretch: float, params: FEParams) -> tuple[float, float]:
    """Lateral stretch and nominal axial stress (Pa) of the tongue's material,
    ``psi = mu/2 (I1_bar - 3) + K/2 (J - 1)^2``, under ``F = diag(l, l, stretch)`` with no lateral stress."""
    mu, K = params.mu, params.bulk

    def cauchy(lam: float) -> tuple[float, float]:        # lam: the lateral stretch
        J = lam * lam * stretch
        i1 = 2 * lam * lam + stretch * stretch
        dev = mu * J ** (-5 / 3)
        return dev * (lam * lam - i1 / 3) + K * (J - 1), dev * (stretch * stretch - i1 / 3) + K * (J - 1)

    lateral = brentq(lambda lam: cauchy(lam)[0], 0.2, 3.0, xtol=1e-15, rtol=1e-15)
    return lateral, cauchy(lateral)[1] * lateral * lateral     # nominal: J sigma / stretch = sigma l^2


def stretch_unit_cube(stretch: float, params: FEParams, steps: int = 4) -> tuple[float, float]:
    """The FE unit cube (2 x 2 x 2 of the tongue's cells), symmetry planes at x, y, z = 0, its top face
    moved to z = ``stretch`` in ``steps``: returns the lateral stretch and the top face's force (N,
    = nominal stress in Pa on the unit face)."""
    points, cells = cube_hexahedra(2)
    points = (points + 1.0) / 2.0
    mesh = fe.Mesh(points, cells, "hexahedron")
    field = fe.FieldContainer([fe.Field(fe.RegionHexahedron(mesh), dim=3)])
    body = fe.SolidBodyNearlyIncompressible(fe.NeoHooke(mu=params.mu), field, bulk=params.bulk)
    top = np.isclose(points[:, 2], 1.0)
    u = field[0]
    bounds = {"x": fe.Boundary(u, fx=0.0, skip=(0, 1, 1)), "y": fe.Boundary(u, fy=0.0, skip=(1, 0, 1)),
              "z": fe.Boundary(u, fz=0.0, skip=(1, 1, 0)), "top": fe.Boundary(u, mask=top, skip=(1, 1, 0))}
    fixed, free = fe.dof.partition(field, bounds)
    for s in np.linspace(1.0, stretch, steps + 1)[1:]:
        imposed = u.values.copy()
        imposed[top, 2] = s - 1.0
        _, internal = newton(body, field, free, fixed, np.zeros(imposed.size), imposed.ravel()[fixed], 1e-8,
                             params.max_iterations, f"unit cube stretched to {s:g}")
    force = internal.reshape(-1, 3)[top, 2].sum()
    corner = np.argmax(points.sum(axis=1))
    return 1.0 + u.values[corner, 0], float(force)
