"""The paper's data on the finite-element tongue: load ramps solved in parallel, cached one by one
(a killed run resumes where it stopped), sampled on the paper's surface grids, as ForceShapeData.

One ramp is one FE solve: a contact point, a final force vector and ``steps`` equal load steps;
every load step is a sample. Ramps are independent jobs of :func:`softenv.parallel.run_jobs`
(``executor="local"`` processes or ``"ray"``); each finished ramp is a versioned ``.npz`` in the
softenv cache keyed by everything it is computed from, so rerunning a stopped generation solves
only the ramps that are missing. A ramp that does not converge is reported with its case and the
load step reached, and no data set is returned.
"""

from __future__ import annotations

import functools
import math
from dataclasses import asdict
from pathlib import Path
from typing import Callable

import numpy as np

from .. import _cache
from .._artifact import load_artifact, require_arrays, save_artifact
from .._validation import check_choice, check_int, check_real
from ..datasets import PAPER_CAP_ANGLE_DEG, PAPER_MAX_FORCE_N, ForceShapeData, paper_contacts, paper_forces
from ..forces import DorsumLayout, PaperLayout, Workspace, sample_workspace
from ..geometry import SphereMesh, mesh_from_spec, paper_mesh
from ..parallel import EXECUTORS, Job, run_jobs
from ..tissue import TissueParams
from .tongue import FEParams, FETongue, NonConvergence

RAMP_FORMAT = "softenv.FERamp"
RAMP_VERSION = 1


@functools.lru_cache(maxsize=4)
def _tongue(params: FEParams) -> FETongue:
    """One mesh and its regions per process and parameter set (ramps in a worker share it)."""
    return FETongue(params)


def _tissue(params: FEParams) -> TissueParams:
    """The data set header's tissue: the FE tongue's small-strain E, nu, radius and patch."""
    return TissueParams(E=params.E, nu=params.nu, radius=params.radius, patch_radius=params.patch_radius)


def fe_ramp(params: FEParams, contact: tuple[float, float, float], force: tuple[float, float, float], steps: int,
            mesh_spec: dict, cache: bool = True) -> np.ndarray:
    """Surface displacements ``(steps, n_vertices, 3)`` (m) at the vertices of the surface mesh
    ``mesh_spec`` (:meth:`SphereMesh.spec`) for ``force`` (N) ramped at ``contact`` (m) in ``steps``;
    from the cache when this ramp was solved before."""
    key = {"fe": asdict(params), "contact": list(contact), "force": list(force), "steps": steps, "mesh": mesh_spec}
    vertices = mesh_from_spec(mesh_spec).vertices

    def build() -> np.ndarray:
        tongue = _tongue(params)
        solution = tongue.solve(np.asarray(contact), np.asarray(force), steps)
        return tongue.displacements_at(solution.displacements, vertices)

    def save(value: np.ndarray, path: Path) -> None:
        save_artifact(path, RAMP_FORMAT, RAMP_VERSION, {"displacements": value}, key)

    def load(path: Path) -> np.ndarray:
        # the cache reads an entry only when its build digest is this ramp's; here format and shape
        arrays, _ = load_artifact(path, RAMP_FORMAT, RAMP_VERSION)
        require_arrays(arrays, ["displacements"], path)
        if arrays["displacements"].shape != (steps, len(vertices), 3):
            raise ValueError(f"{str(path)!r} holds displacements of shape {arrays['displacements'].shape}, not "
                             f"{(steps, len(vertices), 3)}")
        return arrays["displacements"]

    return _cache.cached("fem-ramp", key, build, load, save, cache)


def solve_ramps(params: FEParams, contacts: np.ndarray, forces: np.ndarray, steps: int, mesh: SphereMesh,
                jobs: int = 1, executor: str = "local", echo: Callable[[str], None] | None = print) -> np.ndarray:
    """:func:`fe_ramp` for each row of ``contacts`` and ``forces`` ``(R, 3)``, fanned out over ``jobs``
    workers: ``(R, steps, n_vertices, 3)``. Raises :class:`NonConvergence` listing every ramp that
    failed (those that finished stay cached)."""
    check_choice(executor, "executor", EXECUTORS)
    work = [Job(f"ramp {i}: {np.round(f, 3).tolist()} N at {np.round(c / params.radius, 3).tolist()}", fe_ramp,
                (params, tuple(map(float, c)), tuple(map(float, f)), steps, mesh.spec()))
            for i, (c, f) in enumerate(zip(contacts, forces))]
    results = run_jobs(work, executor, jobs, retries=0, echo=echo)
    failed = [f"{r.key}: {r.error}" for r in results if not r.ok]
    if failed:
        raise NonConvergence(f"{len(failed)} of {len(results)} FE ramps failed (the others are cached; rerun to "
                             "resume):\n" + "\n".join(failed))
    return np.stack([r.value for r in results])


