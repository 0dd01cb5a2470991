"""Trainee scoring: replay a recorded trajectory through a scene and score it against the expert.

Two kinds of log (:mod:`softenv.training.logs`: schemas, files, checks): **hand poses**, as a haptic device
records them, replayed through the simulated laryngoscope and tongue (SoftSphereHaptic-v0's scene);
and **force commands**, replayed through the ideal device (SoftSphere-v0's). Every check runs before
the replay. The target is the centre of the scene's laryngoscopy family (the same for every
trainee); the expert is the scripted one (:mod:`softenv.training.trainee` for hand poses,
:func:`expert_trajectory` for force commands).

Scores run 0-100: accuracy times a weighted sum of parts, each clipped to [0, 1]. Every part but
accuracy counts in proportion to the progress made toward the target, so a session that does nothing,
or withdraws to where it started, scores 0: safety, teeth and smoothness are earned by doing the task
gently, not by leaving the patient alone. The formulas, part by part, are
:data:`HAND_FORMULA` (hand-pose logs: accuracy, speed, safety, teeth, smoothness as SPARC of the
hand's speed, glottic view) and :data:`FORMULA` (force-command logs: accuracy, speed, safety,
smoothness as the force's jerk), both built from the weights and terms below, and every report
carries its own.

``time_to_target``: first time the shape error falls under the scene's tolerance. ``INCISOR_LIMIT_N``
= 10 N, a stated choice: levering on the upper incisors is an error in the technique taught (lift along
the handle), though manikin studies measure peak incisor forces of 36-58 N in every group of experience
(Bucx et al. 1995); 10 N or more costs the whole term. On an airway with lower incisors the lift itself
rests the blade on them, so the teeth term adds only their force beyond the airway's expert's: a hand
that presses harder than the lift needs drives the blade into the jaw as well as the tongue.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..airway import airway, scene_title, target_ranges
from ..devices.laryngoscope import clinical
from .._artifact import Writer, atomic_write_all, check_out_dir
from .._validation import check_choice, check_int, check_real, printable
from ..envs.config import check_config, make_config, scene_sections
from ..envs.scene import degrees_to_features
from ..sections import SceneConfig
from .hand import hand_actions, hand_config, haptic_config, reach_env, steer
from .logs import (FORCE_LOG, HAND_LOG, MAX_DURATION_S, Schema, check_limits, check_table, read_log, read_scene,
                   save_log)
from .trainee import expert_hand_log

COLUMNS = FORCE_LOG.columns
INCISOR_LIMIT_N = 10.0
# the formulas' version: bump it when a weight, a term or the expert changes, so that stored scores
# (softenv.skills) can be told apart and rescored from their raw logs
SCORE_VERSION = 2            # 2: the teeth term counts the lower incisors' force beyond the expert's
# the score's parts: weights and definitions (force-command logs; hand-pose logs)
WEIGHTS = {"accuracy": 0.5, "speed": 0.2, "safety": 0.2, "smoothness": 0.1}
HAND_WEIGHTS = {"accuracy": 0.3, "speed": 0.15, "safety": 0.15, "teeth": 0.15, "smoothness": 0.1, "view": 0.15}
_COMMON = {"accuracy": "clip(1 - final_error / rest_error, 0, 1)",
           "speed": "clip(expert_time / time_to_target, 0, 1) (0 if never reached)"}
TERMS = {**_COMMON, "safety": "clip(1 - max(peak_force - safe_force, 0) / safe_force, 0, 1)",
         "smoothness": "clip(expert_jerk / jerk, 0, 1)"}
HAND_TERMS = {**_COMMON, "safety": "clip(1 - max(peak_tongue_force - safe_force, 0) / safe_force, 0, 1)",
              "teeth": f"clip(1 - (peak_incisor_force + max(peak_jaw_force - expert_peak_jaw_force, 0)) / "
                       f"{INCISOR_LIMIT_N:g} N, 0, 1) (upper incisors; lower incisors beyond the airway's expert's)",
              "smoothness": "clip(expert_sparc / sparc, 0, 1) (SPARC of the hand's speed; 0 if undefined)",
              "view": "clip((view - rest_view) / (expert_view - rest_view), 0, 1) (glottic-view proxy, %)"}


def formula(weights: dict[str, float], terms: dict[str, str]) -> str:
    """A score's formula in words: accuracy times the weighted sum, then each part's definition."""
    total = " + ".join(f"{w:g} {name}" for name, w in weights.items())
    return "; ".join([f"score = 100 accuracy ({total})", *(f"{name} = {terms[name]}" for name in weights)])


def total(parts: dict[str, float], weights: dict[str, float]) -> float:
    """The score from its parts (:func:`formula`): accuracy gates every part, so no progress scores 0."""
    return 100.0 * parts["accuracy"] * sum(w * parts[name] for name, w in weights.items())


FORMULA = formula(WEIGHTS, TERMS)
HAND_FORMULA = formula(HAND_WEIGHTS, HAND_TERMS)
# each part's advice in a trainee's words: a report names the parts whose shortfall costs most points
ADVICE = {
    "accuracy": "End closer to the target shape: press the tongue down and sweep it aside until it fits the outline.",
    "speed": "Reach the target sooner: insert, lift and sweep in one continuous movement.",
    "safety": "Press more gently: keep the tongue force under the safe limit ({safe_force:g} N).",
    "teeth": "Keep the blade off the upper teeth: lift along the handle instead of levering the blade on the incisors.",
    "smoothness": "Move steadily: one smooth movement instead of stops and corrections.",
    "view": "Open the view of the glottis: press the back of the tongue down and aside to clear the line of sight.",
}


# what a graded airway adds to a part's advice (softenv.airway), formatted with its settings and its target's force
AIRWAY_ADVICE = {
    "teeth": "On this airway the upper teeth sit {mouth_opening:g} mm above the blade's flange at the start: the "
             "least levering reaches them.",
    "lower teeth": "This airway's lower teeth lie {interincisal_gap:g} mm under the upper: press the blade onto them "
                   "no harder than the lift needs (a harder press squeezes the jaw, not the tongue).",
    "safety": "This airway's target needs about {target_force:.0f} N: build the lift steadily and stop there.",
    "accuracy": "On this airway the view lies {larynx_depth:g} deg deeper: slide the blade further in before lifting.",
}


def points_to_gain(parts: dict[str, float], expert_parts: dict[str, float],
                   weights: dict[str, float]) -> dict[str, float]:
    """For each part, the points the score would gain with that part alone as good as the expert's (0 where the
    trainee's is as good or better)."""
    now = total(parts, weights)
    return {k: max(0.0, total({**parts, k: max(parts[k], expert_parts[k])}, weights) - now) for k in weights}


