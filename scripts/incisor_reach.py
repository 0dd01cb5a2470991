"""Why the scripted expert never loads the upper teeth: how deep a view lifting reaches on each airway grade
(each with its own lower incisors, where it has them), and where levering on the upper incisors would take the
blade; and how lower incisors at other gaps change that.

    python scripts/incisor_reach.py --out results [--step-deg 0.5] [--gaps 40 35 34 33 32 30 28 26]

For each grade of SoftSphereAirway-v0, at its family's centre force ``P*`` (softenv.airway):

* **lifting**: the scripted expert's controller (HandController: insert, lift along the handle, sweep)
  toward the centre target with its insertion angle stepped deeper by ``--step-deg`` from the centre's; the
  jaw's peak force at the centre, the deepest it reaches (the env's success at the end of the episode) with the teeth untouched, and what
  stops it one step further;
* **levering**: the same start until the blade rests on the tongue, then the hand turned about the incisal
  edge (:func:`lever_action`) until the tongue's normal force is ``P*``, and held; the blade's insertion
  angle there (90 deg + its pitch: the underside's point nearest the tongue's centre) and the teeth's force,
  or, where the neck's limit stops the turn first, the force it reached.

The blade's flange sits under the incisors and lifting moves it away from them, so a view the lift reaches
never needs the teeth; the lever reaches at most a little deeper, and where the neck's limit stops it, not
that far. Then, with lower incisors under the blade (``airway.interincisal_gap`` at each of ``--gaps``, mm):

* **lifting** toward the centre target: whether it reaches it, the tongue's force at the end, the jaw's
  peak force and how close the hand came to its workspace's floor;
* **levering** as above: the force it holds, the teeth's and the jaw's force there.

Writes ``incisor_reach.md`` and ``incisor_reach.json`` into ``--out``.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
from pathlib import Path
from typing import Any

import numpy as np

from softenv._artifact import write_text
from softenv.airway import GRADES, airway, target_ranges
from softenv.bench.timing import code_revision
from softenv.devices.laryngoscope.control import HandController
from softenv.devices.laryngoscope.params import INCISOR_RADIUS, LaryngoscopeParams
from softenv.devices.laryngoscope.physics import hand_action
from softenv.envs import airway_scene
from softenv.training.hand import haptic_config, reach_env, relative_hand_pose, workspace

LEVER_GAIN = 0.025          # rad/s of turn per newton of normal-force error
HORIZON = 250               # control periods an attempt runs (5 s)


def lever_action(laryngoscope: Any, force: float) -> list[float]:
    """The action that turns the hand about the incisal edge, tip down, by ``LEVER_GAIN`` times the tongue's
    normal-force error toward ``force`` (N), at most the device's pitch rate (a single device's
    :class:`~softenv.devices.laryngoscope.single.Laryngoscope`)."""
    p = laryngoscope.params
    ix, iy = p.incisor
    gx, gy, pitch, _ = laryngoscope.hand_pose
    spin = float(np.clip(LEVER_GAIN * (force - laryngoscope.normal_force), -p.max_pitch_rate, p.max_pitch_rate))
    rx, ry = gx - ix, gy - (iy - INCISOR_RADIUS)
    return np.clip(hand_action(-spin * ry, spin * rx, spin, 0.0, pitch, p), -1.0, 1.0).tolist()


def scene(grade: int, gap: float | None = None) -> dict[str, Any]:
    """``grade``'s scene, with lower incisors ``gap`` mm under the upper ones where ``gap`` is given."""
    sections = airway_scene(grade)
    if gap is not None:
        sections["airway"] = {**sections["airway"], "interincisal_gap": gap}
    return sections


def centre(grade: int) -> tuple[float, float]:
    """The centre of ``grade``'s target family: insertion angle (deg) and normal force (N)."""
    config = haptic_config(scene(grade))
    ranges = target_ranges(config["task"], config["airway"])
    return float(np.mean(ranges["target_insertion_deg"])), float(np.mean(ranges["target_normal_force"]))


