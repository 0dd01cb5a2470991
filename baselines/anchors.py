"""The normalized score's anchors on a scene's test targets: no force (0) and the planning oracle (100),
the summed shape errors every benchmark report (``softenv compare``, ``softenv.evaluation``,
``softenv.baselines.ppo_torch``) scales by.

The test targets are fixed by their seeds, so the anchors are the same numbers for everyone: they ship
with the package, one small JSON file a benchmark scene (``shipped_anchors/``, made by
``scripts/make_anchors.py``), each episode's two error sums by its seed. A file is used only for the
scene it names, made under this protocol and oracle version, whose config (every section the error
sums depend on) hashes as the scene's does now; episodes it lacks, or a scene it does not match, are
computed and kept in the cache (:mod:`softenv._cache`'s directory), saying so in one line.

Anchor file (``format_version`` 1), JSON:

| key | what |
|---|---|
| ``format``, ``format_version`` | ``"softenv-anchors"``, 1 |
| ``scene``, ``env_id``, ``scene_hash`` | the benchmark scene, its id, :func:`scene_hash` of its config |
| ``protocol``, ``oracle`` | :data:`PROTOCOL_VERSION`; the oracle's name, version and settings |
| ``seeds`` | the episodes' seeds |
| ``zero``, ``oracle_error_sum`` | each episode's summed shape error (mm x steps) under no force and the oracle |
| ``made_by`` | command, commit, softenv version |
"""

from __future__ import annotations

import hashlib
import inspect
import json
import sys
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from collections.abc import Mapping
from typing import Any, Callable

import numpy as np

import softenv
from softenv._artifact import atomic_write
from softenv._cache import cache_dir
from softenv.envs.config import config_key, make_config
from softenv.envs.world import World

from .evaluate import PROTOCOL_VERSION, Episodes, evaluate, scene_kwargs, episode_seeds
from .planner import TrajectoryOracle
from .policies import PlanningOracle, ZeroPolicy, make_baseline
from ..sections import SceneConfig

ANCHORS_FORMAT = "softenv-anchors"
ANCHORS_VERSION = 1
# what the error sums depend on: not the reward's weights, nor rendering
ANCHOR_SECTIONS = ("tissue", "mesh", "shape_model", "response", "device", "dynamics", "task")
# the oracle the 100 stands for on each device: its class's version and default search (a shipped file of
# another version or search is not used)
ORACLE: dict[str, dict[str, Any]] = {
    "ideal": {"name": "PlanningOracle", "version": PlanningOracle.VERSION, "settings": {}},
    "laryngoscope": {"name": "TrajectoryOracle", "version": TrajectoryOracle.VERSION,
                     "settings": {name: p.default for name, p in inspect.signature(TrajectoryOracle).parameters.items()
                                  if p.default is not inspect.Parameter.empty}}}
SHIPPED = Path(str(files(__package__ or "softenv.baselines") / "shipped_anchors"))


@dataclass
class Anchors:
    """Each episode's summed shape error under no force (``zero``) and the planning oracle (``oracle``),
    for the episodes seeded ``seeds``, and where they came from (``source``: a file, or computed)."""

    scene: str
    seeds: list[int]
    zero: np.ndarray
    oracle: np.ndarray
    source: str

    def digest(self) -> str:
        """A digest of the numbers (a result names the anchors it was scaled by)."""
        text = json.dumps([self.scene, self.seeds, self.zero.tolist(), self.oracle.tolist()])
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def scene_config(scene: str) -> SceneConfig:
    """The full config of a benchmark scene on its test targets."""
    _, kwargs = scene_kwargs(scene)
    kwargs.pop("obs_mode")
    return make_config(**kwargs)


def scene_hash(config: Mapping[str, Any]) -> str:
    """A digest of the sections a scene's error sums depend on (:data:`ANCHOR_SECTIONS`)."""
    return hashlib.sha256(config_key(config, ANCHOR_SECTIONS).encode()).hexdigest()[:16]


def oracle_of(scene: str) -> dict[str, Any]:
    """The oracle (name, version, settings) the scene's 100 stands for."""
    return ORACLE[World(scene_config(scene)).device_kind.name]


def anchor_job(scene: str, episodes: int, oracle_settings: dict[str, Any]
               ) -> tuple[np.ndarray, np.ndarray, Episodes | None]:
    """The anchors of the first ``episodes`` test episodes for ``softenv compare``: the shipped ones
    where ``oracle_settings`` (the device oracle's search, over its defaults) leave the scene's oracle as
    it is, else computed under them (then the oracle's own episodes are returned too: the table's oracle
    row)."""
    seeds = episode_seeds(episodes)
    oracle = oracle_of(scene)
    settings = {**oracle["settings"], **oracle_settings} if oracle["settings"] else {}   # the ideal one takes none
    if settings == oracle["settings"]:
        anchors = load_anchors(scene, seeds, echo=lambda line: None)
        return anchors.zero, anchors.oracle, None
    return compute_anchors(scene, seeds, settings)