def improvements(report: dict[str, Any], n: int = 2) -> list[str]:
    """The advice for the ``n`` parts whose shortfall against the expert's costs the most points, largest first
    (fewer where fewer parts fall short); on a graded airway, with what that airway asks of the part."""
    gain = report["points_to_gain"]
    worst = sorted((k for k in gain if gain[k] > 0.05), key=lambda k: -gain[k])[:n]
    patient = report.get("airway") or {}
    settings = patient.get("settings", {})
    graded = bool(patient) and not airway({"grade": 1, **settings}).is_normal
    words = {**settings, "safe_force": report["safe_force_N"], "target_force": patient.get("target_force_N", 0.0)}
    return [" ".join(text.format(**words) for text in _advice(k, report, graded)) for k in worst]


def _advice(part: str, report: dict[str, Any], graded: bool) -> list[str]:
    """A part's advice, the airway's addition where ``graded``; the teeth's names the teeth that cost the points:
    the upper ones (levered on) and the lower ones (pressed harder than the airway's expert did)."""
    if part != "teeth":
        return [ADVICE[part], *([AIRWAY_ADVICE[part]] if graded and part in AIRWAY_ADVICE else [])]
    trainee, expert = report["metrics"]["clinical"], report["expert"]["clinical"]
    upper = [ADVICE["teeth"], *([AIRWAY_ADVICE["teeth"]] if graded else [])] if trainee["peak_incisor_force_N"] > 0 else []
    return upper + ([AIRWAY_ADVICE["lower teeth"]] if trainee["peak_jaw_force_N"] > expert["peak_jaw_force_N"] else [])


