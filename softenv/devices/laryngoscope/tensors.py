"""``n`` laryngoscopes on torch tensors, CPU or GPU, for the torch twin (:class:`LaryngoscopeTensors`;
the part the twin composes is :mod:`.part_tensors`).

The numpy array engine (:class:`~.batch.LaryngoscopeArrays`: :mod:`.rigid`, :mod:`.incisors`,
:mod:`.physics`) is written against an ``ops`` class and an array namespace; here they are
:class:`~softenv._torch_ops.TorchOps` and torch through ``array_api_compat``, so the same code steps
tensors. The physics stays float64 whatever the env's dtype (the contact's stiffness spans five
decades); the env reads its features and forces in its own dtype. It agrees with the numpy engine, and
so with the pymunk device, to rounding, not bit for bit: torch's ``cos``, ``sin`` and ``exp`` are its
own (``tests/test_torch_laryngoscope.py`` states the bound). A step never reads back to the host, and
leaves its state where the last one did (one address a tensor), so the torch twin can record the step as
a CUDA graph (``cuda_graph=True``) that reads and writes the live state.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from ..._torch_ops import TorchOps
from ..contact import TongueContact
from .batch import LaryngoscopeArrays
from .params import LaryngoscopeParams
from .space import DeviceState


class LaryngoscopeTensors(LaryngoscopeArrays):
    """``n`` laryngoscopes on float64 tensors of ``torch_device``: :class:`~.batch.LaryngoscopeArrays`
    with torch's operations. Its :meth:`state` is on the host (numpy), as the other engines'."""

    ops = TorchOps
    xp = TorchOps.xp
    _own: Any = staticmethod(torch.clone)

    # what a step reads from the last one (the per-substep solver fields are made again each substep)
    _STATE = ("_blade", "_hand", "_lateral", "_contact", "_incisor", "_touched", "_hand_v")
    _ARBITER_STATE = ("alive", "ticks", "exists", "features", "jn", "jt", "normal")

    def __init__(self, params: LaryngoscopeParams, contact: TongueContact, n: int,
                 torch_device: torch.device | str = "cpu") -> None:
        self.torch_device = torch.device(torch_device)
        self._homes: dict[tuple[str, str], torch.Tensor] = {}
        super().__init__(params, contact, n)

    def control_step(self, actions: Any, moving: Any = None) -> None:
        super().control_step(actions, moving)
        self._keep_in_place()

    def _keep_in_place(self) -> None:
        """Copy the state the engine's code left in new tensors into the tensors that held it (one home
        for each, made at the first call), and point at those: the next step reads where this one wrote."""
        arbiters = self._teeth.arbiters
        for holder, name in [(self, name) for name in self._STATE] + [(arbiters, name) for name in self._ARBITER_STATE]:
            setattr(holder, name, self._home((type(holder).__name__, name), getattr(holder, name)))
        self._teeth.bias = [self._home(("bias", str(i)), b) for i, b in enumerate(self._teeth.bias)]

    def _home(self, key: tuple[str, str], value: torch.Tensor) -> torch.Tensor:
        """``value`` copied into the tensor kept for ``key`` (a clone of the first value: no two share one)."""
        home = self._homes.get(key)
        if home is None:
            home = self._homes[key] = value.clone()
        elif home is not value:
            home.copy_(value)
        return home

    def _array(self, value: Any) -> torch.Tensor:
        if isinstance(value, torch.Tensor):
            return value.to(self.torch_device)
        return torch.as_tensor(np.asarray(value), device=self.torch_device)

    def compile_substep(self, options: dict[str, Any]) -> None:
        """Compile the substep (``fullgraph``, static shapes), not the step: a step's 20 substeps unrolled
        would be one graph of some 14,000 operations. Refused where inductor's code is known wrong
        (:func:`check_compile`)."""
        check_compile(options, self.torch_device)
        self._substep = torch.compile(self._substep, fullgraph=True, dynamic=False, **options)  # type: ignore[method-assign]

    def state(self) -> DeviceState:
        bodies = self._bodies()
        host = [x.cpu().numpy() for x in (bodies[:, 1], bodies[:, 0, :3], self._lateral,
                                          torch.cat([self._contact, self._incisor[:, None]], dim=1), self._hand_v)]
        return DeviceState(*host)

    def load_state(self, s: DeviceState, rows: Any = None) -> None:
        """Set the masked devices (all by default) from the matching rows of ``s`` (``n`` rows, numpy or
        tensors): a masked write, with no read of the mask on the host."""
        if len(s.blade) != self.n:
            raise ValueError(f"state has {len(s.blade)} devices; this batch has n={self.n}")
        mask = torch.ones(self.n, dtype=torch.bool, device=self.torch_device) if rows is None else rows
        m, t = mask[:, None], self._array
        self._blade = torch.where(m, t(s.blade), self._blade)
        self._hand = torch.where(m, t(s.hand), self._hand)
        self._lateral = torch.where(m, t(s.lateral), self._lateral)
        contact = t(s.contact)
        self._contact = torch.where(m, contact[:, :4], self._contact)
        self._incisor = torch.where(mask, contact[:, 4], self._incisor)
        self._hand_v = torch.where(m, t(s.hand_velocity), self._hand_v)
        self._touched = torch.where(mask, False, self._touched)
        self._flush(mask)
        self._forget()
        self._keep_in_place()


def check_compile(options: dict[str, Any], torch_device: torch.device) -> None:
    """Refuse ``compile_options`` that compile the substep with inductor for a CUDA device: there its
    code disagrees with the eager substep it compiles (the blade's pose and speed by up to 0.4 of the
    observation's range after one step, on an H200 with torch 2.11), while dynamo alone (``backend="eager"``)
    and ``aot_eager`` agree, and inductor's CPU code agrees to 1e-13 (docs/laryngoscope.md)."""
    backend = options.get("backend", "inductor")
    if torch_device.type == "cuda" and backend == "inductor":
        raise ValueError(f"compile_options={options!r} with torch_device={str(torch_device)!r}: inductor's CUDA "
                         "code for the laryngoscope's substep disagrees with its eager step (docs/laryngoscope.md); "
                         "allowed there: compile_options=None, with cuda_graph=True to record the eager step, or a "
                         "backend other than 'inductor'")
