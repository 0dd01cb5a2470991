"""The finite-element tongue's parameters (numpy only: a scene reads them without importing FElupe)."""

from __future__ import annotations

from dataclasses import dataclass

from .._validation import check_int, check_real
from ..tissue import BLADE_PATCH_RADIUS_M, TONGUE_RADIUS_M, effective_modulus

FE_POISSON = 0.49      # nearly incompressible tissue (0.45-0.5 reported; 0.49 for FE tongues)


@dataclass(frozen=True)
class FEParams:
    """The finite-element tongue's parameters (SI units)."""

    radius: float = TONGUE_RADIUS_M                  # m
    E: float = effective_modulus(nu=FE_POISSON)      # Pa, small-strain Young's modulus
    nu: float = FE_POISSON                           # small-strain Poisson's ratio, [0, 0.4999]
    patch_radius: float = BLADE_PATCH_RADIUS_M       # m, radius of the blade's contact patch
    cap_deg: float = 90.0                            # deg, half-angle of the fixed base cap
    cells_per_side: int = 8                          # hexahedra along the mapped cube's edge
    tol: float = 1e-9                                # Newton: residual norm / load norm
    max_iterations: int = 60                         # Newton iterations per load step (or cut-back part)
    cutbacks: int = 3                                # halvings of a load step whose Newton solve fails

    def __post_init__(self) -> None:
        check_real(self.radius, "radius", 1e-4, 1.0)
        check_real(self.E, "E", 1.0, 1e9)
        check_real(self.nu, "nu", 0.0, 0.4999)
        check_real(self.patch_radius, "patch_radius", self.radius / 1000, self.radius)
        check_real(self.cap_deg, "cap_deg", 10.0, 90.0)
        check_int(self.cells_per_side, "cells_per_side", 2, 64)
        check_real(self.tol, "tol", 1e-14, 1e-3)
        check_int(self.max_iterations, "max_iterations", 1, 200)
        check_int(self.cutbacks, "cutbacks", 0, 10)

    @property
    def mu(self) -> float:
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def bulk(self) -> float:
        return self.E / (3.0 * (1.0 - 2.0 * self.nu))
