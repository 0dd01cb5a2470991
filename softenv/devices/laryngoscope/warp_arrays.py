"""``n`` laryngoscopes on numpy arrays stepped by the Warp kernel (:func:`.warp_kernel.control_period`) on
Warp's CPU device: the vector env's engine (``device.batch_engine="warp"``, the default), every device
equal to a single pymunk device bit for bit; and the kernel's constants as every launch passes them."""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from ..contact import TongueContact
from .params import FACTOR_COLUMNS, SCENE_COLUMNS, LaryngoscopeParams
from .physics import Constants
from .state import IncisorContact, KernelLaryngoscopes
from .warp_kernel import MAX_VERTICES, Params, control_period, f64


def params_of(c: Constants, s: IncisorContact) -> Params:
    """The kernel's constants from the substep's (:class:`~.physics.Constants`) and the contact's."""
    p = Params()
    for name in ("R", "h", "inv_m", "inv_I", "h_over_m", "k", "c", "k_t", "mu", "k_ref", "damping", "step",
                 "inv_step"):
        setattr(p, name, f64(getattr(c, name)))
    p.top = int(c.top)
    p.grip = wp.vec2d(*c.grip)
    p.heel = wp.vec2d(*c.heel)
    p.tip = wp.vec2d(*c.tip)
    p.low = wp.vec4d(*c.low)
    p.high = wp.vec4d(*c.high)
    p.end0 = wp.vec2d(*s.ends[0])
    p.end1 = wp.vec2d(*s.ends[1])
    p.seg_normal = wp.vec2d(*s.seg_normal)
    p.radius = f64(s.radius)
    p.friction = f64(s.friction)
    p.slop = f64(s.slop)
    p.bias_coef = f64(s.bias_coef)
    p.dt_coef = f64(s.dt_coef)
    if c.jaw is not None:
        p.jaw, p.jaw_present = wp.vec2d(*c.jaw), 1
    p.jaw_radius, p.k_jaw, p.c_jaw = f64(c.jaw_radius), f64(c.k_jaw), f64(c.c_jaw)
    if len(s.local) > MAX_VERTICES:
        raise ValueError(f"the blade's outline has {len(s.local)} vertices; the Warp kernel holds at most {MAX_VERTICES}")
    p.vertices = len(s.local)
    return p


def device_params(c: Constants, s: IncisorContact, params: LaryngoscopeParams) -> Params:
    """:func:`params_of` with the hand's speeds at full action (what turns an action into a command)."""
    p = params_of(c, s)
    p.max_hand_speed, p.max_pitch_rate = f64(params.max_hand_speed), f64(params.max_pitch_rate)
    p.max_sweep_speed = f64(params.max_sweep_speed)
    return p


def scene_defaults(params: LaryngoscopeParams, n: int) -> np.ndarray:
    """The scene parameters ``(n, 6)`` each device's launch reads (:func:`.warp_kernel.scene_row`,
    :data:`~.params.SCENE_COLUMNS`) as the scene sets them: the coupling's stiffness and damping, the
    tongue's stiffness factor 1, the wrist's rotary stiffness and damping, the depth factor 1."""
    row = [1.0 if name in FACTOR_COLUMNS else getattr(params, name) for name in SCENE_COLUMNS]
    return np.tile(row, (n, 1)).astype(np.float64)


def kernel_constants(dev: KernelLaryngoscopes, device: Any) -> list[Any]:
    """What every launch for the devices ``dev`` reads, on Warp's ``device``: the constants, the tongue's
    load table and its derivative in the stiffening depth's factor (0 until
    :meth:`~.warp_tensors.LaryngoscopeWarpTensors.use_depth_derivative` replaces it), and the blade's
    polygon (:func:`control_period`'s and :func:`one_substep`'s last arguments)."""
    s, contact = dev.incisors, dev.contact
    return [device_params(dev.c, s, dev.params),
            *(wp.array(np.asarray(x, dtype=np.float64), dtype=f64, device=device)
              for x in (contact.loads, contact.slopes, np.zeros_like(contact.loads), np.zeros_like(contact.slopes))),
            wp.array(s.local, dtype=wp.vec2d, device=device),
            wp.array(s.local_normals, dtype=wp.vec2d, device=device)]


class LaryngoscopeWarp(KernelLaryngoscopes):
    """``n`` laryngoscopes on numpy arrays, each control period one launch of :func:`control_period` on
    Warp's CPU device: every device equals a single pymunk device bit for bit. The state arrays are numpy
    views of Warp arrays, so a period's launch passes no data (a recorded launch, replayed)."""

    def __init__(self, params: LaryngoscopeParams, contact: TongueContact, n: int) -> None:
        super().__init__(params, contact, n)
        state: list[Any] = [wp.array(x, dtype=f64, device="cpu") for x in
                 (self._blade, self._hand, self._lateral, self._hand_v, self._contact, self._incisor)]
        self._blade, self._hand, self._lateral, self._hand_v, self._contact, self._incisor = (x.numpy() for x in state)
        actions = wp.zeros((n, 4), dtype=f64, device="cpu")
        self._actions = actions.numpy()
        scene: Any = wp.array(scene_defaults(params, n), dtype=f64, device="cpu")
        self._launch = wp.launch(control_period, n, device="cpu", record_cmd=True,
                                 inputs=[*state, actions, scene, self.n_substeps, *kernel_constants(self, "cpu")])

    def control_step(self, actions: Any, moving: Any = None) -> None:
        """Advance one control period; ``actions`` ``(n, 4)`` in [-1, 1]; rows outside ``moving`` hold
        their hands still (their results are discarded by the caller)."""
        self._actions[:] = actions
        if moving is not None:
            self._actions[~moving] = 0.0
        self._launch.launch()
        self._forget()
