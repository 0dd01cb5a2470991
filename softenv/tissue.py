r"""Analytic tissue model: the deformed surface of an elastic sphere under a force on a contact patch.

A load is a contact point ``c`` on the sphere and a force vector ``F`` (newtons) acting on the
tissue there. It splits into a compressive normal load ``P = -F . n_c`` and a tangential load
``Q = F + P n_c``. Each vertex at geodesic distance ``s`` from ``c`` moves by

    u = -w(s) n  +  A G(s) t,        w(s) = W G(s),
    G(s) = omega(s) / sqrt(1 + (s / h)^2),    omega(s) = (1 + cos(s / R)) / 2,

where ``n`` is the vertex normal and ``t = Qhat - (Qhat . n) n`` carries the load's direction into
the vertex's tangent plane.

* ``1 / sqrt(1 + (s/h)^2)`` with ``h = a / 2`` (``a`` the contact-patch radius) is the Boussinesq
  point-load decay ``u_z = P (1 - nu^2) / (pi E s)`` spread over the patch: its far field is exactly
  Boussinesq's and its centre value ``W = 2 (1 - nu^2) P / (pi E a)`` is the centre deflection under
  a uniform pressure on a circular patch of radius ``a`` (Johnson, *Contact Mechanics*, 3.4). It is
  never singular.
* The tangential drag uses Cerruti's far field averaged over direction,
  ``|u_t| = Q (1 + nu)(2 - nu) / (2 pi E s)``, spread the same way: ``A = (1 + nu)(2 - nu) Q / (pi E a)``.
* ``omega`` anchors the sphere at the point opposite the contact (the tongue's base): displacement
  decays with distance and vanishes there, so the body does not translate as a whole.

Laws:

* ``linear``: ``W`` and ``A`` proportional to the loads (the paper's regime): with a fixed force
  direction ``X(c, F) = X0 + F U(c)``, so a data set of D contact points has rank D.
* ``stiffening``: Fung-type exponential strain stiffening, ``P = (delta_s / C_n)(exp(W / delta_s) - 1)``,
  i.e. ``W = delta_s log(1 + C_n P / delta_s)`` (same for ``A``), and the contact widens as in Hertz
  contact, ``h = sqrt(a^2 + R |W|) / 2``. Same compliance as ``linear`` at small loads; the field's
  shape changes with load, so more PCA components are needed per deformation.

Saturation (both laws, documented physical limit). Each of the two fields is scaled by its own
factor, so saturation never changes a field's shape. The indentation ``W`` is limited to
``max_indentation * R`` (the surface never reaches the centre); then the drag ``A`` is limited so that
the angular strain of the surface map, bounded by ``R |grad(u_t / (R - w))|``, stays below
``max_angular_strain < 1``: the map of the sphere onto itself remains a diffeomorphism, so nothing
folds and no triangle turns inside out. For a load at share ``x`` of its limit the factor is 1 while
``x <= linear_fraction`` (the response is exactly linear there) and ``phi(x) / x`` beyond, where
``phi`` rises smoothly (``tanh``, C1 at the knee) toward 1: the field approaches but never exceeds
the limit. A sideways force never reduces the indentation; a deep indentation leaves less room for
drag (the crater's walls steepen the strain).

Clinical scaling. A free 3 cm sphere at tongue stiffness (E ~ 8 kPa by MR elastography, Cheng 2011)
would be indented far beyond its radius by laryngoscopy forces (peak ~40 N, Bucx 1992): Hertz gives
d/R > 1 (the dimensionless load ``F (1 - nu^2) / (E R^2)`` is ~4). The small-strain solution is
only meaningful for indentations of a fraction of the radius, so softenv uses an **effective
modulus**, chosen so that the design force gives a chosen indentation ``f R``:
``E_eff = 2 (1 - nu^2) F_max / (pi a * f R)``, i.e. a dimensionless design load of ``pi a f / (2 R)``
(0.31 by default). The default
(``F_max = 40 N``, ``f = 0.4``, ``a = 15 mm``, ``R = 30 mm``, ``nu = 0.45``) gives
``E_eff ~ 113 kPa``, about 14 times the tongue's own modulus: the factor stands for the support and
confinement of the tongue in the oral cavity, which a free sphere lacks. See :meth:`TissueParams.for_clinical_forces`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from ._validation import check_array, check_choice, check_real
from .geometry import SphereMesh

LAWS = ("linear", "stiffening")

TONGUE_RADIUS_M = 0.03        # half of a tongue thickness of ~5-6 cm
TONGUE_POISSON = 0.45         # nu 0.45-0.49 for soft tissue
BLADE_PATCH_RADIUS_M = 0.015  # half-width of a Macintosh blade's contact with the dorsum
CLINICAL_MAX_FORCE_N = 40.0   # peak laryngoscopy force 35 +- 12 N (Bucx 1992), 38 N (Hastings 1996)
DESIGN_INDENTATION = 0.4      # clinical peak force indents the dorsum by 40 % of the radius

_MAX_SLOPE = 2.0 / (3.0 * math.sqrt(3.0))  # max |d/dx (1 + x^2)^(-1/2)|, at x = 1/sqrt(2)
_CONTACT_TOLERANCE = 1e-3                   # relative distance of a contact point from the surface


def effective_modulus(max_force: float = CLINICAL_MAX_FORCE_N, indentation: float = DESIGN_INDENTATION,
                      nu: float = TONGUE_POISSON, radius: float = TONGUE_RADIUS_M,
                      patch_radius: float = BLADE_PATCH_RADIUS_M) -> float:
    """Effective Young's modulus (Pa) at which ``max_force`` (N) indents the linear sphere by ``indentation * radius``."""
    max_force = check_real(max_force, "max_force", 0.0, None, low_open=True)
    indentation = check_real(indentation, "indentation", 0.0, 0.95, low_open=True)
    return 2.0 * (1.0 - nu ** 2) * max_force / (math.pi * patch_radius * indentation * radius)


