"""The finite-element data a scene with ``tissue={"model": "fem"}`` reads (numpy only: no FElupe).

An FE scene has no closed-form response; it is built from FE solves made offline
(:func:`softenv.fem.data.fe_scene_data`) and kept in one versioned ``.npz``
(:func:`softenv.fem.store.scene_data` finds it: shipped, cached, or solved now):

* ``train``: the scene's workspace sample (``n_contacts`` contact points x ``n_loads`` final loads,
  each a ramp of ``steps`` load steps, every step a sample), to which the shape model and the
  response are fitted, as the paper intends;
* ``test``: held-out solves at other contact points and loads (``TEST_CONTACTS`` of them), against
  which the fitted response's surface error is reported in mm;
* the contact curve: the normal load ramped at the top of the dorsum (``CURVE_STEPS`` steps to the
  device's largest force) with the indentation at the patch's centre, and the lateral drag per newton
  of a small sideways load there. The laryngoscope's contact law follows them.

:class:`FERequest` is everything the data are computed from (the FE tongue's parameters, the surface
mesh, the device's force-feature box, the sampling); it is the file's header. A file is used only for
the request it was made for: :meth:`FESceneData.load` refuses another format version, mesh or
material, naming the first field that differs. The default scene's file ships with softenv
(``softenv/fem/shipped/``, found by its header); other FE scenes are generated on first use (the ``fem`` extra) and cached.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from .._artifact import load_artifact, require_arrays, save_artifact
from ..datasets import ForceShapeData
from ..forces import DorsumLayout, Workspace
from ..geometry import SphereMesh, mesh_from_spec
from ..tissue import TissueParams
from .params import FEParams

SCENE_DATA_FORMAT = "softenv.FESceneData"
SCENE_DATA_VERSION = 1
RAMP_STEPS = 4          # load steps per ramp: a scene's n_loads samples per contact are n_loads / 4 ramps
TEST_CONTACTS = 16      # held-out contact points (x the scene's final loads per contact)
TEST_SEED_OFFSET = 1000  # held-out solves draw their contacts and loads from the scene's seed + this
CURVE_STEPS = 20        # load steps of the contact curve at the top of the dorsum


@dataclass(frozen=True)
class FERequest:
    """Everything an FE scene's data are computed from (the data file's header)."""

    fe: FEParams
    mesh: dict                  # SphereMesh.spec() of the scene's surface sampling
    low: tuple[float, ...]      # the device's force-feature box (insertion m, lateral m, normal N, sideways N)
    high: tuple[float, ...]
    n_contacts: int
    n_loads: int                # final loads per contact point (each a ramp of RAMP_STEPS load steps)
    seed: int
    steps: int = RAMP_STEPS
    n_test_contacts: int = TEST_CONTACTS
    curve_steps: int = CURVE_STEPS

    @property
    def workspace(self) -> Workspace:
        return Workspace(self.low, self.high)

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["low"], out["high"] = list(self.low), list(self.high)
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "FERequest":
        return cls(**{**d, "fe": FEParams(**d["fe"]), "low": tuple(d["low"]), "high": tuple(d["high"])})

    def difference(self, other: "FERequest") -> str | None:
        """The first field (``fe.E``, ``mesh``, ``high``, ...) where ``other`` differs, with both values."""
        mine, theirs = _flatten(self.to_dict()), _flatten(other.to_dict())
        for key in mine:
            if mine[key] != theirs.get(key):
                return f"{key}={theirs.get(key)!r} where this scene needs {key}={mine[key]!r}"
        return None


def _flatten(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, dict) and k != "mesh":
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def fe_tissue(fe: FEParams) -> TissueParams:
    """The FE tongue's small-strain E, nu, radius and patch as TissueParams (data headers, radius)."""
    return TissueParams(E=fe.E, nu=fe.nu, radius=fe.radius, patch_radius=fe.patch_radius)


