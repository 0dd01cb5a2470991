"""The torch twin's step replayed as CUDA graphs that the env records itself (``cuda_graph=True``).

``torch.compile(mode="reduce-overhead")`` also replays CUDA graphs, but each call first runs dynamo's
guards and the CUDA-graph trees' checks (the address of every input, the liveness of every output) and
builds a tensor for each of its outputs: on the order of 100 us a call for a small graph
(pytorch/pytorch#150488), as long as a whole step at 1,024 envs should take. Here a step's host work
is one copy of the actions into the graph's input and one ``graph.replay()``; what the graph runs is
the env's tensor work, eager or compiled (``compile_options`` in a mode without CUDA graphs).
"""

from __future__ import annotations

from typing import Any, Callable

import torch

StepWork = Callable[[torch.Tensor, bool], tuple[Any, ...]]


class GraphedStep:
    """``work(actions, may_start)`` as one CUDA graph per value of the host's ``may_start`` flag.

    A graph is recorded at the first call with its flag. That call runs ``work`` once on a side stream,
    as ``torch.cuda.graph`` asks of a first run (lazy initialisation, compiled kernels' tuning); that run
    is the step itself, and recording launches nothing, so the state advances once. Later calls copy the
    actions into the graph's input and replay it. The env's state is written in place, so the graph reads
    and writes the live state; the outputs are the graph's own tensors, overwritten by its next replay
    (the containers around them are new each call, so a caller may edit its info dict).
    """

    def __init__(self, work: StepWork, actions: torch.Tensor) -> None:
        if actions.device.type != "cuda":
            raise ValueError(f"cuda_graph=True needs a CUDA device; got device={str(actions.device)!r}")
        self.work = work
        self.actions = torch.zeros_like(actions)            # the graphs' input: one address for every replay
        self.graphs: dict[bool, tuple[torch.cuda.CUDAGraph, tuple[Any, ...]]] = {}

    def __call__(self, actions: torch.Tensor, may_start: bool) -> tuple[Any, ...]:
        self.actions.copy_(actions)
        recorded = self.graphs.get(may_start)
        if recorded is None:
            return self._run_and_record(may_start)
        graph, outputs = recorded
        graph.replay()
        return _fresh_containers(outputs)

    def _run_and_record(self, may_start: bool) -> tuple[Any, ...]:
        with torch.cuda.device(self.actions.device):       # streams and capture on the env's GPU, not the current one
            side = torch.cuda.Stream()
            side.wait_stream(torch.cuda.current_stream())
            with torch.cuda.stream(side):
                result = self.work(self.actions, may_start)
            torch.cuda.current_stream().wait_stream(side)
            graph = torch.cuda.CUDAGraph()
            with torch.cuda.graph(graph):
                outputs = self.work(self.actions, may_start)
        self.graphs[may_start] = (graph, outputs)
        return result


def _fresh_containers(value: Any) -> Any:
    """``value`` with every tuple and dict copied (the tensors in them are not)."""
    if isinstance(value, dict):
        return {key: _fresh_containers(item) for key, item in value.items()}
    if isinstance(value, tuple):
        return tuple(_fresh_containers(item) for item in value)
    return value
