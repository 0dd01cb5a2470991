"""Build a scene's offline parts: mesh, tissue, workspace data, shape model and response.

Everything here is deterministic and cached twice: on disk (``softenv._cache``; a repeat ``gym.make``
in a new process reads files) and in the process (every environment made from the same scene
shares one immutable :class:`Scene`, so a batch of N environments costs no more memory than one).
Only what the scene names is built: no regressor is trained for an exact scene, and torch is
imported only when an MLP response has to be trained. A ``tissue.model="fem"`` scene reads its FE
solves (``softenv.fem.scene_data``: shipped for the default scene, else generated once and cached) in
place of the analytic workspace sample; its exact response is their RBF interpolant, tabulated.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any

import numpy as np

from .. import _cache
from ..datasets import ForceShapeData, workspace_dataset
from ..devices.contact import DEPTH_STEP, ContactCurve, analytic_curve
from ..fem.params import FEParams
from ..fem.scene_data import RAMP_STEPS, FERequest, FESceneData
from ..fem.store import scene_data
from ..forces import DorsumLayout, Workspace
from ..geometry import SphereMesh, make_mesh
from ..response import ExactResponse, RBFResponse, ResponseModel, TabulatedResponse, make_response, tabulate
from ..shape_model import ShapeModel
from ..tissue import AnalyticTissue, TissueParams
from ..airway import NORMAL_AIRWAY, tongue_only
from .config import config_key, material, scene_material
from ..sections import SceneConfig

_SCENES: dict[str, "Scene"] = {}
DEVICE_BOX_KEYS = ("insertion_deg", "lateral_deg", "max_normal_force", "max_sideways_force")


@dataclass(frozen=True, eq=False)
class Scene:
    """The immutable offline parts of an environment (shared by every env of the same config)."""

    config: SceneConfig
    mesh: SphereMesh
    tissue: TissueParams
    layout: DorsumLayout
    workspace: Workspace          # the device's force-feature box (insertion m, lateral m, normal N, sideways N)
    data: ForceShapeData
    shape_model: ShapeModel
    response: ResponseModel       # TabulatedResponse (exact analytic scenes) or a clipped regressor
    fe: FESceneData | None = None  # the FE solves of a tissue.model="fem" scene

    @property
    def n_components(self) -> int:
        return self.shape_model.n_components_

    @cached_property
    def sqrt_variance(self) -> np.ndarray:
        return self.shape_model.sqrt_variance_

    @cached_property
    def b_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Every ``b`` the response can return (table: node range; regressor: its clip range)."""
        return self.response.b_low_.copy(), self.response.b_high_.copy()

    @cached_property
    def rest_features(self) -> np.ndarray:
        """Zero force at the middle of the contact range."""
        mid = (np.asarray(self.workspace.low) + np.asarray(self.workspace.high)) / 2
        return np.array([mid[0], mid[1], 0.0, 0.0])

    def exact_response(self) -> ExactResponse:
        """The direct (untabulated) exact response of an analytic scene: for checks and reports."""
        if self.fe is not None:
            raise ValueError("tissue.model='fem' has no closed-form response; its truth is the FE solves (scene.fe)")
        return ExactResponse(AnalyticTissue(self.mesh, self.tissue), self.layout, self.shape_model)

    def response_error(self, n: int = 500, seed: int = 0) -> dict[str, float]:
        """RMS surface error (mm) of the scene's response against the truth: the direct exact response at
        ``n`` random forces (analytic tissue), or the held-out FE solves (FE tissue; PCA truncation included)."""
        if self.fe is not None:
            test = self.fe.test
            surfaces = self.shape_model.decode(self.response.predict(test.forces))
            err = np.sqrt(np.sum((surfaces - test.shapes) ** 2, axis=1) / self.mesh.n_vertices)
        else:
            x = np.random.default_rng(seed).uniform(self.workspace.low, self.workspace.high, (n, 4))
            err = self.shape_model.rms_distance(self.response.predict(x), self.exact_response().predict(x))
        err = err * 1e3
        return {"median_mm": float(np.median(err)), "p99_mm": float(np.percentile(err, 99)), "max_mm": float(err.max())}

    def contact_curve(self, design_force: float) -> ContactCurve:
        """The tissue's normal load-indentation curve at the top of the dorsum and lateral compliance, from
        which the laryngoscope's contact law follows (FE tissue: its solves; analytic: the closed form)."""
        if self.fe is None:
            return analytic_curve(self.tissue, self.mesh, design_force)
        loads, depths = self.fe.curve_loads, self.fe.curve_depths
        # past the last solve (the device's largest force) the tongue is a wall (TongueContact's barrier)
        return ContactCurve(loads, depths, float(depths[-1]), self.fe.lateral_compliance,
                            float(np.interp(design_force, np.r_[0.0, loads], np.r_[0.0, depths])))


