"""The simulated laryngoscope: a rigid blade in pymunk, dragged by a hand through a virtual coupling,
pressing the tongue and levering on the upper incisors.

A package split by job; only the modules marked pymunk import it:

* :mod:`.params` -- every number of the device and the substep it needs (numpy).
* :mod:`.physics` -- the arithmetic single and batch share, written once against ``ops`` (floats or arrays).
* :mod:`.space` -- the pymunk space of ``n`` devices, their state, and the readings both share (pymunk).
* :mod:`.single` -- one device on Python floats: the single env and the 1 kHz haptic loop (pymunk).
* :mod:`.rigid`, :mod:`.incisors` -- the blade, its coupling and the incisors as Chipmunk steps them, on arrays.
* :mod:`.batch` -- ``n`` devices on arrays: with ``pymunk.batch`` or with :mod:`.rigid` (pymunk).
* :mod:`.kernel` -- ``n`` devices in one compiled loop (numba): the batch's default engine.
* :mod:`.tensors` -- ``n`` devices on torch tensors (the numpy array engine's code, torch's operations).
* :mod:`.fused` -- ``n`` devices on CUDA tensors, each control period one Triton kernel (triton).
* :mod:`.part` -- the env-facing parts (the device contract of :mod:`softenv.devices.base`): workspace
  clip, the incisor reward term, info keys, the clinical record (pymunk); :mod:`.part_batch` the
  batch's, on the engine ``device.batch_engine`` names (pymunk, numba); :mod:`.part_tensors` the torch
  twin's (torch).

This module holds the kind, the batch engines' names (:data:`LARYNGOSCOPE`) and the observation's names and scales, so readers
of the observation (:mod:`softenv.control`, the baselines) load without pymunk.
"""

from __future__ import annotations

from typing import Any

from ..base import Config, DeviceKind, DeviceScene

# names of the laryngoscope's part of the observation (each value squashed into (-1, 1))
LARYNGOSCOPE_OBS = ("blade_x", "blade_z", "blade_pitch", "blade_y", "blade_vx", "blade_vz", "blade_spin", "blade_vy",
                    "hand_x", "hand_z", "hand_pitch", "hand_y", "tongue_normal", "tongue_sideways", "incisor")
# scales of the observation (value / scale, then squashed)
POSITION_SCALE, ANGLE_SCALE, LATERAL_SCALE = 0.05, 0.5, 0.02             # m, rad, m
SPEED_SCALE, SPIN_SCALE, LATERAL_SPEED_SCALE = 0.2, 2.0, 0.1             # m/s, rad/s, m/s
# the batch's engines (device.batch_engine): compiled (numba) and numpy equal the single device bit for bit
BATCH_ENGINES = ("compiled", "numpy", "pymunk")
EXACT_ENGINES = ("compiled", "numpy")


def _single(scene: DeviceScene, config: Config) -> Any:
    from .part import LaryngoscopePart           # pymunk: only for scenes with the laryngoscope

    return LaryngoscopePart(scene, config)


def _batch(scene: DeviceScene, config: Config, n: int) -> Any:
    from .part_batch import LaryngoscopePartBatch    # pymunk and numba: only for batches of laryngoscopes

    return LaryngoscopePartBatch(scene, config, n)


def _tensors(scene: DeviceScene, config: Config, n: int, torch_device: Any, dtype: Any) -> Any:
    from .part_tensors import LaryngoscopeTensorPart      # pymunk and torch: only for the torch twin's laryngoscopes

    return LaryngoscopeTensorPart(scene, config, n, torch_device, dtype)


LARYNGOSCOPE = DeviceKind("laryngoscope", LARYNGOSCOPE_OBS, _single, _batch, _tensors)