@dataclass(frozen=True, eq=False)
class FESceneData:
    """An FE scene's data (see the module docstring)."""

    request: FERequest
    train: ForceShapeData
    test: ForceShapeData
    curve_loads: np.ndarray      # (CURVE_STEPS,) N, normal load at the top of the dorsum
    curve_depths: np.ndarray     # (CURVE_STEPS,) m, indentation at the patch's centre under it
    lateral_compliance: float    # m/N, drag of the patch's centre per newton of sideways load (under half the press)
    generation: dict             # how the file was made: seconds, jobs, executor

    def save(self, path: str | os.PathLike) -> None:
        """Write the versioned ``.npz`` (atomic); the arrays are the same bits on every regeneration."""
        arrays = {f"{part}_{name}": getattr(data, name) for part, data in (("train", self.train), ("test", self.test))
                  for name in ("forces", "shapes", "contact_ids")}
        arrays.update(curve_loads=self.curve_loads, curve_depths=self.curve_depths,
                      lateral_compliance=np.array(self.lateral_compliance))
        save_artifact(path, SCENE_DATA_FORMAT, SCENE_DATA_VERSION, arrays,
                      {"request": self.request.to_dict(), "generation": self.generation})

    @classmethod
    def load(cls, path: str | os.PathLike, request: FERequest | None = None) -> "FESceneData":
        """Read a file written by :meth:`save`; with ``request``, refuse a file made for another one."""
        arrays, meta = load_artifact(path, SCENE_DATA_FORMAT, SCENE_DATA_VERSION)
        try:
            found = FERequest.from_dict(meta["request"])
            generation = dict(meta["generation"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{str(path)!r} has an invalid header (missing or bad {exc})") from exc
        if request is not None and (diff := request.difference(found)) is not None:
            raise ValueError(f"{str(path)!r} holds FE data for another scene: {diff}; regenerate it for this scene "
                             "(python scripts/make_fem_data.py) or let the scene generate its own")
        names = [f"{p}_{n}" for p in ("train", "test") for n in ("forces", "shapes", "contact_ids")]
        require_arrays(arrays, names + ["curve_loads", "curve_depths", "lateral_compliance"], path)
        mesh = mesh_from_spec(found.mesh)
        train, test = (_dataset(arrays, part, found, mesh, path) for part in ("train", "test"))
        loads, depths = arrays["curve_loads"], arrays["curve_depths"]
        if loads.shape != (found.curve_steps,) or depths.shape != loads.shape:
            raise ValueError(f"{str(path)!r}: contact curve of shapes {loads.shape} and {depths.shape}, expected "
                             f"({found.curve_steps},)")
        if not (np.all(np.diff(loads) > 0) and np.all(np.diff(depths) > 0) and loads[0] > 0 and depths[0] > 0):
            raise ValueError(f"{str(path)!r}: the contact curve's loads and indentations must rise from above 0")
        compliance = float(arrays["lateral_compliance"])
        if not compliance > 0:
            raise ValueError(f"{str(path)!r}: lateral_compliance={compliance!r} must be > 0 m/N")
        return cls(found, train, test, loads, depths, compliance, generation)


def _dataset(arrays: dict[str, np.ndarray], part: str, request: FERequest, mesh: SphereMesh,
             path: str | os.PathLike) -> ForceShapeData:
    contacts = request.n_contacts if part == "train" else request.n_test_contacts
    n = contacts * request.n_loads * request.steps
    forces, shapes, ids = (arrays[f"{part}_{k}"] for k in ("forces", "shapes", "contact_ids"))
    if forces.shape != (n, 4) or shapes.shape != (n, 3 * mesh.n_vertices) or ids.shape != (n,):
        raise ValueError(f"{str(path)!r}: {part} arrays of shapes {forces.shape}, {shapes.shape}, {ids.shape}; "
                         f"the header asks for {n} samples on {mesh.n_vertices} vertices")
    seed = request.seed + (TEST_SEED_OFFSET if part == "test" else 0)
    return ForceShapeData(forces, shapes, ids, mesh, fe_tissue(request.fe), DorsumLayout(request.fe.radius), 0.0,
                          seed, f"fem-scene-{part}", fe=asdict(request.fe))
