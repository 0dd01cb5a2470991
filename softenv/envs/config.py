"""Scene configuration: a validated, declarative description of what an environment builds.

A scene is a nested mapping of sections (``tissue``, ``mesh``, ``shape_model``, ``response``,
``device``, ``dynamics``, ``task``, ``reward``, ``airway``, ``render``). :func:`default_config` returns the
defaults; :func:`make_config` merges overrides (``gym.make("SoftSphere-v0", dynamics={"kind":
"viscoelastic"})``) and validates every value. An unknown section or key, or a value out of range,
raises a ``ValueError`` that lists the valid keys with their units and ranges. :func:`describe_config`
prints the whole table.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from collections.abc import Mapping
from typing import Any, Callable, cast

from .._validation import check_choice, check_int, check_real
from ..airway import GRADES, airway, target_ranges
from ..devices.base import device_kind
from ..devices.laryngoscope import BATCH_ENGINES, EXACT_ENGINES, RETIRED_ENGINES
from ..fem.params import FE_POISSON
from ..fem.scene_data import RAMP_STEPS
from ..response import REGRESSORS
from ..sections import SceneConfig
from ..tissue import BLADE_PATCH_RADIUS_M, DESIGN_INDENTATION, TONGUE_POISSON, TONGUE_RADIUS_M, effective_modulus


class UnknownSectionError(TypeError, ValueError):
    """A keyword that is no scene section. A ``TypeError`` of Python's usual form (``... got an unexpected
    keyword argument 'x'``), which wrappers such as TorchRL's ``GymEnv`` test for before retrying without
    the keyword; also a ``ValueError``, as every other bad setting."""


MIN_DESIGN_INDENTATION = 1e-9     # of the radius, at device.max_normal_force (see validate_config)


@dataclass(frozen=True)
class Field:
    """One configurable value: default, unit, allowed values (as text) and a checker."""

    default: Any
    unit: str
    allowed: str
    check: Callable[[Any, str], Any]
    doc: str


Check = Callable[[Any, str], Any]


def _real(lo: float | None = None, hi: float | None = None, lo_open: bool = False, hi_open: bool = False) -> Check:
    return lambda v, name: check_real(v, name, lo, hi, low_open=lo_open, high_open=hi_open)


def _int(lo: int | None = None, hi: int | None = None) -> Check:
    return lambda v, name: check_int(v, name, lo, hi)


def _choice(*options: Any) -> Check:
    return lambda v, name: check_choice(v, name, options)


def _optional(check: Callable[[Any, str], Any]) -> Callable[[Any, str], Any]:
    return lambda v, name: None if v is None else check(v, name)


def _batch_engine(v: Any, name: str) -> str:
    if v in RETIRED_ENGINES:
        raise ValueError(f"{name}={v!r} is retired: it was {RETIRED_ENGINES[v]}; choose one of {list(BATCH_ENGINES)}")
    return check_choice(v, name, BATCH_ENGINES)


def _device_kind(v: Any, name: str) -> str:
    device_kind(v, name)                  # loads the kind's module (not its physics): refuses what names none
    return v


def _bool(v: Any, name: str) -> bool:
    if not isinstance(v, bool):
        raise ValueError(f"{name} must be True or False, got {v!r}")
    return v


def _pair(lo: float, hi: float) -> Check:
    def check(v: Any, name: str) -> tuple[float, float]:
        if not isinstance(v, (tuple, list)) or len(v) != 2:
            raise ValueError(f"{name} must be a (low, high) pair, got {v!r}")
        a, b = (check_real(x, f"{name}[{i}]", lo, hi) for i, x in enumerate(v))
        if b < a:
            raise ValueError(f"{name}={tuple(v)!r}: high must not be below low")
        return (a, b)
    return check


def _nodes(v: Any, name: str) -> tuple[int, ...]:
    if not isinstance(v, (tuple, list)) or len(v) != 4:
        raise ValueError(f"{name} must be 4 node counts (insertion, lateral, normal, sideways), got {v!r}")
    return tuple(check_int(x, f"{name}[{i}]", 2, 257) for i, x in enumerate(v))


def _components(v: Any, name: str) -> int | float | str:
    if isinstance(v, str):
        return check_choice(v, name, ("scree", "kneedle"))
    if isinstance(v, float) and 0 < v < 1:
        return v
    return check_int(v, name, 1, 500)


SCHEMA: dict[str, dict[str, Field]] = {
    "tissue": {
        "model": Field("analytic", "", "analytic | fem", _choice("analytic", "fem"),
                       "analytic (Boussinesq/Cerruti patch, tabulated) or the finite-element tongue (neo-Hookean, "
                       "nearly incompressible; its data ship for the default scene, others are generated: fem extra; "
                       "device.max_normal_force may indent it by at most 0.4 of its radius, where its ramps are verified)"),
        "law": Field("linear", "", "linear | stiffening", _choice("linear", "stiffening"),
                     "analytic model: linear (the paper's regime) or Fung stiffening with Hertzian contact widening"),
        "E": Field(None, "Pa", "[1e-3, 1e12] | None", _optional(_real(1e-3, 1e12)),
                   "effective Young's modulus (None: the model's default, at which 40 N indents 40 % of the radius; "
                   "steel is 2e11)"),
        "nu": Field(None, "", "[0, 0.5) | None", _optional(_real(0, 0.5, hi_open=True)),
                    "Poisson's ratio (None: the model's default, 0.45 analytic, 0.49 fem: nearly incompressible)"),
        "radius": Field(TONGUE_RADIUS_M, "m", "[1e-4, 1]", _real(1e-4, 1), "sphere radius"),
        "patch_radius": Field(BLADE_PATCH_RADIUS_M, "m", "[radius / 1000, radius]", _real(1e-7, 1),
                              "blade contact-patch radius"),
        "fe_cells": Field(8, "", "2-32", _int(2, 32),
                          "fem model: hexahedra along the mapped cube's edge (8 reach the design force; see README)"),
    },
    "mesh": {
        "kind": Field("latlong", "", "latlong | icosphere", _choice("latlong", "icosphere"), "surface sampling"),
        "resolution": Field(21, "", "latlong 3-200, icosphere 0-6", _int(0, 200),
                            "points per ring (latlong: resolution^2 points) or icosphere subdivisions"),
    },
    "shape_model": {
        "n_components": Field(0.999, "", "scree | kneedle | fraction in (0, 1) | int 1-500", _components,
                              "how many PCA components the scene keeps"),
        "n_contacts": Field(64, "", "8-4096", _int(8, 4096), "contact points sampled over the workspace"),
        "n_loads": Field(16, "", "2-256", _int(2, 256), "loads sampled per contact point"),
        "seed": Field(0, "", ">= 0", _int(0, None), "seed of the workspace sample"),
    },
    "response": {
        "model": Field("exact", "", "exact | " + " | ".join(REGRESSORS), _choice("exact", *REGRESSORS),
                       "force -> b model that the scene steps with (exact: tabulated analytic tissue; "
                       "regressors are trained on the scene's workspace data, MLPs by L-BFGS)"),
        "table_nodes": Field((25, 11, 9, 9), "", "4 counts, 2-257", _nodes,
                             "grid of the tabulated exact response (insertion, lateral, normal, sideways)"),
    },
    "device": {
        "kind": Field("ideal", "", "ideal | laryngoscope | module:attribute", _device_kind,
                      "ideal: force = scaled action; laryngoscope: a blade in pymunk moved by a hand; or a "
                      "'module:attribute' naming a softenv.devices.base.DeviceKind (README: adding a device)"),
        "insertion_deg": Field((30.0, 120.0), "deg", "within [0, 180]", _pair(0, 180),
                               "contact range along the midline, from the front (0) over the top (90)"),
        "lateral_deg": Field(20.0, "deg", "(0, 80]", _real(0, 80, lo_open=True), "contact range off the midline, +-"),
        "max_normal_force": Field(40.0, "N", "(0, 1e6]", _real(0, 1e6, lo_open=True), "largest pressing force"),
        "max_sideways_force": Field(10.0, "N", "(0, 1e6]", _real(0, 1e6, lo_open=True), "largest sideways force, +-"),
        # the laryngoscope's parameters (ignored by other devices); see softenv.devices.laryngoscope.params
        "blade_mass": Field(0.08, "kg", "[0.005, 10]", _real(0.005, 10), "Macintosh 3 blade (stainless, ~80 g)"),
        "handle_mass": Field(0.15, "kg", "[0, 10]", _real(0, 10), "battery handle held by the hand (~150 g)"),
        "coupling_stiffness": Field(2000.0, "N/m", "(0, 1e7]", _real(0, 1e7, lo_open=True),
                                    "virtual coupling hand -> blade, translation (and the lateral sweep)"),
        "coupling_damping": Field(6.0, "N s/m", "[0, 1e5]", _real(0, 1e5),
                                  "virtual coupling damping (6: damping ratio 0.14 at the default masses)"),
        "rotational_stiffness": Field(30.0, "N m/rad", "(0, 1e5]", _real(0, 1e5, lo_open=True),
                                      "virtual coupling, wrist pitch (CHAI3D's tool example: 30)"),
        "rotational_damping": Field(0.03, "N m s/rad", "[0, 1e3]", _real(0, 1e3),
                                    "virtual coupling, pitch damping (0.03: damping ratio 0.11)"),
        "max_hand_speed": Field(0.2, "m/s", "(0, 5]", _real(0, 5, lo_open=True), "hand speed at |action| = 1 (insert, press)"),
        "max_sweep_speed": Field(0.1, "m/s", "(0, 5]", _real(0, 5, lo_open=True), "hand sideways speed at |action| = 1"),
        "max_pitch_rate": Field(1.0, "rad/s", "(0, 20]", _real(0, 20, lo_open=True), "wrist pitch rate at |action| = 1"),
        "friction": Field(0.5, "", "[0, 5]", _real(0, 5), "blade-tongue Coulomb friction (limits the sweep force)"),
        "max_substep": Field(1e-3, "s", "[1e-6, 1e-3]", _real(1e-6, 1e-3), "longest physics substep (1 kHz or finer)"),
        "haptic_preset": Field("omega", "", "touch | falcon | omega", _choice("touch", "falcon", "omega"),
                               "force-feedback device whose limits shape haptic_force_N"),
        "batch_engine": Field("auto", "", "auto | warp | triton | pymunk", _batch_engine,
                              "what steps the laryngoscope in vector envs and the torch twin: warp (one Warp "
                              "kernel a step, CPU or CUDA; bit for bit with the single env on CPU), triton (one "
                              "Triton kernel a step, torch twin on CUDA only), pymunk (one space, numpy twin only; "
                              "agrees to rounding); auto is triton on CUDA tensors where triton is installed, warp "
                              "elsewhere"),
    },
    "dynamics": {
        "kind": Field("quasi_static", "", "quasi_static | viscoelastic", _choice("quasi_static", "viscoelastic"),
                      "tissue responds instantly, or creeps (standard linear solid in b-space)"),
        "dt": Field(0.05, "s", "(0, 10]", _real(0, 10, lo_open=True), "control period"),
        "relaxed_fraction": Field(0.7, "", "(0, 1]", _real(0, 1, lo_open=True),
                                  "share of the deformation that appears at once (Hastings 1996: ~70 %)"),
        "time_constant": Field(5.8, "s", "[0, 1e6]", _real(0, 1e6), "creep time constant (Hastings 1996: ~5.8 s)"),
    },
    "task": {
        "kind": Field("reach", "", "reach | procedure", _choice("reach", "procedure"),
                      "reach one target shape, or follow insert -> press -> sweep"),
        "split": Field("train", "", "train | test", _choice("train", "test"), "target set (disjoint in force space)"),
        "horizon": Field(100, "steps", "1-100000", _int(1, 100_000), "episode length: the env truncates here, on every path"),
        "tolerance": Field(0.1, "", "(0, 1)", _real(0, 1, lo_open=True, hi_open=True),
                           "success: shape error below this share of the target's displacement"),
        "terminate_on_success": Field(False, "", "True | False", _bool, "end the episode on success"),
        "target_insertion_deg": Field((75.0, 110.0), "deg", "within the device range", _pair(0, 180),
                                      "laryngoscopy targets: insertion depth"),
        "target_lateral_deg": Field((-4.0, 8.0), "deg", "within the device range", _pair(-80, 80),
                                    "laryngoscopy targets: lateral offset"),
        "target_normal_force": Field((20.0, 40.0), "N", "within the device range", _pair(0, 1e6),
                                     "laryngoscopy targets: compression"),
        "target_sideways_force": Field((3.0, 10.0), "N", "within the device range", _pair(-1e6, 1e6),
                                       "laryngoscopy targets: sweep toward +y"),
    },
    "reward": {
        "shape_weight": Field(1.0, "", ">= 0", _real(0, None), "weight of -(shape error / target displacement)"),
        "force_weight": Field(0.0, "", ">= 0", _real(0, None), "weight of -(force above safe_force) / safe_force"),
        "safe_force": Field(30.0, "N", "> 0", _real(0, None, lo_open=True), "force above which the penalty applies"),
        "smoothness_weight": Field(0.0, "", ">= 0", _real(0, None), "weight of -mean squared action change"),
        "incisor_weight": Field(1.0, "", ">= 0", _real(0, None),
                                "weight of -(incisor force) / safe_force (laryngoscope; any force is an error)"),
    },
    "airway": {
        "grade": Field(1, "", "1-4", _choice(*GRADES),
                       "difficult-airway grade: 1 normal, 2 restricted neck extension, 3 restricted mouth opening, 4 "
                       "both with a stiff tongue (docs: airways); the settings below left at None take the grade's "
                       "values"),
        "mouth_opening": Field(None, "mm", "[0, 20] | None", _optional(_real(0, 20)),
                               "the upper incisal edge's clearance above the blade's flange in the start pose "
                               "(grade 1: 3)"),
        "neck_extension": Field(None, "rad", "[0.1, 0.5] | None", _optional(_real(0.1, 0.5)),
                                "largest blade pitch the hand may give, either way (grade 1: 0.5)"),
        "larynx_depth": Field(None, "deg", "[-20, 20] | None", _optional(_real(-20, 20)),
                              "added to task.target_insertion_deg: how far back the view lies (grade 1: 0)"),
        "larynx_lift": Field(None, "", "[0.5, 2] | None", _optional(_real(0.5, 2)),
                             "multiplies task.target_normal_force: how much lift the view needs (grade 1: 1)"),
        "tongue_stiffness": Field(None, "", "[0.5, 2] | None", _optional(_real(0.5, 2)),
                                  "multiplies tissue.E and the target forces: the normal tongue's target shapes, "
                                  "each needing that much more force (grade 1: 1)"),
        "interincisal_gap": Field(None, "mm", "[22, 80] | None", _optional(_real(22, 80)),
                                  "the upper and lower incisal edges' distance in the start pose, with the blade's "
                                  "22 mm flange and mouth_opening between them (at least their sum); every grade: "
                                  "no lower teeth"),
    },
    "render": {
        "size": Field(320, "px", "64-2048", _int(64, 2048), "frame width and height"),
        "fps": Field(20, "1/s", "1-240", _int(1, 240), "frames per second in human mode"),
    },
}


def default_config() -> SceneConfig:
    """The default scene (SoftSphere-v0), as a fresh nested dict."""
    return cast(SceneConfig, {section: {key: copy.deepcopy(f.default) for key, f in fields.items()}
                              for section, fields in SCHEMA.items()})


def make_config(base: Mapping[str, Any] | None = None, **overrides: Any) -> SceneConfig:
    """Merge ``overrides`` (section -> {key: value}) into ``base`` (default: the defaults) and validate."""
    check_sections(overrides, "make_config()")
    config: dict[str, dict[str, Any]] = copy.deepcopy(
        {s: dict(v) for s, v in cast(Mapping[str, Mapping[str, Any]], base if base is not None else default_config()).items()})
    for section, values in overrides.items():
        if not isinstance(values, dict):
            raise ValueError(f"scene section {section!r} must be a dict of settings, got {values!r}; "
                             f"valid keys: {_keys_help(section)}")
        for key, value in values.items():
            if key not in SCHEMA[section]:
                raise ValueError(f"unknown key {key!r} in scene section {section!r}; valid keys: {_keys_help(section)}")
            config[section][key] = value
    return validate_config(config)


def check_sections(sections: dict[str, Any], caller: str) -> None:
    """Raise :class:`UnknownSectionError` for the first keyword in ``sections`` that is no scene section."""
    for section in sections:
        if section not in SCHEMA:
            raise UnknownSectionError(f"{caller} got an unexpected keyword argument {section!r} (not a scene section); "
                                      f"valid sections: {list(SCHEMA)}")


def scene_sections(scene: Any, name: str = "scene") -> dict[str, Any]:
    """A caller's scene: ``None`` (the id's own) or a dict of sections, e.g. ``{"tissue": {"E": 5e3}}``
    (their keys and values are checked when the config is made)."""
    if scene is None:
        return {}
    if not isinstance(scene, dict):
        raise ValueError(f"{name}={scene!r} must be a dict of scene sections or None; valid sections: {list(SCHEMA)}")
    check_sections(scene, name)
    return dict(scene)


def scene_config(base_scene: dict[str, Any] | None, sections: dict[str, Any],
                 caller: str = "make_config()") -> SceneConfig:
    """An env's config: its registered scene overrides, then the caller's sections, merged key by key.
    ``caller`` names the constructor in the error for an unknown keyword."""
    check_sections(sections, caller)
    return make_config(make_config(**(base_scene or {})), **sections)


def check_config(config: Any, name: str = "config", maker: str = "make_config(**sections)") -> SceneConfig:
    """``config`` if it is a made config (every section with every key, as :func:`make_config` returns);
    else a ``ValueError`` naming what is missing and ``maker``, the call that makes one. Its values are
    checked where an env is made from it."""
    made = isinstance(config, Mapping) and set(config) == set(SCHEMA) and all(
        isinstance(config[s], Mapping) and set(config[s]) == set(fields) for s, fields in SCHEMA.items())
    if not made:
        given = sorted(config) if isinstance(config, Mapping) else type(config).__name__
        raise ValueError(f"{name} must be a scene config made by make_config() (every section: {list(SCHEMA)}, "
                         f"each with every key), got {given!r}; make one from sections with {maker}")
    return cast(SceneConfig, config)


def validate_config(config: Mapping[str, Any]) -> SceneConfig:
    """Check every value and the constraints between them; returns the normalised config."""
    out: dict[str, dict[str, Any]] = {}
    for section, fields in SCHEMA.items():
        values = config.get(section, {})
        out[section] = {key: f.check(values.get(key, f.default), f"{section}.{key}") for key, f in fields.items()}
    t, dev, task = out["tissue"], out["device"], out["task"]
    if not t["radius"] / 1000 * (1 - 1e-12) <= t["patch_radius"] <= t["radius"]:      # ends included despite rounding
        raise ValueError(f"tissue.patch_radius={t['patch_radius']:g} m must lie within [radius / 1000, radius] = "
                         f"[{t['radius'] / 1000:g}, {t['radius']:g}] m (tissue.radius={t['radius']:g} m)")
    # the design force's indentation over the radius (linear law): below ~1e-9 the deformations drown in the
    # rounding of the surface coordinates and the shape model has nothing to fit
    E, nu = scene_material(out)
    design = 2 * (1 - nu ** 2) * dev["max_normal_force"] / (math.pi * t["patch_radius"] * E * t["radius"])
    if design < MIN_DESIGN_INDENTATION:
        raise ValueError(f"device.max_normal_force={dev['max_normal_force']:g} N on tissue.E={E:g} Pa indents the "
                         f"sphere (tissue.radius={t['radius']:g} m, tissue.patch_radius={t['patch_radius']:g} m) by "
                         f"{design:.2g} of its radius; at least {MIN_DESIGN_INDENTATION:g} is needed to resolve the "
                         "deformations: lower tissue.E or raise device.max_normal_force")
    if t["model"] == "fem":
        _check_fem(cast(SceneConfig, out), design)
    if task["target_normal_force"] == (0.0, 0.0) and task["target_sideways_force"] == (0.0, 0.0):
        raise ValueError("task.target_normal_force and task.target_sideways_force are both (0, 0): every target "
                         "would be the rest shape; give the target family a force")
    if dev["insertion_deg"][1] <= dev["insertion_deg"][0]:
        raise ValueError(f"device.insertion_deg={dev['insertion_deg']!r}: high must exceed low")
    mesh = out["mesh"]
    limit = (3, 200) if mesh["kind"] == "latlong" else (0, 6)
    check_int(mesh["resolution"], "mesh.resolution", *limit)
    checks = [("target_insertion_deg", dev["insertion_deg"]), ("target_lateral_deg", (-dev["lateral_deg"], dev["lateral_deg"])),
              ("target_normal_force", (0.0, dev["max_normal_force"])),
              ("target_sideways_force", (-dev["max_sideways_force"], dev["max_sideways_force"]))]
    ranges = target_ranges(task, out["airway"])
    for key, (lo, hi) in checks:
        a, b = ranges[key]
        if a < lo or b > hi:
            on = "" if ranges[key] == task[key] else f" (on airway grade {out['airway']['grade']}: {(a, b)!r})"
            raise ValueError(f"task.{key}={task[key]!r}{on} must lie within the device range [{lo:g}, {hi:g}]")
    return cast(SceneConfig, out)


def material(tissue: Mapping[str, Any], stiffness: float = 1.0) -> tuple[float, float]:
    """``(E, nu)`` of a tissue section, its model's defaults where they are None: nu 0.45 (analytic) or
    0.49 (fem: nearly incompressible), E such that 40 N indents 40 % of the default radius at that nu; E
    times ``stiffness`` (an airway's tongue stiffness)."""
    nu = tissue["nu"] if tissue["nu"] is not None else (FE_POISSON if tissue["model"] == "fem" else TONGUE_POISSON)
    return (tissue["E"] if tissue["E"] is not None else effective_modulus(nu=nu)) * stiffness, nu


def scene_material(config: Mapping[str, Any]) -> tuple[float, float]:
    """``(E, nu)`` of a scene's tongue: its tissue's on its airway."""
    return material(config["tissue"], airway(config["airway"]).tongue_stiffness)


def _check_fem(config: SceneConfig, design: float) -> None:
    """The limits of the finite-element tongue (softenv.fem.params.FEParams) and of its data's ramps; ``design``
    is the device's largest force's indentation over the radius (linear law)."""
    t, n_loads = config["tissue"], config["shape_model"]["n_loads"]
    if design > DESIGN_INDENTATION * (1 + 1e-9):
        force = config["device"]["max_normal_force"]
        raise ValueError(f"device.max_normal_force={force:g} N indents the FE tongue by {design:.3g} of its radius "
                         f"(linear law); the FE ramps are verified up to {DESIGN_INDENTATION:g} (the design force on "
                         f"the default mesh; beyond it Newton may lose the solution): lower the force to at most "
                         f"{force * DESIGN_INDENTATION / design:.4g} N, stiffen the tongue, or use the analytic tongue")
    if t["law"] != "linear":
        raise ValueError(f"tissue.law={t['law']!r} applies to tissue.model='analytic' only; the FE tongue is "
                         "neo-Hookean (its nonlinearity is its own): leave tissue.law at 'linear'")
    E, nu = scene_material(config)
    check_real(E, "tissue.E (fem model)", 1.0, 1e9)
    check_real(nu, "tissue.nu (fem model)", 0.0, 0.4999)
    if n_loads % RAMP_STEPS:
        raise ValueError(f"shape_model.n_loads={n_loads} must be a multiple of {RAMP_STEPS} with tissue.model='fem' "
                         f"(the FE data's samples are the {RAMP_STEPS} load steps of each ramp)")


def describe_config() -> str:
    """A Markdown table of every setting: section, key, default, unit, allowed values, meaning."""
    lines = ["| section | key | default | unit | allowed | meaning |", "|---|---|---|---|---|---|"]
    for section, fields in SCHEMA.items():
        for key, f in fields.items():
            default = f"{f.default:.4g}" if isinstance(f.default, float) else repr(f.default)
            cells = (section, key, default, f.unit, f.allowed, f.doc)
            lines.append("| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |")   # a cell's "|" escaped
    return "\n".join(lines)


def _keys_help(section: str) -> str:
    return ", ".join(f"{k} ({f.unit + ', ' if f.unit else ''}{f.allowed})" for k, f in SCHEMA[section].items())


FE_KEYS = ("model", "fe_cells")     # tissue keys of the fem model (left out of an analytic scene's key)


def config_key(config: Mapping[str, Any], sections: tuple[str, ...]) -> str:
    """A stable text key of some sections (for caches and saved agents). An analytic tissue is keyed
    as before the fem model existed (resolved E and nu, no FE keys), and a device batched by an exact
    engine as before ``device.batch_engine`` existed, so caches and agents made then stay valid. The
    airway bears on the tissue, the device and the task: its resolved settings are keyed with any of
    them, unless they are the normal airway's (keyed as before airways existed)."""
    keyed = dict(config)
    device = config.get("device")
    if device is not None and device.get("batch_engine") in EXACT_ENGINES:
        # engines that equal the single env bit for bit make the same runs: keyed as before the setting
        keyed["device"] = {k: v for k, v in device.items() if k != "batch_engine"}
    t = config.get("tissue")
    if t is not None and t["model"] == "analytic":
        E, nu = material(t)
        keyed["tissue"] = {**{k: v for k, v in t.items() if k not in FE_KEYS}, "E": E, "nu": nu}
    keys = [(s, sorted(keyed[s].items())) for s in sections]
    section = config.get("airway")
    if section is not None and set(sections) & {"tissue", "device", "task"}:
        settings = airway(section)
        if not settings.is_normal:
            keys.append(("airway", list(settings.keyed().items())))
    return repr(keys)

