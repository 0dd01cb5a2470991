"""Haptic device presets: what a person holding a real force-feedback device would feel.

The simulation's virtual coupling may be stiffer than any device can render. The force sent to a
device is therefore scaled down so that the rendered stiffness never exceeds the device's maximum
stiffness (CHAI3D's rule for its tool examples), then saturated at the device's maximum force with
its direction kept. Figures at a 1 kHz servo rate, from CHAI3D's device drivers (Touch, Falcon,
omega.x); ``../shared/DESIGN.md`` section 7.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._ops import ArrayOps, PhysicsOps, ScalarOps


@dataclass(frozen=True)
class HapticPreset:
    """A force-feedback device's limits at 1 kHz (SI units)."""

    name: str
    max_force: float          # N, continuous force the device renders
    max_stiffness: float      # N/m, stiffest virtual spring it renders stably
    max_damping: float        # N s/m, largest virtual damping it renders stably
    workspace_radius: float   # m, radius of its translational workspace


PRESETS: dict[str, HapticPreset] = {
    "touch": HapticPreset("touch", 3.3, 400.0, 4.0, 0.075),        # 3D Systems Touch (Phantom Omni class)
    "falcon": HapticPreset("falcon", 8.0, 3000.0, 20.0, 0.04),     # Novint Falcon
    "omega": HapticPreset("omega", 12.0, 5000.0, 30.0, 0.075),     # Force Dimension omega.x
}


def render_force(force: np.ndarray, coupling_stiffness: float, preset: HapticPreset) -> np.ndarray:
    """Force ``(..., 3)`` (N) on the hand, as the preset device would render it.

    Scaled by ``min(1, max_stiffness / coupling_stiffness)`` (the coupling's spring and damper alike),
    then saturated at ``max_force`` with its direction kept.
    """
    f = np.asarray(force, dtype=np.float64)
    return np.stack(render_components(f[..., 0], f[..., 1], f[..., 2], coupling_stiffness, preset, ArrayOps), axis=-1)


def render_components(fx: Any, fy: Any, fz: Any, coupling_stiffness: float, preset: HapticPreset,
                      ops: PhysicsOps = ScalarOps) -> tuple[Any, Any, Any]:
    """:func:`render_force` on components: Python floats (``ScalarOps``) or arrays (``ArrayOps``)."""
    scale = min(1.0, preset.max_stiffness / coupling_stiffness)
    fx, fy, fz = fx * scale, fy * scale, fz * scale
    norm = ops.sqrt(fx * fx + fy * fy + fz * fz)
    factor = ops.clip(preset.max_force / ops.where(norm > 1e-300, norm, 1e-300), 0.0, 1.0)
    return fx * factor, fy * factor, fz * factor