@dataclass
class Replay:
    """A trajectory replayed through a scene: per-step series and the summary metrics. ``clinical``
    (:mod:`softenv.devices.laryngoscope.clinical`) and ``incisor_N`` exist for hand-pose logs only."""

    time_s: np.ndarray
    error_mm: np.ndarray
    force_N: np.ndarray
    final_error_mm: float
    rest_error_mm: float
    time_to_target_s: float | None
    peak_force_N: float
    mean_force_N: float
    force_time_integral_Ns: float
    jerk_rms: float
    incisor_N: np.ndarray | None = None
    clinical: dict[str, float] = field(default_factory=dict)
    frames: list[np.ndarray] = field(default_factory=list)     # rendered views, when asked for


def load_trajectory(path: str | Path) -> np.ndarray:
    """Read and check a force-command log; returns an ``(n, 5)`` float array in ``COLUMNS`` order."""
    return read_log(path, FORCE_LOG)[1]


def check_trajectory(table: Any, source: str = "trajectory") -> np.ndarray:
    """The force-command schema's shared rules on an in-memory table (:func:`softenv.training.logs.check_table`)."""
    return check_table(table, FORCE_LOG, source)


def check_ranges(table: np.ndarray, config: SceneConfig, source: str = "trajectory") -> None:
    dev = config["device"]
    check_limits(table, FORCE_LOG, {
        "insertion_deg": dev["insertion_deg"], "lateral_deg": (-dev["lateral_deg"], dev["lateral_deg"]),
        "normal_N": (0.0, dev["max_normal_force"]),
        "sideways_N": (-dev["max_sideways_force"], dev["max_sideways_force"])}, source)


def force_config(config: SceneConfig | None) -> SceneConfig:
    """``config`` (made by :func:`softenv.make_config`), or SoftSphere-v0's own for ``None``: a force-command log's scene."""
    return make_config() if config is None else check_config(config)


def replay(table: np.ndarray, config: SceneConfig | None = None, frame_every: int = 0) -> Replay:
    """Replay a validated force-command log through a reach scene whose target is the family centre
    (``config``: :func:`force_config`).

    Each row is held until the next (zero-order hold) and sampled at the scene's ``dt``. With
    ``frame_every`` > 0, the scene's view is rendered every that many steps (and after the last) into ``frames``.
    """
    check_int(frame_every, "frame_every", 0)
    table = check_trajectory(table).copy()
    table[:, 0] -= table[0, 0]                       # time counts from the first row
    config = force_config(config)
    check_ranges(table, config)
    dt = config["dynamics"]["dt"]
    times = (np.arange(max(1, int(math.floor(table[-1, 0] / dt + 1e-9)))) + 1) * dt
    rows = np.clip(np.searchsorted(table[:, 0], times - dt, side="right") - 1, 0, len(table) - 1)
    env = reach_env(config, len(times), render_mode="rgb_array" if frame_every else None)
    world = env.world
    features = degrees_to_features(table[rows, 1:], config["tissue"]["radius"])
    # ranges are checked above, so the clip only removes rounding at the box's faces
    actions = np.clip(world.force_box.normalised(features), -1.0, 1.0).astype(np.float32)
    env.reset(seed=0, options={"target": _family_centre(world)})
    error, force = np.empty(len(times)), np.empty(len(times))
    frames: list[np.ndarray] = []
    for i, a in enumerate(actions):
        _, _, _, _, info = env.step(a)
        error[i], force[i] = info["shape_error_mm"], info["force_N"]
        _keep_frame(env, i, len(times), frame_every, frames)
    applied = world.force_box.features(actions.astype(np.float64))[:, 2:]
    jerk = np.diff(applied, n=3, axis=0) / dt ** 3 if len(applied) > 3 else np.zeros((1, 2))
    return _replay(env, times, error, force, float(np.sqrt(np.mean(np.sum(jerk * jerk, axis=1)))), frames=frames)


def _keep_frame(env: Any, step: int, steps: int, every: int, frames: list[np.ndarray]) -> None:
    """Render the env's view into ``frames`` every ``every`` steps and after the last (0: never)."""
    if every and (step % every == 0 or step == steps - 1):
        frames.append(env.render())


