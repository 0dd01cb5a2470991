"""The torch twin's parts: elementwise ops on tensors, and where its episodes come from.

An episode is a target force (four features); the step scores the agent against that target's
shape and against the score's two anchors (the zero-force and the oracle error sums). Two sources:

* :class:`HostEpisodes` (``target_draw="host"``): the per-env numpy generators draw the targets, and
  :meth:`~softenv.envs.world.World.start_episodes` precomputes every episode on the host, exactly as
  the numpy twin does, so both twins play the same episodes. Starting episodes mid-run reads which
  envs ended: one host synchronisation on each step where an episode can end.
* :class:`DeviceEpisodes` (``target_draw="device"``): the targets are drawn on the device from a
  counter-based generator (splitmix64 of the env's seed and episode number: the same numbers on any
  device and for any ``num_envs``), and the references are computed step by step alongside the
  agent (the target's shape by the response table, the anchors as running sums, the oracle's creep
  as a second state). Nothing is read back to the host and every shape is static, so a step can be
  captured whole by ``torch.compile(fullgraph=True)``.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
import torch

from .._torch_ops import TorchOps
from .batching import seeded_episodes
from .checks import check_seeds, target_option
from .task import procedure_features
from .world import World

Lookup = Callable[[torch.Tensor], torch.Tensor]


# -- splitmix64 on int64 tensors (two's-complement wrap-around, as torch's integer ops do) ----------

_GOLDEN = 0x9E3779B97F4A7C15
_MIX1, _MIX2 = 0xBF58476D1CE4E5B9, 0x94D049BB133111EB
DRAWS_PER_EPISODE = 8          # counter slots reserved per episode (5 used: the cell and 4 coordinates)


def as_int64(value: int) -> int:
    """A Python int modulo 2^64, as the int64 with the same bits."""
    value &= (1 << 64) - 1
    return value - (1 << 64) if value >= 1 << 63 else value


def _shift_right(x: torch.Tensor, s: int) -> torch.Tensor:
    return (x >> s) & ((1 << (64 - s)) - 1)        # logical shift (torch's >> on int64 keeps the sign)


def splitmix64(seed: torch.Tensor, counter: torch.Tensor) -> torch.Tensor:
    """Output number ``counter`` (>= 1) of the splitmix64 generator started at ``seed`` (int64 tensors,
    broadcast): ``mix(seed + counter * golden)``, Steele, Lea and Flood's SplitMix finaliser."""
    z = seed + counter * as_int64(_GOLDEN)
    z = (z ^ _shift_right(z, 30)) * as_int64(_MIX1)
    z = (z ^ _shift_right(z, 27)) * as_int64(_MIX2)
    return z ^ _shift_right(z, 31)


def episode_uniforms(seed: torch.Tensor, episode: torch.Tensor, count: int) -> torch.Tensor:
    """``count`` uniforms in [0, 1) (float64, 53 random bits) for each env's episode: ``(N, count)``."""
    slots = torch.arange(1, count + 1, device=seed.device)
    z = splitmix64(seed[:, None], episode[:, None] * DRAWS_PER_EPISODE + slots)
    return _shift_right(z, 11).to(torch.float64) * 2.0 ** -53


# -- episode sources --------------------------------------------------------------------------------