def fe_paper_dataset(n_points: int = 441, n_deformations: int = 10, n_magnitudes: int = 11, *,
                     params: FEParams = FEParams(), noise: float = 1e-5, seed: int = 0,
                     max_force: float = PAPER_MAX_FORCE_N, cap_angle_deg: float = PAPER_CAP_ANGLE_DEG,
                     jobs: int = 1, executor: str = "local",
                     echo: Callable[[str], None] | None = print) -> ForceShapeData:
    """The paper's protocol (:func:`softenv.datasets.paper_dataset`) on the FE tongue: the same contact
    points, the force straight down, each deformation one ramp whose ``n_magnitudes`` load steps are
    the samples ``max_force * (1..n_magnitudes) / n_magnitudes``; white noise as there."""
    n_deformations = check_int(n_deformations, "n_deformations", 1, 1000)
    n_magnitudes = check_int(n_magnitudes, "n_magnitudes", 1, 1000)
    noise = check_real(noise, "noise", 0.0, 1.0)
    max_force = check_real(max_force, "max_force", 0.0, None, low_open=True)
    cap = math.radians(check_real(cap_angle_deg, "cap_angle_deg", 0.0, 90.0, low_open=True))
    seed = check_int(seed, "seed", 0)
    mesh = paper_mesh(n_points, params.radius)
    rng = np.random.default_rng(seed)
    contacts = paper_contacts(n_deformations, cap, params.radius, rng)
    down = np.tile([0.0, 0.0, -max_force], (n_deformations, 1))
    ramps = solve_ramps(params, contacts, down, n_magnitudes, mesh, jobs, executor, echo)
    shapes = (mesh.vertices + ramps).reshape(n_deformations * n_magnitudes, -1)
    shapes += rng.normal(0.0, noise * params.radius, shapes.shape)
    forces, ids = paper_forces(contacts, n_magnitudes, max_force)
    return ForceShapeData(forces, shapes, ids, mesh, _tissue(params), PaperLayout(), noise, seed,
                          f"fem-paper-{n_points}pts-{n_deformations}def", fe=asdict(params))


def fe_workspace_dataset(workspace: Workspace, mesh: SphereMesh, params: FEParams = FEParams(), *,
                         n_contacts: int = 64, n_loads: int = 4, steps: int = 4, method: str = "lhs", seed: int = 0,
                         jobs: int = 1, executor: str = "local",
                         echo: Callable[[str], None] | None = print) -> ForceShapeData:
    """A scene's workspace on the FE tongue, in the dorsum layout (insertion, lateral, normal, sideways):
    ``n_contacts`` contact points x ``n_loads`` final loads, drawn as
    :func:`softenv.datasets.workspace_dataset` draws its samples; each is one ramp whose ``steps``
    load steps (the load scaled by ``1..steps / steps`` at its contact point) are the samples."""
    layout = DorsumLayout(params.radius)
    if workspace.n_features != layout.n_features:
        raise ValueError(f"workspace has {workspace.n_features} columns but the dorsum layout has {layout.n_features}")
    steps = check_int(steps, "steps", 1, 1000)
    ends, _ = sample_workspace(workspace, n_contacts, n_loads, method, seed)
    contacts, forces = layout.to_loads(ends)
    ramps = solve_ramps(params, contacts, forces, steps, mesh, jobs, executor, echo)
    fractions = np.arange(1, steps + 1) / steps
    features = np.repeat(ends, steps, axis=0)
    features[:, 2:] *= np.tile(fractions, len(ends))[:, None]
    shapes = (mesh.vertices + ramps).reshape(len(ends) * steps, -1)
    ids = np.repeat(np.arange(n_contacts), n_loads * steps)
    return ForceShapeData(features, shapes, ids, mesh, _tissue(params), layout, 0.0, seed, "fem-workspace-dorsum",
                          fe=asdict(params))