def _family_centre(world: Any) -> np.ndarray:
    return world.force_box.normalised(world.family.centre)


def _replay(env: Any, times: np.ndarray, error: np.ndarray, force: np.ndarray, jerk_rms: float,
            **extra: Any) -> Replay:
    """The summary of a replayed episode (series in, metrics out)."""
    world, dt = env.world, times[0]
    ref = math.sqrt(max(float(np.sum((env.target_b[0] - world.b_rest) ** 2)), world.floor_sq) / world.n_vertices) * 1e3
    reached = np.flatnonzero(error < world.tolerance * ref)
    return Replay(times, error, force, float(error[-1]), ref, float(times[reached[0]]) if reached.size else None,
                  float(force.max()), float(force.mean()), float(force.sum() * dt), jerk_rms, **extra)


def replay_hand(table: np.ndarray, config: SceneConfig | None = None, source: str = "trajectory",
                frame_every: int = 0) -> Replay:
    """Replay a hand-pose log through the laryngoscope and tongue (``config``, made by
    :func:`~softenv.training.hand.haptic_config`; None: SoftSphereHaptic-v0's) toward the family centre:
    each control period the hand is commanded the velocity that brings it from where it is to the log's next pose (closed loop, so rounding never
    accumulates). ``frame_every``: as for :func:`replay` (the view has the side view beside the tongue)."""
    check_int(frame_every, "frame_every", 0)
    config = hand_config(config)
    times, poses = hand_actions(table, config, source)
    env = reach_env(config, len(times), render_mode="rgb_array" if frame_every else None)
    env.reset(seed=0, options={"target": _family_centre(env.world)})
    error, force, incisor = np.empty(len(times)), np.empty(len(times)), np.empty(len(times))
    frames: list[np.ndarray] = []
    for k, (_, info) in enumerate(steer(env, poses)):
        error[k], force[k], incisor[k] = info["shape_error_mm"], info["tongue_force_N"], info["incisor_force_N"]
        _keep_frame(env, k, len(times), frame_every, frames)
    return _replay(env, times, error, force, math.nan, incisor_N=incisor, clinical=info["clinical"], frames=frames)


def expert_trajectory(config: SceneConfig | None = None, duration_s: float = 5.0, style: str = "expert") -> np.ndarray:
    """A recorded-like trajectory of the laryngoscopy procedure toward the family centre.

    ``expert``: insert (first 30 %), press (to 60 %), sweep (to 80 %), hold; smooth (cosine ramps).
    ``too_forceful``: the same path pressing to the device's maximum with a 3 Hz tremor.
    ``wrong_direction``: presses too shallow, off to the other side, and sweeps toward -y.
    """
    check_real(duration_s, "duration_s", 0.1, MAX_DURATION_S)
    check_choice(style, "style", ("expert", "too_forceful", "wrong_direction"))
    config = force_config(config)
    task, dev = config["task"], config["device"]
    target = np.array([np.mean(r) for r in target_ranges(task, config["airway"]).values()])
    start_insertion = dev["insertion_deg"][0]
    if style == "wrong_direction":
        target = np.array([start_insertion + 0.3 * (target[0] - start_insertion), -target[1] - 8.0, target[2],
                           -target[3]])
    t = np.arange(0.0, duration_s + 1e-9, 0.02)
    ramp = lambda a, b: 0.5 - 0.5 * np.cos(np.pi * np.clip((t / duration_s - a) / (b - a), 0.0, 1.0))  # noqa: E731
    insertion = start_insertion + (target[0] - start_insertion) * ramp(0.0, 0.3)
    lateral = target[1] * ramp(0.0, 0.3)
    normal = target[2] * (0.1 + 0.9 * ramp(0.3, 0.6)) * (t > 0)
    sideways = target[3] * ramp(0.6, 0.8)
    if style == "too_forceful":
        normal = np.minimum(dev["max_normal_force"] * ramp(0.2, 0.3) * (1.0 + 0.15 * np.sin(2 * np.pi * 3.0 * t)),
                            dev["max_normal_force"])
    lateral = np.clip(lateral, -dev["lateral_deg"], dev["lateral_deg"])
    return np.stack([t, insertion, lateral, np.clip(normal, 0, dev["max_normal_force"]),
                     np.clip(sideways, -dev["max_sideways_force"], dev["max_sideways_force"])], axis=1)


