"""Difficult airways: the airway's settings and the grades that set them.

A scene's ``airway`` section holds a ``grade`` (1 normal ... 4 very difficult) and six settings,
each ``None`` to take the grade's value (:data:`GRADES`) or a number of its own:

| setting | unit | what it changes in the scene |
|---|---|---|
| ``mouth_opening`` | mm | the upper incisal edge's clearance above the blade's flange in the start pose |
| ``neck_extension`` | rad | the largest pitch the hand may give the blade, either way (the head's tilt) |
| ``larynx_depth`` | deg | added to the target family's insertion angles: how far back the view lies |
| ``larynx_lift`` | | multiplies the target family's normal forces: how much lift the view needs |
| ``tongue_stiffness`` | | multiplies the tongue's Young's modulus, and the target family's forces with it, so the
  targets are the normal tongue's shapes, each needing that much more force |
| ``interincisal_gap`` | mm | the upper and lower incisal edges' distance in the start pose, the blade's flange and
  ``mouth_opening`` between them; ``None`` (grades 1 and 2): no lower teeth (a jaw that never closes on the blade) |

Grade 1 is the airway of every laryngoscope scene before grades existed (SoftSphereHaptic-v0's), so
a scene whose airway section is left at its defaults is keyed, cached and scored as before. The
grades' sources and choices are in the docs (``docs/airways.md``). Pure data: no device and no env.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Mapping
from typing import Any

# grade -> (name, mouth opening mm, neck extension rad, larynx depth deg, larynx lift, tongue stiffness,
# interincisal gap mm or None)
GRADES: dict[int, tuple[str, float, float, float, float, float, float | None]] = {
    1: ("normal", 3.0, 0.5, 0.0, 1.0, 1.0, None),
    2: ("restricted neck extension", 2.0, 0.4, 2.0, 1.1, 1.0, None),
    3: ("restricted mouth opening", 1.0, 0.5, 2.0, 1.2, 1.0, 35.0),
    4: ("restricted neck extension and mouth opening, stiff tongue", 0.0, 0.4, 4.0, 1.25, 1.15, 33.0),
}
SETTINGS = ("mouth_opening", "neck_extension", "larynx_depth", "larynx_lift", "tongue_stiffness", "interincisal_gap")


@dataclass(frozen=True)
class Airway:
    """An airway's settings resolved from its section (see the module docstring)."""

    grade: int
    mouth_opening: float              # mm
    neck_extension: float             # rad
    larynx_depth: float               # deg
    larynx_lift: float
    tongue_stiffness: float
    interincisal_gap: float | None    # mm; None: no lower teeth

    @property
    def name(self) -> str:
        return GRADES[self.grade][0]

    @property
    def settings(self) -> tuple[float, ...]:
        """The values of :data:`SETTINGS`, in order."""
        return tuple(getattr(self, k) for k in SETTINGS)

    def keyed(self) -> dict[str, float]:
        """The settings by name, an absent part (a setting at ``None``: no lower teeth) left out: how keys,
        logs and reports name the airway, the same as before that part existed."""
        return {k: v for k, v in zip(SETTINGS, self.settings) if v is not None}

    @property
    def is_normal(self) -> bool:
        """Whether every setting is the normal airway's (grade 1)."""
        return self.settings == GRADES[1][1:]

    @property
    def normal_force_scale(self) -> float:
        """The target family's normal forces over the normal airway's."""
        return self.larynx_lift * self.tongue_stiffness


def airway(section: Mapping[str, Any]) -> Airway:
    """The settings of an ``airway`` section (a made config's): each ``None`` takes its grade's value."""
    grade = section["grade"]
    values: tuple[Any, ...] = GRADES[grade][1:]
    # a section written before a setting existed (an older log's) takes the grade's value for it
    return Airway(grade, *(float(section[k]) if section.get(k) is not None else v for k, v in zip(SETTINGS, values)))


NORMAL_AIRWAY: dict[str, Any] = {"grade": 1, **{k: None for k in SETTINGS}}     # the section's defaults


def tongue_only(section: Mapping[str, Any]) -> dict[str, Any]:
    """A normal airway with this section's tongue: what a scene's tongue, shape model and response depend on."""
    return {**NORMAL_AIRWAY, "tongue_stiffness": airway(section).tongue_stiffness}


def target_ranges(task: Mapping[str, Any], section: Mapping[str, Any]) -> dict[str, tuple[float, float]]:
    """The target family's ranges on this airway: the task's ranges (the normal airway's) deepened by the
    larynx's depth, their normal forces scaled by its lift and the tongue's stiffness, their sideways forces
    by the tongue's stiffness."""
    a = airway(section)
    scale = {"target_insertion_deg": (1.0, a.larynx_depth), "target_lateral_deg": (1.0, 0.0),
             "target_normal_force": (a.normal_force_scale, 0.0), "target_sideways_force": (a.tongue_stiffness, 0.0)}
    return {key: (lo * s + shift, hi * s + shift) for key, (s, shift) in scale.items()
            for lo, hi in [task[key]]}


def scene_title(section: Mapping[str, Any]) -> str:
    """A scene's name as a trainee reads it: SoftSphereHaptic-v0's airway, or the graded airway's grade."""
    a = airway(section)
    if a.grade == 1 and a.is_normal:
        return "SoftSphereHaptic-v0"
    custom = "" if a.settings == GRADES[a.grade][1:] else ", settings changed"
    return f"airway grade {a.grade} ({a.name}{custom})"


def grade_table() -> str:
    """A Markdown table of the grades and their settings."""
    lines = ["| grade | name | mouth opening (mm) | neck extension (rad) | larynx depth (deg) | larynx lift | "
             "tongue stiffness | interincisal gap (mm) |", "|---|---|---|---|---|---|---|---|"]
    for grade, (name, *values) in GRADES.items():
        lines.append(f"| {grade} | {name} | " + " | ".join("no lower teeth" if v is None else f"{v:g}" for v in values)
                     + " |")
    return "\n".join(lines)