def compute_anchors(scene: str, seeds: list[int], oracle_settings: dict[str, Any] | None = None
                    ) -> tuple[np.ndarray, np.ndarray, Episodes | None]:
    """The summed shape error of no force (0) and of the oracle (100) on the episodes seeded ``seeds``.
    On the ideal device the oracle is :class:`PlanningOracle`; on the laryngoscope
    :class:`TrajectoryOracle` (``oracle_settings``, default the shipped oracle's), which plans every
    episode through the device from the scripted expert's actions; its episodes are returned too."""
    world = World(scene_config(scene))
    zero = evaluate(ZeroPolicy(world), scene, len(seeds), list(seeds))
    if world.device_kind.name == "ideal":
        oracle = evaluate(PlanningOracle(world), scene, len(seeds), list(seeds))
        return zero.values["error_sum_mm"], oracle.values["error_sum_mm"], None
    planner = TrajectoryOracle(scene, **(oracle_settings or {}))
    planner.plan(make_baseline("expert", world), len(seeds), list(seeds))
    planned = evaluate(planner, scene, len(seeds), list(seeds))
    return zero.values["error_sum_mm"], planned.values["error_sum_mm"], planned


def anchors_file(scene: str) -> Path:
    return SHIPPED / f"{scene.replace('/', '_')}.json"


def anchors_record(scene: str, seeds: list[int], zero: np.ndarray, oracle: np.ndarray,
                   made_by: dict[str, str]) -> dict[str, Any]:
    """An anchor file's contents (see the module docstring)."""
    env_id, _ = scene_kwargs(scene)
    return {"format": ANCHORS_FORMAT, "format_version": ANCHORS_VERSION, "scene": scene, "env_id": env_id,
            "scene_hash": scene_hash(scene_config(scene)), "protocol": PROTOCOL_VERSION, "oracle": oracle_of(scene),
            "seeds": [int(s) for s in seeds], "zero": [float(v) for v in zero],
            "oracle_error_sum": [float(v) for v in oracle], "made_by": {**made_by, "softenv": softenv.__version__}}


def read_anchors(path: Path, scene: str) -> tuple[dict[int, tuple[float, float]], str]:
    """The per-seed anchors in ``path`` when it holds this scene's, as made now; else ``({}, why not)``.
    A file that is not a readable anchor file is refused (``ValueError`` naming it)."""
    try:
        record = json.loads(path.read_text())
        if record.get("format") != ANCHORS_FORMAT or record.get("format_version") != ANCHORS_VERSION:
            raise ValueError(f"format {record.get('format')!r} version {record.get('format_version')!r}, "
                             f"expected {ANCHORS_FORMAT!r} version {ANCHORS_VERSION}")
        seeds, zero, oracle = record["seeds"], record["zero"], record["oracle_error_sum"]
        if not (len(seeds) == len(zero) == len(oracle)) or not np.isfinite(np.r_[zero, oracle]).all():
            raise ValueError(f"{len(seeds)} seeds, {len(zero)} zero and {len(oracle)} oracle sums, all finite expected")
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise ValueError(f"anchor file {str(path)!r} is not usable: {exc}") from None
    expected = {"scene": scene, "scene_hash": scene_hash(scene_config(scene)), "protocol": PROTOCOL_VERSION,
                "oracle": oracle_of(scene)}
    differs = [f"{key} {record.get(key)!r} (now {value!r})" for key, value in expected.items() if record.get(key) != value]
    if differs:
        return {}, f"{path.name} was made for another {', '.join(differs)}"
    return {int(s): (float(z), float(o)) for s, z, o in zip(seeds, zero, oracle)}, ""


def _cached_file(scene: str) -> Path:
    return cache_dir() / f"anchors-{scene.replace('/', '_')}-{scene_hash(scene_config(scene))}.json"


def load_anchors(scene: str, seeds: list[int] | None = None,
                 echo: Callable[[str], None] | None = None) -> Anchors:
    """The anchors of the episodes seeded ``seeds`` (default: the protocol's test episodes) on a
    benchmark ``scene``: from the shipped file where it matches, else from the cache, else computed
    (and cached), with one line to ``echo`` (default: standard error) saying what was computed and why.
    A damaged shipped file is refused; a damaged cache entry is computed again."""
    say = echo if echo is not None else (lambda line: print(line, file=sys.stderr))
    seeds = episode_seeds() if seeds is None else [int(s) for s in seeds]
    shipped_path, cached_path = anchors_file(scene), _cached_file(scene)
    shipped, why = read_anchors(shipped_path, scene) if shipped_path.exists() else ({}, f"none ships for {scene}")
    try:
        cached = read_anchors(cached_path, scene)[0] if cached_path.exists() else {}
    except ValueError:
        cached = {}
    missing = [s for s in seeds if s not in shipped and s not in cached]
    if missing:
        say(f"anchors of {scene}: computing {len(missing)} episode(s) the shipped file does not hold "
            f"({why or 'other seeds'}); kept in {cached_path}")
        zero, oracle, _ = compute_anchors(scene, missing)
        cached.update({s: (float(z), float(o)) for s, z, o in zip(missing, zero, oracle)})
        order = sorted(cached)
        record = anchors_record(scene, order, np.array([cached[s][0] for s in order]),
                                np.array([cached[s][1] for s in order]),
                                {"command": "softenv.baselines.anchors.load_anchors"})
        atomic_write(cached_path, lambda fh: fh.write(json.dumps(record)), text=True)
    known = {**cached, **shipped}
    source = str(shipped_path) if all(s in shipped for s in seeds) else f"computed, kept in {cached_path}"
    return Anchors(scene, seeds, np.array([known[s][0] for s in seeds]), np.array([known[s][1] for s in seeds]), source)