def degrees_to_features(commands: Any, radius: float) -> np.ndarray:
    """Device commands ``(..., 4)`` in the config's units -- insertion and lateral position in degrees
    of arc, normal and sideways force in N -- as force features (m, m, N, N)."""
    out = np.array(commands, dtype=np.float64)
    out[..., :2] = radius * np.deg2rad(out[..., :2])
    return out


def depth_sensitivity(scene: Scene) -> TabulatedResponse:
    """The response's derivative in a factor ``q`` on the stiffening law's depth (the depth ``q`` times the
    tissue's), at ``q = 1``, on the response table's grid: central differences of the analytic tissue at
    ``q = 1 +- DEPTH_STEP``, each tabulated and projected on the scene's shape model (cached). The torch
    twin's ``stiffening_depth`` takes the response to first order in ``q`` from it. An analytic tongue on the
    stiffening law only: the linear law has no depth, and the FE tongue's law is neo-Hookean."""
    t = scene.tissue
    if scene.fe is not None or t.law != "stiffening" or not isinstance(scene.response, TabulatedResponse):
        raise ValueError(f"the stiffening depth is a parameter of the analytic tongue's stiffening law with the "
                         f"tabulated response; this scene has tissue.model={scene.config['tissue']['model']!r}, "
                         f"law={t.law!r}, response.model={scene.config['response']['model']!r}")
    table = scene.response
    nodes = table.nodes

    def at(q: float) -> TabulatedResponse:
        tissue = AnalyticTissue(scene.mesh, replace(t, stiffening_depth=t.stiffening_depth * q))
        return tabulate(ExactResponse(tissue, scene.layout, scene.shape_model), scene.workspace, nodes)

    def build() -> TabulatedResponse:
        values = (at(1 + DEPTH_STEP).values_ - at(1 - DEPTH_STEP).values_) / (2 * DEPTH_STEP)
        out = TabulatedResponse(table.low_, table.high_, values)
        out.shape_model_fingerprint_ = scene.shape_model.fingerprint()
        return out

    made_of = {"tissue": t.to_dict(), "mesh": scene.mesh.spec(), "low": table.low_.tolist(), "high": table.high_.tolist(),
               "nodes": list(nodes), "shape_model": scene.shape_model.fingerprint(), "step": DEPTH_STEP}
    def load(path: Any) -> TabulatedResponse:
        loaded = TabulatedResponse.load(path, shape_model=scene.shape_model)
        if not isinstance(loaded, TabulatedResponse):
            raise ValueError(f"{path}: holds a {loaded.kind} response, not a table")
        return loaded

    return _cache.cached("depth-sensitivity", made_of, build, load, lambda m, path: m.save(path))


def device_workspace(config: SceneConfig) -> Workspace:
    """The device's box in force-feature units, from the config's degrees and newtons."""
    dev, R = config["device"], config["tissue"]["radius"]
    low = degrees_to_features([dev["insertion_deg"][0], -dev["lateral_deg"], 0.0, -dev["max_sideways_force"]], R)
    high = degrees_to_features([dev["insertion_deg"][1], dev["lateral_deg"], dev["max_normal_force"],
                                dev["max_sideways_force"]], R)
    return Workspace(tuple(low.tolist()), tuple(high.tolist()))