def _start(grade: int, insertion_deg: float, gap: float | None = None) -> tuple[Any, Any, np.ndarray, Any, slice]:
    """A reach env on ``grade`` (lower incisors ``gap`` mm under the upper, where given) reset toward the family's
    centre moved to ``insertion_deg``; its controller and the device's slice of the observation (what the
    controller reads)."""
    config = haptic_config(scene(grade, gap))
    env = reach_env(config, HORIZON)
    world = env.world
    target = world.family.centre.copy()           # insertion and lateral arc (m), normal and sideways force (N)
    target[0] = math.radians(insertion_deg) * config["tissue"]["radius"]
    obs, _ = env.reset(seed=0, options={"target": world.force_box.normalised(target)})
    return env, obs, target, HandController(world.config), slice(2 * world.k, 2 * world.k + world.device_obs_size)


def lift(grade: int, insertion_deg: float, gap: float | None = None) -> dict[str, Any]:
    """The expert's controller toward the centre target at ``insertion_deg``: reached, the teeth's and the jaw's
    peak force, the tongue's force at the end, and how far above its workspace's floor the hand came lowest (mm;
    0: it pressed as deep as the hand may go, so nobody could press harder)."""
    env, obs, target, controller, device = _start(grade, insertion_deg, gap)
    floor = workspace(env.world.config)[0][1]
    teeth = jaw = 0.0
    lowest = math.inf
    for _ in range(HORIZON):
        obs, _, _, _, info = env.step(controller.act(obs[None, device], target[None])[0].astype(np.float32))
        teeth = max(teeth, info["incisor_force_N"])
        jaw = max(jaw, float(env.device.laryngoscope.jaw_force))
        lowest = min(lowest, float(relative_hand_pose(env)[1]))
    return {"insertion_deg": insertion_deg, "reached": bool(info["is_success"]), "peak_incisor_N": teeth,
            "peak_jaw_N": jaw, "tongue_N": float(env.device.laryngoscope.normal_force),
            "shape_error_mm": info["shape_error_mm"], "above_floor_mm": (lowest - floor) * 1e3}


def lever(grade: int, gap: float | None = None, held: int = 50) -> dict[str, Any]:
    """Insert as the expert does until the blade rests on the tongue, then turn about the incisal edge to the
    centre's normal force and hold: the blade's insertion angle, the teeth's and the jaw's force, or the neck's
    limit."""
    env, obs, target, controller, device = _start(grade, centre(grade)[0], gap)
    laryngoscope = env.device.laryngoscope
    force = float(target[2])
    for _ in range(HORIZON):
        action = (controller.act(obs[None, device], target[None])[0] if laryngoscope.normal_force <= 0.0
                  else lever_action(laryngoscope, force))
        obs, *_ = env.step(np.asarray(action, dtype=np.float32))
    for _ in range(held):
        obs, *_ = env.step(np.zeros(4, dtype=np.float32))
    p, pitch = laryngoscope.params, laryngoscope.hand_pose[2]
    return {"force_N": force, "held_N": float(laryngoscope.normal_force),
            "insertion_deg": 90.0 + math.degrees(float(laryngoscope.kinematics()[2])),
            "incisor_N": float(laryngoscope.incisor_force), "jaw_N": float(laryngoscope.jaw_force),
            "hand_pitch_deg": math.degrees(pitch),
            "at_neck_limit": abs(pitch) >= p.pitch_limit - 1e-6}


def lift_reach(grade: int, step_deg: float, limit_deg: float = 130.0) -> dict[str, Any]:
    """Lifting from the centre's insertion angle deeper by ``step_deg``: the attempt at the centre, the deepest
    reached with the teeth untouched, and the first that was not (or ``None`` up to ``limit_deg``)."""
    insertion = centre(grade)[0]
    at_centre, deepest, first_failed = None, None, None
    while insertion <= limit_deg:
        attempt = lift(grade, insertion)
        at_centre = at_centre or attempt
        if not attempt["reached"] or attempt["peak_incisor_N"] > 0.0:
            first_failed = attempt
            break
        deepest = attempt
        insertion += step_deg
    return {"centre": at_centre, "deepest": deepest, "first_failed": first_failed}