@dataclass(frozen=True)
class TissueParams:
    """Material and geometry of the tissue sphere (SI units).

    Attributes:
        law: ``"linear"`` or ``"stiffening"`` (see module docstring).
        E: effective Young's modulus, Pa (> 0). Default: 40 N indents 40 % of the radius.
        nu: Poisson's ratio, in [0, 0.5).
        radius: sphere radius, m (> 0).
        patch_radius: contact-patch radius ``a``, m, in (0, radius].
        stiffening_depth: Fung depth ``delta_s`` as a fraction of the radius (stiffening law).
        max_indentation: saturation limit of the indentation, fraction of the radius, in (0, 0.95].
        max_angular_strain: saturation limit of the surface map's angular strain, in (0, 0.9].
        linear_fraction: share of the safe limit below which the response is unsaturated, in (0, 1).
    """

    law: str = "linear"
    E: float = effective_modulus()
    nu: float = TONGUE_POISSON
    radius: float = TONGUE_RADIUS_M
    patch_radius: float = BLADE_PATCH_RADIUS_M
    stiffening_depth: float = 0.2
    max_indentation: float = 0.8
    max_angular_strain: float = 0.5
    linear_fraction: float = 0.75

    def __post_init__(self) -> None:
        check_choice(self.law, "law", LAWS)
        check_real(self.E, "E", 0.0, None, low_open=True)
        check_real(self.nu, "nu", 0.0, 0.5, high_open=True)
        check_real(self.radius, "radius", 0.0, None, low_open=True)
        check_real(self.patch_radius, "patch_radius", 0.0, self.radius, low_open=True)
        check_real(self.stiffening_depth, "stiffening_depth", 0.0, None, low_open=True)
        check_real(self.max_indentation, "max_indentation", 0.0, 0.95, low_open=True)
        check_real(self.max_angular_strain, "max_angular_strain", 0.0, 0.9, low_open=True)
        check_real(self.linear_fraction, "linear_fraction", 0.0, 1.0, low_open=True, high_open=True)

    @classmethod
    def for_clinical_forces(cls, max_force: float = CLINICAL_MAX_FORCE_N,
                            indentation: float = DESIGN_INDENTATION, **overrides: Any) -> "TissueParams":
        """Parameters whose effective modulus maps ``max_force`` newtons to ``indentation * radius``."""
        base = replace(cls(), **{k: v for k, v in overrides.items() if k != "E"})
        E = effective_modulus(max_force, indentation, base.nu, base.radius, base.patch_radius)
        return replace(base, E=E)

    @property
    def normal_compliance(self) -> float:
        """Contact indentation per newton of normal load, m/N: ``2 (1 - nu^2) / (pi E a)``."""
        return 2.0 * (1.0 - self.nu ** 2) / (math.pi * self.E * self.patch_radius)

    @property
    def tangential_compliance(self) -> float:
        """Contact drag per newton of tangential load, m/N: ``(1 + nu)(2 - nu) / (pi E a)``."""
        return (1.0 + self.nu) * (2.0 - self.nu) / (math.pi * self.E * self.patch_radius)

    def dimensionless_load(self, force: float) -> float:
        """``F (1 - nu^2) / (E R^2)``: small-strain theory needs this of order 0.1 or less."""
        return force * (1.0 - self.nu ** 2) / (self.E * self.radius ** 2)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