def fe_request(config: SceneConfig) -> FERequest:
    """What a tissue.model="fem" scene's FE data are computed from: the tissue section's material and
    geometry on ``fe_cells``, the scene's surface mesh and device box, its workspace sampling."""
    t, sm_cfg = config["tissue"], config["shape_model"]
    E, nu = scene_material(config)
    params = FEParams(radius=t["radius"], E=E, nu=nu, patch_radius=t["patch_radius"], cells_per_side=t["fe_cells"])
    mesh = make_mesh(config["mesh"]["kind"], config["mesh"]["resolution"], t["radius"])
    workspace = device_workspace(config)
    return FERequest(params, mesh.spec(), tuple(workspace.low), tuple(workspace.high), sm_cfg["n_contacts"],
                     sm_cfg["n_loads"] // RAMP_STEPS, sm_cfg["seed"])


def build_scene(config: SceneConfig, progress: bool = False) -> Scene:
    """The scene for a validated config (memoised per process, files cached on disk)."""
    # the device enters the scene only through its force-feature box (the laryngoscope's dynamics do not),
    # the airway only through the tongue's stiffness
    t = config["tissue"]
    device: Mapping[str, Any] = config["device"]
    box = {"device": {k: device[k] for k in DEVICE_BOX_KEYS}, "airway": tongue_only(config["airway"])}
    key = config_key({**config, **box}, ("tissue", "mesh", "shape_model", "response", "device"))
    if key in _SCENES:
        return _SCENES[key]
    E, nu = scene_material(config)
    tissue = TissueParams(law=t["law"], E=E, nu=nu, radius=t["radius"], patch_radius=t["patch_radius"])
    mesh = make_mesh(config["mesh"]["kind"], config["mesh"]["resolution"], tissue.radius)
    layout = DorsumLayout(tissue.radius)
    workspace = device_workspace(config)
    sm_cfg = config["shape_model"]
    fe = scene_data(fe_request(config)) if t["model"] == "fem" else None
    data = fe.train if fe is not None else workspace_dataset(
        workspace, layout, mesh, tissue, n_contacts=sm_cfg["n_contacts"], n_loads=sm_cfg["n_loads"], seed=sm_cfg["seed"])
    memo = key
    if fe is not None:      # fits cached from FE data are keyed by those data's bits, not only by their request
        key += hashlib.sha256(data.forces.tobytes() + data.shapes.tobytes()).hexdigest()
    # an analytic tongue of any stiffness shares the normal tongue's shape model, so a target shape has the
    # same b on every airway grade (the linear tongue's deformations only scale with it: the same span)
    normal_E = material(t)[0]
    stiffened = fe is None and tissue.E != normal_E
    shapes_key = config_key({**config, **box, "airway": NORMAL_AIRWAY},
                            ("tissue", "mesh", "shape_model", "response", "device")) if stiffened else key

    def fit() -> ShapeModel:
        shapes = workspace_dataset(workspace, layout, mesh, replace(tissue, E=normal_E), n_contacts=sm_cfg["n_contacts"],
                                   n_loads=sm_cfg["n_loads"], seed=sm_cfg["seed"]).shapes if stiffened else data.shapes
        return ShapeModel(sm_cfg["n_components"]).fit(shapes, mesh)

    shape_model = _cache.cached("shape-model", {"data": shapes_key}, fit,
                                lambda p: ShapeModel.load(p, mesh=mesh), lambda m, p: m.save(p))
    name = config["response"]["model"]
    if name == "exact":
        def table() -> ResponseModel:
            # the tissue's own response on a grid: the analytic tissue's, or (no closed form) the FE solves'
            # interpolant (cubic RBF, softenv.response.rbf: the best of results/fem_scene.md)
            exact = (ExactResponse(AnalyticTissue(mesh, tissue), layout, shape_model) if fe is None else
                     RBFResponse().fit(data.forces, shape_model.encode(data.shapes), shape_model=shape_model))
            return tabulate(exact, workspace, nodes, progress=progress)

        nodes = config["response"]["table_nodes"]
        response: ResponseModel = _cache.cached("table", {"scene": key, "nodes": nodes}, table,
                                                lambda p: TabulatedResponse.load(p, shape_model=shape_model),
                                                lambda m, p: m.save(p))
    else:
        def train() -> ResponseModel:
            # MLPs train by L-BFGS here: Levenberg-Marquardt's Jacobian on 1024 x k targets takes minutes
            options = {"trainer": "lbfgs"} if name.startswith("mlp") else {}
            return make_response(name, seed=sm_cfg["seed"], clip=True, **options).fit(
                data.forces, shape_model.encode(data.shapes), shape_model=shape_model)

        response = _cache.cached("regressor", {"scene": key, "model": name, "trainer": "lbfgs"}, train,
                                 lambda p: ResponseModel.load(p, shape_model=shape_model), lambda m, p: m.save(p))
    scene = Scene(config, mesh, tissue, layout, workspace, data, shape_model, response, fe)
    _SCENES[memo] = scene
    return scene