def save_trajectory(table: np.ndarray, path: str | Path, note: str = "", scene: dict[str, Any] | None = None) -> None:
    """Write a force-command log as CSV, recording ``scene`` (:func:`softenv.training.logs.save_log`)."""
    save_log(table, path, FORCE_LOG, note, scene)


def score(trainee: Replay, expert: Replay, safe_force: float) -> dict[str, float]:
    """The force-command score and its parts (see the module docstring)."""
    parts = _common_parts(trainee, expert, safe_force)
    parts["smoothness"] = float(np.clip(expert.jerk_rms / max(trainee.jerk_rms, 1e-12), 0.0, 1.0))
    parts["score"] = total(parts, WEIGHTS)
    return parts


def hand_score(trainee: Replay, expert: Replay, safe_force: float, rest_view: float) -> dict[str, float]:
    """The hand-pose score and its parts (see the module docstring); ``rest_view``: the glottic view
    (%) of the untouched tongue."""
    parts = _common_parts(trainee, expert, safe_force)
    c, e = trainee.clinical, expert.clinical
    teeth = c["peak_incisor_force_N"] + max(c["peak_jaw_force_N"] - e["peak_jaw_force_N"], 0.0)
    parts["teeth"] = float(np.clip(1.0 - teeth / INCISOR_LIMIT_N, 0.0, 1.0))
    parts["smoothness"] = 0.0 if not math.isfinite(c["sparc"]) else float(np.clip(e["sparc"] / c["sparc"], 0.0, 1.0))
    gain = e["glottic_view_pct"] - rest_view
    parts["view"] = float(np.clip((c["glottic_view_pct"] - rest_view) / gain, 0.0, 1.0)) if gain > 0 else 1.0
    parts["score"] = total(parts, HAND_WEIGHTS)
    return parts


def _common_parts(trainee: Replay, expert: Replay, safe_force: float) -> dict[str, float]:
    return {
        "accuracy": float(np.clip(1.0 - trainee.final_error_mm / trainee.rest_error_mm, 0.0, 1.0)),
        "speed": 0.0 if trainee.time_to_target_s is None or expert.time_to_target_s is None
        else float(np.clip(expert.time_to_target_s / trainee.time_to_target_s, 0.0, 1.0)),
        "safety": float(np.clip(1.0 - max(trainee.peak_force_N - safe_force, 0.0) / safe_force, 0.0, 1.0)),
    }


def score_hand_log(table: np.ndarray, config: SceneConfig | None = None, source: str = "trajectory",
                   expert: Replay | None = None) -> tuple[dict[str, float], Replay, Replay]:
    """Score an in-memory hand-pose log on ``config`` (as :func:`replay_hand`); returns the parts, the trainee's
    and the expert's replays (pass ``expert`` to reuse one replay over many logs)."""
    config = hand_config(config)
    trainee = replay_hand(table, config, source)
    expert = expert or replay_hand(expert_hand_log(config), config, "the expert's log")
    rest_view = clinical.rest_view_analytic()
    return hand_score(trainee, expert, config["reward"]["safe_force"], rest_view), trainee, expert


def log_config(schema: Schema, scene: dict[str, Any] | None) -> SceneConfig:
    """The config a log of ``schema`` replays on: its id's scene (SoftSphereHaptic-v0 for hand poses,
    SoftSphere-v0 for force commands) with ``scene``'s sections."""
    return haptic_config(scene) if schema is HAND_LOG else make_config(**scene_sections(scene))


def scene_of(path: str | Path, schema: Schema, scene: dict[str, Any] | None,
             named: str | None = None) -> tuple[dict[str, Any], SceneConfig, str]:
    """The scene a log is replayed on: its sections, its made config, and where it came from: the one it
    records (a ``scene`` that makes another config is refused, named as the caller gave it: ``named``, else
    ``scene={...}``, never silently used), else ``scene``, else the id's own."""
    source = f"trajectory {str(path)!r}"
    recorded = read_scene(path)
    if recorded is None:
        sections = scene_sections(scene)
        return sections, log_config(schema, sections), "the caller" if scene else "the id's own (the log records none)"
    try:
        config = log_config(schema, recorded)
    except ValueError as exc:
        raise ValueError(f"{source}: the scene it records is not valid here: {exc}") from None
    if scene is not None and log_config(schema, scene) != config:
        raise ValueError(f"{source} was recorded on scene {recorded}; {named or f'scene={scene}'} asks for another scene "
                         "(omit it to replay the log on its own)")
    return recorded, config, "the log"


