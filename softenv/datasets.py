"""Force-vector / surface-shape data sets: the paper's protocol and workspace samples for scenes.

:func:`paper_dataset` follows the paper: a sphere sampled on 441 or 961 points, up to 10 point-force
deformations (contact points spread over the dorsum) times 11 force magnitudes, a fixed force
direction (straight down), and small white noise. :func:`workspace_dataset` samples a scene's
workspace (contact points over a patch of the dorsum, normal and sideways loads) with a Latin
hypercube or Sobol design. Both return a :class:`ForceShapeData`, cached on disk as a versioned
``.npz``; splits hold out whole contact points (:func:`split_by_contact`) or random rows
(:func:`split_rows`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from . import _cache
from ._artifact import load_artifact, require_arrays, save_artifact
from ._validation import check_array, check_choice, check_int, check_real
from .forces import ForceLayout, PaperLayout, Workspace, layout_from_dict, sample_workspace
from .geometry import SphereMesh, mesh_from_spec, paper_mesh
from .tissue import AnalyticTissue, TissueParams

DATA_FORMAT = "softenv.ForceShapeData"
DATA_VERSION = 1

PAPER_MAX_FORCE_N = 8.0      # keeps every paper deformation in the linear law's unsaturated range
PAPER_CAP_ANGLE_DEG = 30.0   # contact points lie within this polar angle of the top of the sphere


@dataclass(frozen=True, eq=False)
class ForceShapeData:
    """Force vectors and the surfaces they produce.

    Attributes:
        forces: ``(N, n_features)`` force vectors in ``layout``'s columns and units.
        shapes: ``(N, 3 n_vertices)`` surfaces (m), flattened ``x1, y1, z1, x2, ...``, noise included.
        contact_ids: ``(N,)`` index of each row's contact point (for held-out-contact splits).
        mesh, tissue, layout: how the surfaces were made (``fe``: the finite-element model's parameters
            where the surfaces are FE solutions; ``tissue`` then holds its E, nu, radius and patch).
        noise: standard deviation of the white noise added to every coordinate, as a fraction of the radius.
        seed: the seed that drew contact points, loads and noise.
    """

    forces: np.ndarray
    shapes: np.ndarray
    contact_ids: np.ndarray
    mesh: SphereMesh
    tissue: TissueParams
    layout: ForceLayout
    noise: float
    seed: int
    name: str = "dataset"
    fe: dict | None = None       # the finite-element model's parameters (softenv.fem.FEParams), None: analytic

    @property
    def n_samples(self) -> int:
        return int(self.forces.shape[0])

    @property
    def noise_std(self) -> float:
        """Noise standard deviation in metres."""
        return self.noise * self.tissue.radius

    @property
    def n_contacts(self) -> int:
        return int(np.unique(self.contact_ids).size)

    def subset(self, rows: np.ndarray) -> "ForceShapeData":
        """The rows ``rows`` (indices or boolean mask) as a new data set."""
        rows = np.asarray(rows)
        return replace(self, forces=self.forces[rows], shapes=self.shapes[rows], contact_ids=self.contact_ids[rows])

    def save(self, path: str | os.PathLike) -> None:
        """Write a versioned ``.npz`` (atomic)."""
        save_artifact(path, DATA_FORMAT, DATA_VERSION,
                      {"forces": self.forces, "shapes": self.shapes, "contact_ids": self.contact_ids},
                      {"mesh": self.mesh.spec(), "tissue": self.tissue.to_dict(),
                       "layout": self.layout.to_dict(), "noise": self.noise, "seed": self.seed, "name": self.name,
                       **({"fe": self.fe} if self.fe is not None else {})})

    @classmethod
    def load(cls, path: str | os.PathLike) -> "ForceShapeData":
        """Read a file written by :meth:`save`, checking format, mesh and array shapes."""
        arrays, meta = load_artifact(path, DATA_FORMAT, DATA_VERSION)
        require_arrays(arrays, ["forces", "shapes", "contact_ids"], path)
        try:
            mesh = mesh_from_spec(meta["mesh"])
            tissue = TissueParams(**meta["tissue"])
            layout = layout_from_dict(meta["layout"])
            noise, seed, name = float(meta["noise"]), int(meta["seed"]), str(meta["name"])
            fe = meta.get("fe")
        except (KeyError, TypeError, AttributeError) as exc:
            raise ValueError(f"{str(path)!r} has an invalid header (missing or bad {exc})") from exc
        forces, shapes, ids = arrays["forces"], arrays["shapes"], arrays["contact_ids"]
        n = forces.shape[0]
        if forces.shape != (n, layout.n_features) or shapes.shape != (n, 3 * mesh.n_vertices) or ids.shape != (n,):
            raise ValueError(f"{str(path)!r} has inconsistent arrays: forces {forces.shape}, shapes {shapes.shape}, "
                             f"contact_ids {ids.shape} for a {layout.name!r} layout on {mesh.n_vertices} vertices")
        return cls(forces, shapes, ids, mesh, tissue, layout, noise, seed, name, fe)


def paper_contacts(n_deformations: int, cap: float, radius: float, rng: np.random.Generator) -> np.ndarray:
    """The paper's contact points ``(n_deformations, 3)`` (m): a Fibonacci spiral over the cap within
    ``cap`` radians of the top, turned by one uniform draw from ``rng``."""
    i = np.arange(n_deformations) + 0.5
    z = 1.0 - (1.0 - math.cos(cap)) * i / n_deformations
    azimuth = math.pi * (3.0 - math.sqrt(5.0)) * i + rng.uniform(0.0, 2.0 * math.pi)
    r_xy = np.sqrt(1.0 - z ** 2)
    return radius * np.stack([r_xy * np.cos(azimuth), r_xy * np.sin(azimuth), z], axis=1)


def paper_forces(contacts: np.ndarray, n_magnitudes: int, max_force: float) -> tuple[np.ndarray, np.ndarray]:
    """The paper's force vectors ``(x, y, z, F)`` (:class:`PaperLayout`): each contact point with the
    magnitudes ``max_force * (1..n_magnitudes) / n_magnitudes``, and each row's contact index."""
    magnitudes = max_force * np.arange(1, n_magnitudes + 1) / n_magnitudes
    forces = np.concatenate([np.repeat(contacts, n_magnitudes, axis=0),
                             np.tile(magnitudes, len(contacts))[:, None]], axis=1)
    return forces, np.repeat(np.arange(len(contacts)), n_magnitudes)