def jaw_row(grade: int, gap: float) -> dict[str, Any]:
    """Lifting and levering toward ``grade``'s centre with lower incisors ``gap`` mm under the upper."""
    clearance = LaryngoscopeParams.from_config(haptic_config(scene(grade, gap))).lower_clearance   # refuses a gap too small
    return {"gap_mm": gap, "clearance_mm": clearance * 1e3, "lift": lift(grade, centre(grade)[0], gap),
            "lever": lever(grade, gap)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results"))
    parser.add_argument("--step-deg", type=float, default=0.5)
    parser.add_argument("--gaps", type=float, nargs="+", default=[40.0, 35.0, 34.0, 33.0, 32.0, 30.0, 28.0, 26.0],
                        help="interincisal gaps (mm) to try on every grade")
    args = parser.parse_args()
    rows = []
    for grade in GRADES:
        config = haptic_config(airway_scene(grade))
        insertion, force = centre(grade)
        rows.append({"grade": grade, "name": GRADES[grade][0],
                     "mouth_opening_mm": airway(config["airway"]).mouth_opening,
                     "interincisal_gap_mm": airway(config["airway"]).interincisal_gap,
                     "insertion_range_deg": list(target_ranges(config["task"], config["airway"])["target_insertion_deg"]),
                     "centre_insertion_deg": insertion, "centre_force_N": force,
                     "lift": lift_reach(grade, args.step_deg), "lever": lever(grade),
                     "jaw": [jaw_row(grade, gap) for gap in args.gaps]})
        print(f"grade {grade} done", flush=True)
    made = {"command": shlex.join(["python", *sys.argv]), "commit": code_revision(), "step_deg": args.step_deg,
            "gaps_mm": args.gaps}
    args.out.mkdir(parents=True, exist_ok=True)
    write_text(args.out / "incisor_reach.json", json.dumps({"made": made, "grades": rows}, indent=1) + "\n")
    write_text(args.out / "incisor_reach.md", report(rows, made))
    print(f"wrote {args.out}/incisor_reach.md and .json")


def report(rows: list[dict[str, Any]], made: dict[str, Any]) -> str:
    lines = ["# How deep a view lifting reaches, and where the lever on the incisors goes", "",
             f"Made by `{made['command']}` at {made['commit']}. Each grade of SoftSphereAirway-v0 at its target "
             f"family's centre force. Lifting: the scripted expert's controller toward the centre target with its "
             f"insertion angle stepped {made['step_deg']:g} deg deeper at a time from the centre's, {HORIZON} "
             f"control periods an attempt; the deepest reached (the env's success) with the teeth untouched, and "
             f"what stopped the next. Levering: the expert's insertion until the blade rests on the tongue, then the "
             f"hand turned about the incisal edge ({LEVER_GAIN} rad/s per newton of normal-force error) and held; "
             f"the blade's insertion angle there (90 deg + its pitch) and the teeth's force. Each grade with its own "
             f"lower incisors, where it has them (`airway.interincisal_gap`).", "",
             "| grade | mouth opening (mm) | interincisal gap (mm) | family insertion (deg) | centre force (N) | "
             "lifting at the centre: jaw peak (N) | lifting reaches, teeth untouched (deg) | one step deeper | "
             "lever: insertion (deg) | lever: teeth (N) | lever: force held (N) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        deepest, failed, lev = r["lift"]["deepest"], r["lift"]["first_failed"], r["lever"]
        why = ("-" if failed is None else "not reached" if not failed["reached"]
               else f"teeth touched ({failed['peak_incisor_N']:.2g} N)")
        force = f"{lev['held_N']:.1f}" + (" (neck limit)" if lev["at_neck_limit"] else "")
        lo, hi = r["insertion_range_deg"]
        gap = "none" if r["interincisal_gap_mm"] is None else f"{r['interincisal_gap_mm']:g}"
        lines.append(f"| {r['grade']} | {r['mouth_opening_mm']:g} | {gap} | {lo:g}-{hi:g} | {r['centre_force_N']:.1f} | "
                     f"{r['lift']['centre']['peak_jaw_N']:.1f} | "
                     f"{'-' if deepest is None else format(deepest['insertion_deg'], '.1f')} | {why} | "
                     f"{lev['insertion_deg']:.1f} | {lev['incisor_N']:.1f} | {force} |")
    held = [r for r in rows if not r["lever"]["at_neck_limit"] and r["lift"]["deepest"] is not None]
    stopped = [r["grade"] for r in rows if r["lever"]["at_neck_limit"]]
    deeper = [r["lever"]["insertion_deg"] - r["lift"]["deepest"]["insertion_deg"] for r in held]
    teeth = [r["lever"]["incisor_N"] for r in rows]
    gained = [r["lift"]["deepest"]["insertion_deg"] - r["centre_insertion_deg"] for r in rows if r["lift"]["deepest"]]
    lines += ["", "Lifting along the handle moves the flange away from the incisors above it: it reaches views "
              f"{min(gained):.1f}-{max(gained):.1f} deg deeper than the family's centre with the teeth untouched. "
              f"Levering turns the blade about the incisal edge and loads the teeth with {min(teeth):.1f}-"
              f"{max(teeth):.1f} N"
              + (f"; where it holds the centre's force (grade {', '.join(str(r['grade']) for r in held)}) its view "
                 f"lies {min(deeper):+.1f} to {max(deeper):+.1f} deg from the lift's deepest" if held else "")
              + (f"; on grade {', '.join(map(str, stopped))} the neck's limit stops the turn short of the force"
                 if stopped else "")
              + ". The view fixes the blade's pitch (the underside's point nearest the tongue's centre lies at 90 deg "
              "plus the pitch), and at a given pitch pressing into the tongue moves the flange away from the upper "
              "incisors: no press that reaches a view short of the lift's deepest loads them, so an expert who lifts "
              "has no reason to. The lower incisors of the restricted mouth openings"
              + " (" + ", ".join(f"grade {r['grade']}: {r['lift']['centre']['peak_jaw_N']:.1f} N at the centre"
                                 for r in rows if r["interincisal_gap_mm"] is not None) + ")"
              + " take part of the lift's push where the view is shallow, and are left behind as the blade pitches "
              "tip-down for deeper views.", "",
              "## With lower incisors", "",
              f"The same two attempts toward each grade's centre with `airway.interincisal_gap` set (lower incisors "
              f"that gap under the upper ones; the clearance is the gap less the mouth opening and the flange's "
              f"{LaryngoscopeParams.flange_height * 1e3:g} mm: how far under the blade's underside they start). The jaw "
              f"yields as a 10 kN/m spring.", "",
              "| grade | gap (mm) | clearance (mm) | lift: reached | lift: tongue at the end (N) | lift: jaw peak (N) | "
              "lift: hand above its floor, lowest (mm) | lever: force held (N) | lever: teeth (N) | lever: jaw (N) |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for j in r["jaw"]:
            li, lev = j["lift"], j["lever"]
            force = f"{lev['held_N']:.1f}" + (" (neck limit)" if lev["at_neck_limit"] else "")
            lines.append(f"| {r['grade']} | {j['gap_mm']:g} | {j['clearance_mm']:g} | {'yes' if li['reached'] else 'no'} | "
                         f"{li['tongue_N']:.1f} | {li['peak_jaw_N']:.1f} | {li['above_floor_mm']:.1f} | {force} | "
                         f"{lev['incisor_N']:.1f} | "
                         f"{lev['jaw_N']:.1f} |")
    stopped = {r["grade"]: max((j["gap_mm"] for j in r["jaw"] if not j["lift"]["reached"]), default=None) for r in rows}
    lines += ["", "Widest gap at which the lift no longer reaches the centre: "
              + ", ".join(f"grade {g}: {'none tried' if v is None else f'{v:g} mm'}" for g, v in stopped.items())
              + ". Where the lift stops on the jaw, the tongue's force stalls below the target's and the jaw carries "
              "the rest of the hand's push; only turning the blade on the teeth takes the tongue further. Where the "
              "hand comes down to its floor (0 mm above it), the lift holds the centre only because the hand presses "
              "as deep as it may: a harder press is impossible there.", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
