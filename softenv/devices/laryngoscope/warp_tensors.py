"""``n`` laryngoscopes on torch tensors stepped by the Warp kernel (:func:`.warp_kernel.control_period`):
the torch twin's engine on CPU tensors, and on CUDA tensors where it is asked for by name. Warp reads and
writes the tensors in place (``warp.from_torch`` shares their memory). :func:`differentiable_rollout`
bridges Warp's adjoint to torch autograd."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
import warp as wp

from ..contact import TongueContact
from .params import LaryngoscopeParams
from .tensors import LaryngoscopeTensors
from .warp_arrays import kernel_constants, scene_defaults
from .warp_kernel import Device, close_period, control_period, f64, one_substep, open_period


class LaryngoscopeWarpTensors(LaryngoscopeTensors):
    """:class:`~.tensors.LaryngoscopeTensors`' state and readings, each control period one launch of the
    Warp kernel on the tensors' device: on CPU every device equals a single pymunk device bit for bit.
    ``taped``: each control period runs through :func:`differentiable_rollout` instead (the same substeps,
    with their adjoint), its state held as the tensors autograd returns."""

    has_adjoint = True

    def __init__(self, params: LaryngoscopeParams, contact: TongueContact, n: int,
                 torch_device: torch.device | str = "cpu") -> None:
        super().__init__(params, contact, n, torch_device)
        self._warp_device = wp.device_from_torch(self.torch_device)
        self._constants = kernel_constants(self, self._warp_device)
        self.scene_params = self._array(scene_defaults(params, n))     # (n, 6): scene_row's; a taped step may track it

    def use_depth_derivative(self, loads: Any, slopes: Any) -> None:
        """The tongue's load table's derivative in the stiffening depth's factor (:func:`~..contact.depth_derivative`),
        along which a factor other than 1 in the scene parameters moves the table; until this call it is 0."""
        self._constants[3:5] = [wp.array(np.asarray(x, dtype=np.float64), dtype=f64, device=self._warp_device)
                                for x in (loads, slopes)]

    def control_step(self, actions: Any, moving: Any = None) -> None:
        """Advance one control period; ``actions`` ``(n, 4)`` in [-1, 1]; rows outside ``moving`` hold
        their hands still (their results are discarded by the caller)."""
        if moving is not None:
            actions = torch.where(moving[:, None], actions, 0.0)
        if self.taped:
            period = differentiable_rollout(self, self._blade, self._hand, self._lateral, actions[None],
                                            self.scene_params)
            for field, name in HELD_AS.items():
                setattr(self, name, period[field][0])
            self._forget()
            return
        arrays = [wp.from_torch(x, dtype=f64) for x in (self._blade, self._hand, self._lateral, self._hand_v,
                                                         self._contact, self._incisor,
                                                         actions.to(torch.float64).contiguous(),
                                                         self.scene_params.detach().contiguous())]
        stream = wp.stream_from_torch(self.torch_device) if self.torch_device.type == "cuda" else None
        wp.launch(control_period, self.n, inputs=[*arrays, self.n_substeps, *self._constants],
                  device=self._warp_device, stream=stream)
        self._forget()


# what a differentiable rollout returns for each period, and each row's width
ROLLOUT_FIELDS = {"blade": 6, "hand": 3, "lateral": 4, "hand_velocity": 4, "contact": 4, "incisor": 0}
# the state tensor each field is held as (LaryngoscopeTensors._STATE)
HELD_AS = {"blade": "_blade", "hand": "_hand", "lateral": "_lateral", "hand_velocity": "_hand_v", "contact": "_contact",
           "incisor": "_incisor"}


class _Rollout(torch.autograd.Function):
    """The Warp kernel's periods as one torch autograd node: forward records each substep's launch on a
    :class:`warp.Tape` (:func:`~.warp_kernel.one_substep`, every intermediate state kept); backward runs
    Warp's adjoint back through them."""

    @staticmethod
    def forward(ctx: Any, engine: LaryngoscopeWarpTensors, blade: torch.Tensor, hand: torch.Tensor,
                lateral: torch.Tensor, actions: torch.Tensor, scene: torch.Tensor) -> tuple[torch.Tensor, ...]:
        device, n, count = engine._warp_device, engine.n, engine.n_substeps

        def held(x: torch.Tensor) -> Any:
            return wp.from_torch(x.detach().to(torch.float64).contiguous().clone(), dtype=f64, requires_grad=True)

        def fresh(width: int) -> Any:
            return wp.zeros((n, width) if width else n, dtype=f64, device=device, requires_grad=True)

        inputs = [held(blade), held(hand), held(lateral)]
        orders = [held(a) for a in actions]
        tune = held(scene)
        state = inputs
        outputs: list[list[Any]] = []
        tape = wp.Tape()
        with tape:
            for order in orders:
                d = wp.zeros(n, dtype=Device, device=device, requires_grad=True)
                command = wp.zeros(n, dtype=wp.vec4d, device=device, requires_grad=True)
                wp.launch(open_period, n, inputs=[*state, order, engine._constants[0], d, command], device=device)
                for _ in range(count):
                    after = wp.zeros(n, dtype=Device, device=device, requires_grad=True)
                    wp.launch(one_substep, n, inputs=[d, command, tune, *engine._constants, after], device=device)
                    d = after
                period = [fresh(width) for width in ROLLOUT_FIELDS.values()]
                wp.launch(close_period, n, inputs=[d, count, engine._constants[0], *period], device=device)
                outputs.append(period)
                state = period[:3]
        ctx.tape, ctx.inputs, ctx.orders, ctx.tune, ctx.outputs = tape, inputs, orders, tune, outputs
        return tuple(torch.stack([wp.to_torch(period[k]) for period in outputs]) for k in range(len(ROLLOUT_FIELDS)))

    @staticmethod
    def backward(ctx: Any, *grads: torch.Tensor) -> tuple[Any, ...]:
        seeds = {period[k]: wp.from_torch(g[t].contiguous(), dtype=f64)
                 for t, period in enumerate(ctx.outputs) for k, g in enumerate(grads) if g is not None}
        ctx.tape.backward(grads=seeds)
        blade, hand, lateral = (wp.to_torch(x.grad).clone() for x in ctx.inputs)
        actions = torch.stack([wp.to_torch(x.grad).clone() for x in ctx.orders])
        scene = wp.to_torch(ctx.tune.grad).clone()
        ctx.tape.zero()
        return None, blade, hand, lateral, actions, scene


def differentiable_rollout(engine: LaryngoscopeWarpTensors, blade: torch.Tensor, hand: torch.Tensor,
                           lateral: torch.Tensor, actions: torch.Tensor,
                           scene: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
    """Control periods of the Warp kernel from the state ``blade`` ``(n, 6)``, ``hand`` ``(n, 3)`` and
    ``lateral`` ``(n, 4)`` (as :class:`~.state.DeviceState` holds them), with ``actions`` ``(T, n, 4)``
    (normalised, as :meth:`control_step` takes them), as torch autograd sees it: each period's state
    ``(T, n, ...)`` by :data:`ROLLOUT_FIELDS` name, whose gradients reach the start state and the actions
    through Warp's adjoint of every substep, and to ``scene`` ``(n, 6)`` (the scene parameters of
    :func:`~.warp_kernel.scene_row`; None: the engine's). It leaves
    ``engine``'s own state as it was. Through the incisors' contact and the clamps (workspace, friction
    cone, the tongue's load table) the gradient is that of the branch each substep took."""
    out = _Rollout.apply(engine, blade, hand, lateral, actions, engine.scene_params if scene is None else scene)
    return dict(zip(ROLLOUT_FIELDS, out))
