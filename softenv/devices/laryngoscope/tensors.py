"""``n`` laryngoscopes' state on torch tensors, CPU or GPU, for the torch twin's engines (the Warp kernel's,
:mod:`.warp_tensors`; the Triton kernel's, :mod:`.fused`; the part the twin composes is
:mod:`.part_tensors`). The physics stays float64 whatever the env's dtype (the contact's stiffness spans
five decades); the env reads its features and forces in its own dtype. A step never reads back to the
host, and leaves its state where the last one did (one address a tensor), so the torch twin can record
the step as a CUDA graph (``cuda_graph=True``) that reads and writes the live state.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from ..._torch_ops import TorchOps
from ..contact import TongueContact
from .params import LaryngoscopeParams
from .state import DeviceState, KernelLaryngoscopes


class LaryngoscopeTensors(KernelLaryngoscopes):
    """``n`` laryngoscopes' state on float64 tensors of ``torch_device`` and its readings; an engine
    supplies :meth:`substeps`, which writes the state in place. Its :meth:`state` is on the host (numpy),
    as the other engines'."""

    ops = TorchOps
    xp = TorchOps.xp
    _own: Any = staticmethod(torch.clone)

    _STATE = ("_blade", "_hand", "_lateral", "_contact", "_incisor", "_hand_v")     # what a step reads from the last
    has_adjoint = False         # an engine whose control step torch autograd can follow (Warp's) sets it
    taped = False               # set by the torch twin's differentiable=True: control steps carry the graph
    scene_params: torch.Tensor  # (n, 6) params.SCENE_COLUMNS of an engine whose kernel reads them (Warp's)

    def __init__(self, params: LaryngoscopeParams, contact: TongueContact, n: int,
                 torch_device: torch.device | str = "cpu") -> None:
        self.torch_device = torch.device(torch_device)
        super().__init__(params, contact, n)

    def use_depth_derivative(self, loads: Any, slopes: Any) -> None:
        """The load table's derivative in the stiffening depth's factor, for an engine whose kernel reads the
        scene parameters (Warp's, which overrides this); the others cannot move their table."""
        raise ValueError(f"{type(self).__name__} does not read scene parameters; the stiffening depth's gradient "
                         "needs Warp's engine (differentiable=True runs it)")

    def _array(self, value: Any) -> torch.Tensor:
        if isinstance(value, torch.Tensor):
            return value.to(self.torch_device)
        return torch.as_tensor(np.asarray(value), device=self.torch_device)

    def state(self) -> DeviceState:
        bodies = self._bodies()
        host = [x.cpu().numpy() for x in (bodies[:, 1], bodies[:, 0, :3], self._lateral,
                                          torch.cat([self._contact, self._incisor[:, None]], dim=1), self._hand_v)]
        return DeviceState(*host)

    def load_state(self, s: DeviceState, rows: Any = None) -> None:
        """Set the masked devices (all by default) from the matching rows of ``s`` (``n`` rows, numpy or
        tensors): a masked write into the state's own tensors, with no read of the mask on the host."""
        if len(s.blade) != self.n:
            raise ValueError(f"state has {len(s.blade)} devices; this batch has n={self.n}")
        mask = torch.ones(self.n, dtype=torch.bool, device=self.torch_device) if rows is None else rows
        m, t = mask[:, None], self._array
        contact = t(s.contact)
        for name, value, where in [("_blade", t(s.blade), m), ("_hand", t(s.hand), m), ("_lateral", t(s.lateral), m),
                                   ("_contact", contact[:, :4], m), ("_incisor", contact[:, 4], mask),
                                   ("_hand_v", t(s.hand_velocity), m)]:
            held = getattr(self, name)
            if held.requires_grad:          # a taped state: out of place, as an earlier step may have saved it
                setattr(self, name, torch.where(where, value, held))
            else:
                held.copy_(torch.where(where, value, held))
        self._forget()

    def detach(self) -> None:
        """Cut autograd's graph at the current state (a taped engine's)."""
        for name in self._STATE:
            setattr(self, name, getattr(self, name).detach())
        self._forget()

    def track_state(self) -> dict[str, torch.Tensor]:
        """Hold the state as new leaves of autograd's graph and return them by name (blade, hand, lateral,
        contact, incisor, hand_v): a taped engine's later readings then have gradients to them."""
        if not self.taped:
            raise ValueError("track_state() needs the torch twin's differentiable=True: the plain engine writes its "
                             "state in place, where autograd cannot follow it")
        for name in self._STATE:
            setattr(self, name, getattr(self, name).detach().clone().requires_grad_(True))
        self._forget()
        return {name.lstrip("_"): getattr(self, name) for name in self._STATE}