def paper_dataset(n_points: int = 441, n_deformations: int = 10, n_magnitudes: int = 11, *,
                  law: str = "linear", noise: float = 1e-5, seed: int = 0,
                  max_force: float = PAPER_MAX_FORCE_N, cap_angle_deg: float = PAPER_CAP_ANGLE_DEG,
                  tissue: TissueParams | None = None, cache: bool = True) -> ForceShapeData:
    """The paper's data set: ``n_deformations`` contact points x ``n_magnitudes`` force magnitudes.

    Contact points are spread evenly (a Fibonacci spiral, rotated by ``seed``) over the cap within
    ``cap_angle_deg`` of the top; the force points straight down (``-z``) with magnitudes
    ``max_force * (1..n_magnitudes) / n_magnitudes``; white noise of standard deviation
    ``noise * radius`` is added to every coordinate. Forces are ``(x, y, z, F)`` (:class:`PaperLayout`).
    """
    check_int(n_points, "n_points", 9)
    n_deformations = check_int(n_deformations, "n_deformations", 1, 1000)
    n_magnitudes = check_int(n_magnitudes, "n_magnitudes", 1, 1000)
    check_choice(law, "law", ("linear", "stiffening"))
    noise = check_real(noise, "noise", 0.0, 1.0)
    max_force = check_real(max_force, "max_force", 0.0, None, low_open=True)
    cap = math.radians(check_real(cap_angle_deg, "cap_angle_deg", 0.0, 90.0, low_open=True))
    seed = check_int(seed, "seed", 0)
    tissue = replace(tissue if tissue is not None else TissueParams(), law=law)
    params = {"n_points": n_points, "n_deformations": n_deformations, "n_magnitudes": n_magnitudes,
              "noise": noise, "seed": seed, "max_force": max_force, "cap": cap, "tissue": tissue.to_dict()}

    def build() -> ForceShapeData:
        mesh = paper_mesh(n_points, tissue.radius)
        rng = np.random.default_rng(seed)
        contacts = paper_contacts(n_deformations, cap, tissue.radius, rng)
        forces, ids = paper_forces(contacts, n_magnitudes, max_force)
        layout = PaperLayout()
        shapes = AnalyticTissue(mesh, tissue).surfaces(*layout.to_loads(forces))
        shapes += rng.normal(0.0, noise * tissue.radius, shapes.shape)
        return ForceShapeData(forces, shapes, ids, mesh, tissue, layout, noise, seed,
                              f"paper-{n_points}pts-{n_deformations}def-{law}")

    return _cache.cached("paper", params, build, ForceShapeData.load, ForceShapeData.save, cache)


