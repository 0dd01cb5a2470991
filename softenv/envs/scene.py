"""Build a scene's offline parts: mesh, tissue, workspace data, shape model and response.

Everything here is deterministic and cached twice: on disk (``softenv._cache``; a repeat ``gym.make``
in a new process reads files) and in the process (every environment made from the same scene
shares one immutable :class:`Scene`, so a batch of N environments costs no more memory than one).
Only what the scene names is built: no regressor is trained for an exact scene, and torch is
imported only when an MLP response has to be trained.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from .. import _cache
from ..datasets import ForceShapeData, workspace_dataset
from ..forces import DorsumLayout, Workspace
from ..geometry import SphereMesh, make_mesh
from ..response import ExactResponse, ResponseModel, TabulatedResponse, make_response
from ..shape_model import ShapeModel
from ..tissue import AnalyticTissue, TissueParams
from .config import config_key

_SCENES: dict[str, "Scene"] = {}
DEVICE_BOX_KEYS = ("insertion_deg", "lateral_deg", "max_normal_force", "max_sideways_force")


@dataclass(frozen=True, eq=False)
class Scene:
    """The immutable offline parts of an environment (shared by every env of the same config)."""

    config: dict
    mesh: SphereMesh
    tissue: TissueParams
    layout: DorsumLayout
    workspace: Workspace          # the device's force-feature box (insertion m, lateral m, normal N, sideways N)
    data: ForceShapeData
    shape_model: ShapeModel
    response: ResponseModel       # TabulatedResponse (exact scenes) or a clipped regressor

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
        """The direct (untabulated) exact response of this scene: for checks and reports."""
        return ExactResponse(AnalyticTissue(self.mesh, self.tissue), self.layout, self.shape_model)

    def table_error(self, n: int = 500, seed: int = 0) -> dict[str, float]:
        """RMS surface error (mm) of the scene's response against the direct exact response, at random forces."""
        x = np.random.default_rng(seed).uniform(self.workspace.low, self.workspace.high, (n, 4))
        err = self.shape_model.rms_distance(self.response.predict(x), self.exact_response().predict(x)) * 1e3
        return {"median_mm": float(np.median(err)), "p99_mm": float(np.percentile(err, 99)), "max_mm": float(err.max())}


def degrees_to_features(commands: Any, radius: float) -> np.ndarray:
    """Device commands ``(..., 4)`` in the config's units -- insertion and lateral position in degrees
    of arc, normal and sideways force in N -- as force features (m, m, N, N)."""
    out = np.array(commands, dtype=np.float64)
    out[..., :2] = radius * np.deg2rad(out[..., :2])
    return out


def device_workspace(config: dict) -> Workspace:
    """The device's box in force-feature units, from the config's degrees and newtons."""
    dev, R = config["device"], config["tissue"]["radius"]
    low = degrees_to_features([dev["insertion_deg"][0], -dev["lateral_deg"], 0.0, -dev["max_sideways_force"]], R)
    high = degrees_to_features([dev["insertion_deg"][1], dev["lateral_deg"], dev["max_normal_force"],
                                dev["max_sideways_force"]], R)
    return Workspace(tuple(low.tolist()), tuple(high.tolist()))


def build_scene(config: dict, progress: bool = False) -> Scene:
    """The scene for a validated config (memoised per process, files cached on disk)."""
    # the device enters the scene only through its force-feature box (the laryngoscope's dynamics do not)
    box = {"device": {k: config["device"][k] for k in DEVICE_BOX_KEYS}}
    key = config_key({**config, **box}, ("tissue", "mesh", "shape_model", "response", "device"))
    if key in _SCENES:
        return _SCENES[key]
    t = config["tissue"]
    tissue = TissueParams(law=t["law"], E=t["E"], nu=t["nu"], radius=t["radius"], patch_radius=t["patch_radius"])
    mesh = make_mesh(config["mesh"]["kind"], config["mesh"]["resolution"], tissue.radius)
    layout = DorsumLayout(tissue.radius)
    workspace = device_workspace(config)
    sm_cfg = config["shape_model"]
    data = workspace_dataset(workspace, layout, mesh, tissue, n_contacts=sm_cfg["n_contacts"], n_loads=sm_cfg["n_loads"],
                             seed=sm_cfg["seed"])
    shape_model = _cache.cached("shape-model", {"data": key}, lambda: ShapeModel(sm_cfg["n_components"]).fit(data.shapes, mesh),
                                lambda p: ShapeModel.load(p, mesh=mesh), lambda m, p: m.save(p))
    name = config["response"]["model"]
    if name == "exact":
        exact = ExactResponse(AnalyticTissue(mesh, tissue), layout, shape_model)
        nodes = config["response"]["table_nodes"]
        response: ResponseModel = _cache.cached(
            "table", {"scene": key, "nodes": nodes}, lambda: exact.tabulate(workspace, nodes, progress=progress),
            lambda p: TabulatedResponse.load(p, shape_model=shape_model), lambda m, p: m.save(p))
    else:
        b = shape_model.encode(data.shapes)

        def train() -> ResponseModel:
            # MLPs train by L-BFGS here: Levenberg-Marquardt's Jacobian on 1024 x k targets takes minutes
            options = {"trainer": "lbfgs"} if name.startswith("mlp") else {}
            return make_response(name, seed=sm_cfg["seed"], clip=True, **options).fit(data.forces, b, shape_model=shape_model)

        response = _cache.cached("regressor", {"scene": key, "model": name, "trainer": "lbfgs"}, train,
                                 lambda p: ResponseModel.load(p, shape_model=shape_model), lambda m, p: m.save(p))
    scene = Scene(config, mesh, tissue, layout, workspace, data, shape_model, response)
    _SCENES[key] = scene
    return scene