def score_file(path: str | Path, scene: dict[str, Any] | None = None, out_dir: str | Path | None = None,
               scene_named: str | None = None) -> dict[str, Any]:
    """Score a log file (hand poses or force commands, by its columns) on the scene it records (a log of
    ``format_version`` 2), else on ``scene`` (None: the id's own); a ``scene`` that contradicts the
    recorded one is refused (by ``scene_named``, how the caller named it, if given). With ``out_dir``, write
    ``<name>_score.json``, ``.md`` and ``.png``.
    Arguments and file are checked before any replay."""
    if out_dir is not None:
        check_out_dir(out_dir, "out directory")
    schema, table = read_log(path)
    sections, config, scene_from = scene_of(path, schema, scene, scene_named)
    return score_log(table, schema, config, path, sections, scene_from, out_dir)


def score_log(table: np.ndarray, schema: Schema, config: SceneConfig, path: str | Path, sections: dict[str, Any],
              scene_from: str, out_dir: str | Path | None = None) -> dict[str, Any]:
    """Score a log read from ``path`` on its made ``config`` (``sections``, from ``scene_from``, as the report
    names them): :func:`score_file` after it has read the file and made the scene, or a session that
    made its scene itself. With ``out_dir`` (checked by the caller), write the report's three files."""
    source = f"trajectory {str(path)!r}"
    safe_force = config["reward"]["safe_force"]
    if schema is HAND_LOG:
        parts, trainee, expert = score_hand_log(table, config, source)
        expert_parts = hand_score(expert, expert, safe_force, clinical.rest_view_analytic())
        formula, weights = HAND_FORMULA, HAND_WEIGHTS
    else:
        check_ranges(table, config, source)
        trainee, expert = replay(table, config), replay(expert_trajectory(config), config)
        parts, expert_parts = score(trainee, expert, safe_force), score(expert, expert, safe_force)
        formula, weights = FORMULA, WEIGHTS
    patient = airway(config["airway"])
    report = {"trajectory": printable(str(path)), "log": schema.name, "formula_version": SCORE_VERSION, "scene": sections, "scene_from": scene_from,
              "airway": {"grade": patient.grade, "name": patient.name, "title": scene_title(config["airway"]),
                         "settings": patient.keyed(),
                         "target_force_N": float(np.mean(target_ranges(config["task"], config["airway"])["target_normal_force"]))},
              **parts,
              "weights": weights, "expert_parts": expert_parts, "safe_force_N": safe_force,
              "points_to_gain": points_to_gain(parts, expert_parts, weights),
              "metrics": _summary(trainee), "expert": _summary(expert), "formula": formula}
    report["advice"] = improvements(report)
    if out_dir is not None:                 # the three files all or nothing: a failed write leaves none of them
        out = Path(out_dir)
        stem = Path(path).stem
        atomic_write_all([(out / f"{stem}_score.json", lambda fh: fh.write(json.dumps(report, indent=2)), True),
                          (out / f"{stem}_score.md", lambda fh: fh.write(_markdown(report)), True),
                          (out / f"{stem}_score.png", _plot(trainee, expert,
                                                            printable(f"{stem}: score {parts['score']:.0f}/100")),
                           False)])
    return report


def _summary(r: Replay) -> dict[str, Any]:
    out = {k: v for k, v in asdict(r).items() if not isinstance(v, (np.ndarray, dict, list)) and v is not None
           or k == "time_to_target_s"}
    if math.isnan(out["jerk_rms"]):
        del out["jerk_rms"]                                     # a hand log's smoothness is SPARC (clinical)
    if r.clinical:
        out["clinical"] = r.clinical
    return out