class AnalyticTissue:
    """Deformed surfaces of a sphere mesh under batches of loads.

    Args:
        mesh: the surface sampling; its radius must equal ``params.radius``.
        params: tissue parameters.
        chunk: loads evaluated per vectorised block (bounds temporary memory).
    """

    def __init__(self, mesh: SphereMesh, params: TissueParams | None = None, *, chunk: int = 256) -> None:
        self.params = params if params is not None else TissueParams()
        if not math.isclose(mesh.radius, self.params.radius, rel_tol=1e-12):
            raise ValueError(f"mesh radius {mesh.radius:g} m does not match params.radius "
                             f"{self.params.radius:g} m; build both with the same radius")
        self.mesh = mesh
        self.chunk = int(chunk)
        self._normals_T = np.ascontiguousarray(mesh.normals.T)

    @property
    def rest_shape(self) -> np.ndarray:
        """Undeformed surface as a flat ``(3 n_vertices,)`` vector (x1, y1, z1, x2, ...)."""
        return self.mesh.vertices.reshape(-1).copy()

    def surfaces(self, contacts: np.ndarray, forces: np.ndarray) -> np.ndarray:
        """Deformed surfaces ``(B, 3 n_vertices)`` for contact points ``(B, 3)`` and force vectors ``(B, 3)``.

        Contact points must lie on the sphere to within 0.1 % of the radius; they are then
        projected onto it exactly.
        """
        contacts, forces = self._check_loads(contacts, forces)
        out = np.empty((contacts.shape[0], 3 * self.mesh.n_vertices))
        for start in range(0, contacts.shape[0], self.chunk):
            block = slice(start, start + self.chunk)
            out[block] = self._positions(contacts[block], forces[block]).reshape(-1, out.shape[1])
        return out

    def displacements(self, contacts: np.ndarray, forces: np.ndarray) -> np.ndarray:
        """Vertex displacements ``(B, n_vertices, 3)`` from the rest shape."""
        shapes = self.surfaces(contacts, forces).reshape(-1, self.mesh.n_vertices, 3)
        return shapes - self.mesh.vertices

    def amplitudes(self, contacts: np.ndarray, forces: np.ndarray) -> dict[str, np.ndarray]:
        """Per-load contact indentation ``W``, drag ``A`` (m, after saturation), width ``h`` and saturation factor."""
        contacts, forces = self._check_loads(contacts, forces)
        n_c = contacts / self.params.radius
        W, A, h, _ = self._raw_amplitudes(n_c, forces)
        m_n, m_t = self._saturation(W, A, h)
        return {"indentation": m_n * W, "drag": m_t * A, "half_width": h,
                "normal_saturation": m_n, "tangential_saturation": m_t}

    # -- internals --------------------------------------------------------------------------------

    def _check_loads(self, contacts: Any, forces: Any) -> tuple[np.ndarray, np.ndarray]:
        c = check_array(contacts, "contacts", ndim=(1, 2), shape=(3,)).reshape(-1, 3)
        f = check_array(forces, "forces", ndim=(1, 2), shape=(3,)).reshape(-1, 3)
        if c.shape[0] != f.shape[0]:
            raise ValueError(f"contacts has {c.shape[0]} rows but forces has {f.shape[0]}; they must match")
        R = self.params.radius
        dist = np.linalg.norm(c, axis=1)
        off = np.abs(dist - R) > _CONTACT_TOLERANCE * R
        if off.any():
            i = int(np.argmax(off))
            raise ValueError(f"contacts[{i}]={c[i].tolist()} lies {dist[i]:.6g} m from the centre; contact "
                             f"points must lie on the sphere of radius {R:g} m (to within {_CONTACT_TOLERANCE:.0e} R)")
        return c * (R / dist)[:, None], f

    def _raw_amplitudes(self, n_c: np.ndarray, forces: np.ndarray) -> Any:
        p = self.params
        P = -np.einsum("bi,bi->b", forces, n_c)           # compressive normal load, N
        Q = forces + P[:, None] * n_c                      # tangential load vector, N
        Qmag = np.linalg.norm(Q, axis=1)
        Qhat = np.divide(Q, Qmag[:, None], out=np.zeros_like(Q), where=Qmag[:, None] > 0)
        if p.law == "linear":
            W = p.normal_compliance * P
            A = p.tangential_compliance * Qmag
            h = np.full_like(P, p.patch_radius / 2)
        else:
            ds = p.stiffening_depth * p.radius
            W = np.sign(P) * ds * np.log1p(p.normal_compliance * np.abs(P) / ds)
            A = ds * np.log1p(p.tangential_compliance * Qmag / ds)
            h = np.sqrt(p.patch_radius ** 2 + p.radius * np.abs(W)) / 2
        return W, A, h, Qhat

    def _saturation(self, W: np.ndarray, A: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Multipliers ``(m_n, m_t)`` in (0, 1] of the normal and tangential fields (1 = unsaturated)."""
        p = self.params
        R = p.radius
        m_n = _soft_limit(np.abs(W) / (p.max_indentation * R), p.linear_fraction)
        W_eff = m_n * W
        gap = R - np.maximum(W_eff, 0.0)          # distance of the indented contact from the centre
        L_G = _MAX_SLOPE / h + 1.0 / (2.0 * R)     # max |G'|: profile slope plus anchor-window slope
        L_1 = L_G + 2.0 / R                        # max |grad(G t)|, since |grad t| <= 2 / R
        strain = A * R * (L_1 / gap + np.abs(W_eff) * L_G / gap ** 2)
        m_t = _soft_limit(strain / p.max_angular_strain, p.linear_fraction)
        return m_n, m_t

    def _positions(self, contacts: np.ndarray, forces: np.ndarray) -> np.ndarray:
        R = self.params.radius
        N = self.mesh.normals
        n_c = contacts / R
        W, A, h, Qhat = self._raw_amplitudes(n_c, forces)
        m_n, m_t = self._saturation(W, A, h)
        cos = n_c @ self._normals_T                                         # (B, n)
        np.clip(cos, -1.0, 1.0, out=cos)
        # geodesic distance s = 2 R asin(sqrt((1 - cos) / 2)); profile G = window / sqrt(1 + (s/h)^2)
        s = np.subtract(1.0, cos)
        s *= 0.5
        np.sqrt(s, out=s)
        np.arcsin(s, out=s)
        s *= (2.0 * R) / h[:, None]
        np.square(s, out=s)
        s += 1.0
        np.sqrt(s, out=s)
        G = np.add(1.0, cos, out=cos)
        G *= 0.5
        G /= s
        drag = (m_t * A)[:, None] * G                                      # tangential amplitude field
        radial = R - (m_n * W)[:, None] * G - drag * (Qhat @ self._normals_T)
        out = radial[:, :, None] * N[None]                                  # (R - w) n - drag (Qhat . n) n
        out += drag[:, :, None] * Qhat[:, None, :]                          # + drag Qhat
        return out

def _soft_limit(x: np.ndarray, knee: float) -> np.ndarray:
    """Multiplier ``m`` with ``m x = x`` for ``x <= knee`` and ``m x -> 1`` smoothly (C1, tanh) beyond."""
    over = x > knee
    safe_x = np.where(over, x, 1.0)
    phi = knee + (1.0 - knee) * np.tanh((safe_x - knee) / (1.0 - knee))
    return np.where(over, phi / safe_x, 1.0)