def workspace_dataset(workspace: Workspace, layout: ForceLayout, mesh: SphereMesh,
                      tissue: TissueParams | None = None, *, n_contacts: int = 64, n_loads: int = 16,
                      method: str = "lhs", noise: float = 0.0, seed: int = 0, cache: bool = True) -> ForceShapeData:
    """Surfaces for force vectors sampled over a scene's ``workspace`` (see :func:`~softenv.forces.sample_workspace`)."""
    tissue = tissue if tissue is not None else TissueParams()
    if workspace.n_features != layout.n_features:
        raise ValueError(f"workspace has {workspace.n_features} columns but layout {layout.name!r} has {layout.n_features}")
    noise = check_real(noise, "noise", 0.0, 1.0)
    params = {"workspace": [workspace.low, workspace.high, workspace.n_contact], "layout": layout.to_dict(),
              "mesh": mesh.spec(), "tissue": tissue.to_dict(), "n_contacts": n_contacts,
              "n_loads": n_loads, "method": method, "noise": noise, "seed": seed}

    def build() -> ForceShapeData:
        forces, ids = sample_workspace(workspace, n_contacts, n_loads, method, seed)
        shapes = AnalyticTissue(mesh, tissue).surfaces(*layout.to_loads(forces))
        if noise > 0:
            shapes += np.random.default_rng(seed + 2).normal(0.0, noise * tissue.radius, shapes.shape)
        return ForceShapeData(forces, shapes, ids, mesh, tissue, layout, noise, seed, f"workspace-{layout.name}")

    return _cache.cached("workspace", params, build, ForceShapeData.load, ForceShapeData.save, cache)


class Split(NamedTuple):
    """Row indices of the training, validation and test parts."""

    train: np.ndarray
    validation: np.ndarray
    test: np.ndarray


def _part_sizes(n: int, fractions: tuple[float, float, float]) -> list[int]:
    """Largest-remainder rounding of ``n * fractions``, giving every non-zero part at least one item."""
    f = check_array(fractions, "fractions", ndim=1, shape=(3,))
    if (f < 0).any() or not math.isclose(float(f.sum()), 1.0, abs_tol=1e-9):
        raise ValueError(f"fractions={f.tolist()} must be three non-negative numbers summing to 1")
    if n < int((f > 0).sum()):
        raise ValueError(f"cannot split {n} items into {int((f > 0).sum())} non-empty parts")
    raw = n * f
    sizes = np.floor(raw).astype(int)
    sizes[(f > 0) & (sizes == 0)] = 1
    while sizes.sum() > n:
        sizes[np.argmax(sizes)] -= 1
    order = np.argsort(-(raw - np.floor(raw)))
    for i in order[: n - sizes.sum()]:
        sizes[i] += 1
    return sizes.tolist()


def split_rows(n_rows: int, fractions: tuple[float, float, float] = (0.7, 0.15, 0.15), seed: int = 0) -> Split:
    """Random rows, as MATLAB's ``dividerand`` (the paper's split: tests interpolation)."""
    n_rows = check_int(n_rows, "n_rows", 1)
    perm = np.random.default_rng(seed).permutation(n_rows)
    a, b, _ = _part_sizes(n_rows, fractions)
    return Split(np.sort(perm[:a]), np.sort(perm[a:a + b]), np.sort(perm[a + b:]))


def split_by_contact(contact_ids: np.ndarray, fractions: tuple[float, float, float] = (0.7, 0.15, 0.15),
                     seed: int = 0) -> Split:
    """Whole contact points held out: test rows come from contact points never seen in training."""
    ids = check_array(contact_ids, "contact_ids", ndim=1, dtype=np.int64)
    groups = np.unique(ids)
    perm = np.random.default_rng(seed).permutation(groups)
    a, b, _ = _part_sizes(groups.size, fractions)
    parts = (perm[:a], perm[a:a + b], perm[a + b:])
    return Split(*(np.flatnonzero(np.isin(ids, p)) for p in parts))