def _markdown(report: dict[str, Any]) -> str:
    m, e = report["metrics"], report["expert"]
    ttt = lambda v: "never" if v is None else f"{v:.2f} s"  # noqa: E731
    rows = [("final shape error", f"{m['final_error_mm']:.3f} mm", f"{e['final_error_mm']:.3f} mm"),
            ("time to target", ttt(m["time_to_target_s"]), ttt(e["time_to_target_s"])),
            ("peak tongue force", f"{m['peak_force_N']:.1f} N", f"{e['peak_force_N']:.1f} N"),
            ("mean tongue force", f"{m['mean_force_N']:.1f} N", f"{e['mean_force_N']:.1f} N"),
            ("force-time integral", f"{m['force_time_integral_Ns']:.1f} N s", f"{e['force_time_integral_Ns']:.1f} N s")]
    if "jerk_rms" in m:
        rows.append(("jerk (RMS)", f"{m['jerk_rms']:.3g} N/s^3", f"{e['jerk_rms']:.3g} N/s^3"))
    if "clinical" in m:
        mc, ec = m["clinical"], e["clinical"]
        rows += [("peak incisor force", f"{mc['peak_incisor_force_N']:.2f} N", f"{ec['peak_incisor_force_N']:.2f} N"),
                 ("incisor contact", f"{mc['incisor_contact_s']:.2f} s", f"{ec['incisor_contact_s']:.2f} s"),
                 ("peak jaw force (lower incisors)", f"{mc['peak_jaw_force_N']:.2f} N", f"{ec['peak_jaw_force_N']:.2f} N"),
                 ("lever share (moments about the incisors)", f"{mc['lever_share']:.2f}", f"{ec['lever_share']:.2f}"),
                 ("hand path", f"{mc['hand_path_m'] * 100:.1f} cm", f"{ec['hand_path_m'] * 100:.1f} cm"),
                 ("SPARC (hand speed)", f"{mc['sparc']:.2f}", f"{ec['sparc']:.2f}"),
                 ("LDLJ (hand speed)", f"{mc['ldlj']:.1f}", f"{ec['ldlj']:.1f}"),
                 ("glottic view", f"{mc['glottic_view_pct']:.0f} %", f"{ec['glottic_view_pct']:.0f} %"),
                 ("duration", f"{mc['duration_s']:.2f} s", f"{ec['duration_s']:.2f} s")]
    lines = [f"# Trainee score: {report['score']:.1f} / 100\n", f"Trajectory `{report['trajectory']}` "
             f"({report['log']}), replayed on scene sections `{json.dumps(report['scene'])}` "
             f"(from {report['scene_from']}): {report['airway']['title']}; the expert's reference is on the same "
             "airway.\n", "| metric | trainee | expert |", "|---|---|---|",
             *[f"| {a} | {b} | {c} |" for a, b, c in rows], "",
             "| part | weight | trainee | expert | points to gain |", "|---|---|---|---|---|",
             *[f"| {k} | {w:g} | {report[k]:.3f} | {report['expert_parts'][k]:.3f} | {report['points_to_gain'][k]:.1f} |"
               for k, w in report["weights"].items()], "",
             "To improve first: " + (" ".join(report["advice"]) or "nothing: every part is as good as the expert's."),
             "", f"Formula: {report['formula']}."]
    return "\n".join(lines) + "\n"


def _plot(trainee: Replay, expert: Replay, title: str) -> Writer:
    """The report's figure (shape error, tongue and incisor force against the expert) as a PNG writer."""
    import matplotlib                                       # the viz extra

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt                         # the viz extra

    panels = 3 if trainee.incisor_N is not None else 2
    fig, axes = plt.subplots(panels, 1, figsize=(6, 1.9 * panels + 0.8), sharex=True)
    series = [("shape error (mm)", "error_mm"), ("tongue force (N)", "force_N"), ("incisor force (N)", "incisor_N")]
    for ax, (label, key) in zip(axes, series):
        ax.plot(trainee.time_s, getattr(trainee, key), label="trainee")
        ax.plot(expert.time_s, getattr(expert, key), "--", label="expert")
        ax.set_ylabel(label)
    axes[0].legend(fontsize=7)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()

    def write(fh: Any) -> None:
        fig.savefig(fh, format="png", dpi=110)
        plt.close(fig)

    return write
