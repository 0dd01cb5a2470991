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
import time
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
from .params import FEParams
from .scene_data import TEST_SEED_OFFSET, FERequest, FESceneData, fe_tissue
from .tongue import FETongue, NonConvergence

RAMP_FORMAT = "softenv.FERamp"
RAMP_VERSION = 2      # 2: the patch centre's displacement follows the vertices'


@functools.lru_cache(maxsize=4)
def _tongue(params: FEParams) -> FETongue:
    """One mesh and its regions per process and parameter set (ramps in a worker share it)."""
    return FETongue(params)


def fe_ramp(params: FEParams, contact: tuple[float, float, float], force: tuple[float, float, float], steps: int,
            mesh_spec: dict, cache: bool = True) -> np.ndarray:
    """Displacements ``(steps, n_vertices + 1, 3)`` (m) for ``force`` (N) ramped at ``contact`` (m) in
    ``steps``: at the vertices of the surface mesh ``mesh_spec`` (:meth:`SphereMesh.spec`), then at the
    patch's centre (the contact direction on the undeformed sphere); from the cache when this ramp was
    solved before."""
    key = {"fe": asdict(params), "contact": list(contact), "force": list(force), "steps": steps, "mesh": mesh_spec,
           "format": RAMP_VERSION}       # entries of an older format are never even looked at
    centre = np.asarray(contact, dtype=float) * (params.radius / np.linalg.norm(contact))
    vertices = np.vstack([mesh_from_spec(mesh_spec).vertices, centre])

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
    workers: ``(R, steps, n_vertices + 1, 3)`` (the last point: the patch's centre). Raises
    :class:`NonConvergence` listing every ramp that failed (those that finished stay cached)."""
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
    shapes = (mesh.vertices + ramps[:, :, :-1]).reshape(n_deformations * n_magnitudes, -1)
    shapes += rng.normal(0.0, noise * params.radius, shapes.shape)
    forces, ids = paper_forces(contacts, n_magnitudes, max_force)
    return ForceShapeData(forces, shapes, ids, mesh, fe_tissue(params), PaperLayout(), noise, seed,
                          f"fem-paper-{n_points}pts-{n_deformations}def", fe=asdict(params))


def fe_workspace_dataset(workspace: Workspace, mesh: SphereMesh, params: FEParams = FEParams(), *,
                         n_contacts: int = 64, n_loads: int = 4, steps: int = 4, method: str = "lhs", seed: int = 0,
                         jobs: int = 1, executor: str = "local",
                         echo: Callable[[str], None] | None = print) -> ForceShapeData:
    """A scene's workspace on the FE tongue, in the dorsum layout (insertion, lateral, normal, sideways):
    ``n_contacts`` contact points x ``n_loads`` final loads, drawn as
    :func:`softenv.datasets.workspace_dataset` draws its samples; each is one ramp whose ``steps``
    load steps (the load scaled by ``1..steps / steps`` at its contact point) are the samples."""
    steps = check_int(steps, "steps", 1, 1000)
    ends, contacts, forces = _workspace_loads(workspace, params, n_contacts, n_loads, method, seed)
    ramps = solve_ramps(params, contacts, forces, steps, mesh, jobs, executor, echo)
    return _workspace_samples(ends, ramps, n_contacts, mesh, params, seed, "fem-workspace-dorsum")


def _workspace_loads(workspace: Workspace, params: FEParams, n_contacts: int, n_loads: int, method: str,
                     seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Final force features ``(n_contacts n_loads, 4)`` over the workspace and their contact points and forces."""
    layout = DorsumLayout(params.radius)
    if workspace.n_features != layout.n_features:
        raise ValueError(f"workspace has {workspace.n_features} columns but the dorsum layout has {layout.n_features}")
    ends, _ = sample_workspace(workspace, n_contacts, n_loads, method, seed)
    return (ends, *layout.to_loads(ends))


def _workspace_samples(ends: np.ndarray, ramps: np.ndarray, n_contacts: int, mesh: SphereMesh, params: FEParams,
                       seed: int, name: str) -> ForceShapeData:
    """Every load step of the ramps to ``ends`` as a sample (the load scaled by ``1..steps / steps``)."""
    steps = ramps.shape[1]
    fractions = np.arange(1, steps + 1) / steps
    features = np.repeat(ends, steps, axis=0)
    features[:, 2:] *= np.tile(fractions, len(ends))[:, None]
    shapes = (mesh.vertices + ramps[:, :, :-1]).reshape(len(ends) * steps, -1)
    ids = np.repeat(np.arange(n_contacts), len(ends) // n_contacts * steps)
    return ForceShapeData(features, shapes, ids, mesh, fe_tissue(params), DorsumLayout(params.radius), 0.0, seed, name,
                          fe=asdict(params))


def fe_scene_data(request: FERequest, jobs: int = 1, executor: str = "local",
                  echo: Callable[[str], None] | None = print) -> FESceneData:
    """Solve an FE scene's data (:mod:`softenv.fem.scene_data`): the workspace sample and the held-out
    solves (one fan-out over ``jobs`` workers), then the contact curve at the top of the dorsum."""
    p, mesh, started = request.fe, mesh_from_spec(request.mesh), time.perf_counter()
    test_seed = request.seed + TEST_SEED_OFFSET
    train = _workspace_loads(request.workspace, p, request.n_contacts, request.n_loads, "lhs", request.seed)
    test = _workspace_loads(request.workspace, p, request.n_test_contacts, request.n_loads, "lhs", test_seed)
    ramps = solve_ramps(p, np.vstack([train[1], test[1]]), np.vstack([train[2], test[2]]), request.steps, mesh, jobs,
                        executor, echo)
    n = len(train[0])
    # the contact curve: the largest press at the top, and a sideways load under half that press
    top, press, sideways = np.array([0.0, 0.0, p.radius]), request.high[2], request.high[3]
    curves = solve_ramps(p, np.vstack([top, top]), np.array([[0.0, 0.0, -press], [0.0, sideways, -press / 2]]),
                         request.curve_steps, mesh, jobs, executor, echo)[:, :, -1]     # at the patch's centre
    fractions = np.arange(1, request.curve_steps + 1) / request.curve_steps
    drag, sideways_loads = curves[1, :, 1], fractions * sideways
    return FESceneData(request,
                       _workspace_samples(train[0], ramps[:n], request.n_contacts, mesh, p, request.seed, "fem-scene-train"),
                       _workspace_samples(test[0], ramps[n:], request.n_test_contacts, mesh, p, test_seed, "fem-scene-test"),
                       fractions * press, -curves[0, :, 2],
                       float(drag @ sideways_loads / (sideways_loads @ sideways_loads)),    # least-squares slope
                       {"seconds": round(time.perf_counter() - started, 1), "jobs": jobs, "executor": executor})
