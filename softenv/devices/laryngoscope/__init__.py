"""The simulated laryngoscope: a rigid blade in pymunk, dragged by a hand through a virtual coupling,
pressing the tongue and levering on the upper incisors.

A package split by job; only the modules marked pymunk import it, and each engine's module its compiler:

* :mod:`.params` -- every number of the device and the substep it needs (numpy).
* :mod:`.physics` -- the arithmetic the pymunk devices share, written once against ``ops`` (floats or arrays).
* :mod:`.state` -- engine-neutral: the state, its readings, the coupling's and the contact's constants.
* :mod:`.space` -- the pymunk space of ``n`` devices (pymunk).
* :mod:`.single` -- one device on Python floats: the single env and the 1 kHz haptic loop (pymunk).
* :mod:`.batch` -- ``n`` devices in one pymunk space (pymunk).
* :mod:`.warp_kernel` -- ``n`` devices, each control period one Warp kernel (warp): the batch's engine, CPU
  or CUDA, and the gradients'; :mod:`.warp_tensors` runs it on the torch twin's tensors (torch).
* :mod:`.tensors` -- the state on torch tensors; :mod:`.fused` -- each control period one Triton kernel on
  CUDA tensors (triton).
* :mod:`.clinical` -- the clinical metrics of an episode; :mod:`.control` -- the hand controller that
  realises a force (the scripted expert's skill): numpy only, for readers without pymunk.
* :mod:`.part` -- the env-facing parts (the device contract of :mod:`softenv.devices.base`): workspace
  clip, the incisor reward term, info keys, the clinical record (pymunk); :mod:`.part_batch` the
  batch's, on the engine ``device.batch_engine`` names; :mod:`.part_tensors` the torch twin's (torch).

This module holds the kind, the batch engines' names (:data:`LARYNGOSCOPE`) and the observation's names and scales, so readers
of the observation (:mod:`softenv.devices.laryngoscope.control`, the baselines) load without pymunk.
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
# the batch's engines (device.batch_engine), each named for what runs: "auto" picks triton for torch
# tensors on CUDA (where triton is installed) and warp everywhere else
BATCH_ENGINES = ("auto", "warp", "triton", "pymunk")
EXACT_ENGINES = ("auto", "warp")          # equal to the single device bit for bit (on CPU)
# engines of earlier versions, refused with what replaced them
RETIRED_ENGINES = {
    "compiled": "the numba kernel, replaced by 'warp' (the same arithmetic, bit for bit; 'triton' on CUDA)",
    "numpy": "the array engine on numpy and torch operations, replaced by 'warp' (bit for bit on CPU)",
}


def _single(scene: DeviceScene, config: Config) -> Any:
    from .part import LaryngoscopePart           # pymunk: only for scenes with the laryngoscope

    return LaryngoscopePart(scene, config)


def _batch(scene: DeviceScene, config: Config, n: int) -> Any:
    from .part_batch import LaryngoscopePartBatch    # pymunk: only for batches of laryngoscopes

    return LaryngoscopePartBatch(scene, config, n)


def _tensors(scene: DeviceScene, config: Config, n: int, torch_device: Any, dtype: Any) -> Any:
    from .part_tensors import LaryngoscopeTensorPart      # pymunk and torch: only for the torch twin's laryngoscopes

    return LaryngoscopeTensorPart(scene, config, n, torch_device, dtype)


LARYNGOSCOPE = DeviceKind("laryngoscope", LARYNGOSCOPE_OBS, _single, _batch, _tensors)