class HostEpisodes:
    """Episodes from the per-env numpy generators, precomputed on the host (the numpy twin's)."""

    def __init__(self, world: World, num_envs: int, tensor: Callable[..., torch.Tensor]) -> None:
        self.world, self.tensor = world, tensor
        self.rngs = [np.random.default_rng() for _ in range(num_envs)]
        self.arrays: dict[str, torch.Tensor] = {}
        self.rows = torch.arange(num_envs, device=tensor(0.0).device)

    def reset(self, seed: Any, options: dict[str, Any] | None, mask: np.ndarray | None = None) -> None:
        """Every env's next episode, or the ``mask``ed envs' (``reset(options={"reset_mask": ...})``)."""
        self.rngs, episodes = seeded_episodes(self.world, self.rngs, seed, options, mask)
        if mask is None:
            self.arrays = {name: self.tensor(getattr(episodes, name), sum_dtype(name, None))
                           for name in ("target_b", "sq_ref", "zero_cum", "oracle_cum")}
        else:
            self._write(np.flatnonzero(mask).tolist(), episodes)

    def references(self, t: torch.Tensor, stepped: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """This step's target shape, its reference (squared), and the zero and oracle error sums so far."""
        ep, T = self.arrays, self.arrays["sq_ref"].shape[1]
        ti, hi = torch.clamp(t, max=T - 1), torch.clamp(t, max=self.world.horizon - 1)
        return (ep["target_b"][self.rows, ti], ep["sq_ref"][self.rows, ti],
                ep["zero_cum"][self.rows, hi], ep["oracle_cum"][self.rows, hi])

    def upcoming(self, t: torch.Tensor) -> torch.Tensor:
        """The target shape observed before step ``t``."""
        T = self.arrays["sq_ref"].shape[1]
        return self.arrays["target_b"][self.rows, torch.clamp(t, max=T - 1)]

    def first(self) -> torch.Tensor:
        return self.arrays["target_b"][:, 0]

    def restart(self, mask: torch.Tensor) -> bool:
        """Draw new episodes for the masked envs; False when none ended (a host read of the mask)."""
        idx = mask.nonzero()[:, 0].tolist()
        if not idx:
            return False
        self._write(idx, self.world.start_episodes([self.rngs[i] for i in idx]))
        return True

    def _write(self, idx: list[int], new: Any) -> None:
        rows = torch.as_tensor(idx, device=self.rows.device)
        for name, value in self.arrays.items():
            value[rows] = self.tensor(getattr(new, name), value.dtype)


class DeviceEpisodes:
    """Episodes drawn and scored on the device (see the module docstring).

    The target is drawn as :meth:`~softenv.envs.task.TargetFamily.sample_many` draws it (a cell of the
    split, then a point in it), from uniforms of :func:`episode_uniforms`. ``reset(seed=s)`` seeds env
    ``i`` with ``s + i`` and restarts its episode count; ``reset()`` goes on to each env's next episode.
    """

    def __init__(self, world: World, num_envs: int, tensor: Callable[..., torch.Tensor], lookup: Lookup) -> None:
        self.world, self.tensor, self.lookup = world, tensor, lookup
        n, k = num_envs, world.k
        device = tensor(0.0).device
        family = world.family
        self.cells = torch.as_tensor(family.cells, dtype=torch.float64, device=device)
        self.n_cells = family.n_cells
        self.low, self.span = tensor(family.low, torch.float64), tensor(family.high - family.low, torch.float64)
        self.b_rest = tensor(world.b_rest)
        self.seed = torch.zeros(n, dtype=torch.int64, device=device)
        self.episode = torch.zeros(n, dtype=torch.int64, device=device)
        self.features = tensor(np.zeros((n, 4)))
        self.target = tensor(np.zeros((n, k)))              # the target shape of each env's coming step
        self.zero_cum, self.oracle_cum = tensor(np.zeros(n), torch.float64), tensor(np.zeros(n), torch.float64)
        self.creep = tensor(np.zeros((n, k)))                 # the oracle's creep state (viscoelastic tissue)
        self.seeded = False

    # -- episode starts -----------------------------------------------------------------------------

    def reset(self, seed: Any, options: dict[str, Any] | None, mask: np.ndarray | None = None) -> None:
        """Every env's next episode, or the ``mask``ed envs' (``reset(options={"reset_mask": ...})``)."""
        n = len(self.seed)
        target = target_option(self.world, options)            # everything is checked before the state changes
        seeds: list[Any] = check_seeds(seed, n)
        if not self.seeded:                    # an env never seeded starts from fresh entropy
            entropy = np.random.SeedSequence().entropy
            assert isinstance(entropy, int)              # fresh entropy is one int
            base = entropy % (1 << 63)
            seeds = [base + i if s is None else s for i, s in enumerate(seeds)]
        device = self.seed.device
        chosen = torch.ones(n, dtype=torch.bool, device=device) if mask is None else torch.as_tensor(mask, device=device)
        fresh = torch.tensor([s is not None for s in seeds], device=device) & chosen
        given = torch.tensor([as_int64(s) if s is not None else 0 for s in seeds], device=device)
        self.seed = keep(fresh, given, self.seed)
        torch.where(fresh, torch.zeros_like(self.episode), self.episode + chosen.to(torch.int64), out=self.episode)
        self.seeded = True
        features = self.draw() if target is None else self.tensor(np.broadcast_to(target, (n, 4)))
        self.features = keep(chosen[:, None], features.to(self.features.dtype), self.features)
        self._begin(chosen)

    def draw(self) -> torch.Tensor:
        """Each env's target for its current episode number, ``(N, 4)`` float64."""
        u = episode_uniforms(self.seed, self.episode, 5)
        n_split = len(self.cells)
        cell = self.cells[torch.clamp((u[:, 0] * n_split).to(torch.int64), max=n_split - 1)]
        return self.low + (cell + u[:, 1:]) / self.n_cells * self.span

    def restart(self, mask: torch.Tensor) -> bool:
        """Start the masked envs' next episodes (for every env at once: no host read)."""
        self.episode += mask.to(torch.int64)
        self.features = keep(mask[:, None], self.draw().to(self.features.dtype), self.features)
        self._begin(mask)
        return True

    def _begin(self, mask: torch.Tensor) -> None:
        step0 = torch.zeros(len(mask), dtype=torch.int64, device=mask.device)
        self.target = keep(mask[:, None], self.lookup(self._schedule(step0)), self.target)
        zero = torch.zeros_like(self.zero_cum)
        self.zero_cum = keep(mask, zero, self.zero_cum)
        self.oracle_cum = keep(mask, zero, self.oracle_cum)
        self.creep = keep(mask[:, None], self.b_rest, self.creep)

    def _schedule(self, step: torch.Tensor) -> torch.Tensor:
        if self.world.task_kind == "reach":
            return self.features
        t = (step.to(self.features.dtype) + 1) / self.world.horizon
        return procedure_features(self.features, t, self.world.start_insertion, TorchOps)

    # -- the step -------------------------------------------------------------------------------

    def references(self, t: torch.Tensor, stepped: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """As :meth:`HostEpisodes.references`; the error sums of the stepped envs advance by this step."""
        w = self.world
        target = self.target.clone()           # upcoming() overwrites self.target later in the step
        r = target - self.b_rest
        rr = torch.sum(r * r, dim=-1)
        sq_ref = torch.clamp(rr, min=w.floor_sq)
        zero_cum = self.zero_cum + torch.sqrt(rr / sq_ref).to(torch.float64)
        oracle_cum = self.oracle_cum
        dyn = w.dynamics
        if dyn.stateful:                    # the oracle holds the target force from the start: it creeps too
            creep = self.creep.clone()                      # step advances it in place
            d = dyn.step(creep, target) - target
            oracle_cum = oracle_cum + torch.sqrt(torch.sum(d * d, dim=-1) / sq_ref).to(torch.float64)
            self.creep = keep(stepped[:, None], creep, self.creep)
        self.zero_cum = keep(stepped, zero_cum, self.zero_cum)
        self.oracle_cum = keep(stepped, oracle_cum, self.oracle_cum)
        return target, sq_ref, zero_cum, oracle_cum

    def upcoming(self, t: torch.Tensor) -> torch.Tensor:
        if self.world.task_kind != "reach":     # the procedure's target moves: look up the next step's
            self.target.copy_(self.lookup(self._schedule(torch.clamp(t, max=self.world.horizon - 1))))
        return self.target

    def first(self) -> torch.Tensor:
        return self.target               # right after _begin, the masked rows hold their first target


def keep(mask: torch.Tensor, new: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
    """``where(mask, new, state)``, returned for the caller to hold as the state (``x = keep(m, new, x)``).
    Without gradients it is written into ``state``'s own storage and ``state`` returned: the env's state
    tensors never move, so a captured CUDA graph, which replays fixed addresses, reads and writes the live
    state. Where either carries autograd's graph (``differentiable=True``) it is a new tensor: an in-place
    write would change a tensor an earlier step saved for its backward."""
    if new.requires_grad or state.requires_grad:
        return torch.where(mask, new, state)
    return torch.where(mask, new, state, out=state)


def sum_dtype(name: str, dtype: torch.dtype | None) -> torch.dtype | None:
    # the score's running sums stay float64 in either dtype: a float32 sum over an episode drifts by 1e-5
    return torch.float64 if name in ("zero_cum", "oracle_cum", "agent_cum") else dtype
