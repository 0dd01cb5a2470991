"""The batched SoftSphere twin in torch: the ideal-device and laryngoscope ids on CPU or GPU tensors.

``gym.make_vec("SoftSphere-v0", num_envs=N, vectorization_mode="vector_entry_point", backend="torch",
torch_device="cuda", dtype=torch.float32)`` makes a :class:`SoftSphereTorchVectorEnv`. It takes actions and
returns observations, rewards, flags and infos as tensors on ``torch_device``, with the numpy twin's rules
(:class:`~softenv.envs.vector.SoftSphereVectorEnv`): the same world (scene, response table,
targets, dynamics, reward weights), the same seeding (per-env numpy generators draw the targets at
reset, so both twins play the same episodes), the same autoreset modes. In float64 it equals the numpy
twin to rounding (the response's corner sum runs in another order: tested within 1e-12 over 1,000
steps); in float32 within 1e-5 of float64 (the score's running sums stay float64: tested). The
observation is float32 like the observation space.

What it expresses: the tabulated response (``response.model = "exact"``, analytic or FE tissue, any
law), quasi-static and viscoelastic dynamics, reach and procedure tasks, ``obs_mode`` vector and
dict, and any device kind with a tensor form (``DeviceKind.tensors``: the ideal device, and the
laryngoscope on float64 tensors: the Warp kernel on CPU, bit for bit with the numpy twin's, and one
Triton kernel a step on CUDA by default; ``compile_options`` compiles the env's work around the
device's step).
Not: regressor responses and vertex observations. With ``differentiable=True`` the same step carries torch
autograd's graph (``docs/gradients.md``).

Where episodes come from (``target_draw``): ``"host"`` (default) draws the targets with the per-env
numpy generators and precomputes each episode on the host, so it plays the numpy twin's episodes;
starting an episode mid-run reads which envs ended: one host synchronisation on each step where an
episode can end. Without success termination (the default) those are known on the host, once per
``horizon`` steps; with it, every step.
``"device"`` draws and scores episodes on the device (:mod:`softenv.envs.torch_parts`): with
``check_actions=False`` a step then never synchronises with the host and keeps every shape static,
so ``torch.compile(fullgraph=True)`` captures it whole (tested); for CUDA graphs the env compiles its
own step (``compile_options``) or records it (``cuda_graph``), keeping its step count on the host. Its targets come from
another generator, so its episodes differ from the numpy twin's; given the same target, the two
agree to rounding (tested).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..devices.base import DeviceTensors
from ..response import TabulatedResponse
from .batching import autoreset_mode as autoreset_mode_of
from .batching import disabled_step_check, episode_limit, reset_mask_option
from .checks import check_actions
from .config import scene_config
from .scene import depth_sensitivity
from .task import action_change, normalized_score, reward_terms
from .torch_graph import GraphedStep
from .._torch_ops import TorchOps
from .torch_parts import DeviceEpisodes, HostEpisodes, keep, sum_dtype
from .world import World

_GRAPH_MODES = ("reduce-overhead", "max-autotune")     # torch.compile modes that record CUDA graphs themselves


class SoftSphereTorchVectorEnv(VectorEnv):
    """``num_envs`` SoftSphere envs on torch tensors, with the scene's device in its tensor form (see the
    module docstring).

    Args:
        torch_device: torch device of every tensor (``"cpu"``, ``"cuda"``, ...); one this process cannot use is a
            ``ValueError`` that names it.
        dtype: ``torch.float64`` (default) or ``torch.float32`` for the state and rewards.
        check_actions: check each step's actions (shape, finite, within [-1, 1]): one host sync.
        target_draw: ``"host"`` (the numpy twin's episodes) or ``"device"`` (no host sync; see above).
        compile_options: ``torch.compile`` arguments (``{"mode": "reduce-overhead"}`` for CUDA graphs):
            the env compiles its step's tensor work (``fullgraph``; two graphs) and keeps its step count
            and the action check on the host. A device that keeps its step apart (the laryngoscope: its
            tensor engine compiles its substep, run 20 times a step, alone, with inductor on CPU only:
            ``tensors.check_compile``; its fused kernel on CUDA is compiled already) runs its calls as they
            are, and the env compiles its work around them (graph breaks: ``run_apart``). Needs
            ``target_draw="device"``. With CUDA graphs a step's outputs live until the next step: clone
            what you keep.
        cuda_graph: record the step's tensor work (eager, or compiled by ``compile_options`` in a mode
            without CUDA graphs) as CUDA graphs the env replays itself (:mod:`softenv.envs.torch_graph`):
            a step's host work is then one copy of the actions and one graph launch, without dynamo's and
            the CUDA-graph trees' per-call checks. Needs a CUDA device and ``target_draw="device"``; a
            step's outputs live until the next step: clone what you keep.
        differentiable: carry torch autograd's graph from actions that require grad through every step
            (the state held out of place; the laryngoscope on Warp's adjoint): rewards, infos and
            observations then have gradients to the episode's actions. ``detach()`` cuts the graph;
            ``reset()`` starts afresh. Not with ``compile_options`` or ``cuda_graph``. See the docs'
            "Gradients through softenv".
        Others as :class:`~softenv.envs.vector.SoftSphereVectorEnv`.

    Infos are dicts of tensors with ``_key`` masks, as the numpy twin's; with ``autoreset_mode="same_step"``
    ``info["final_obs"]`` holds every env's last observation (rows where ``info["_final_obs"]``) and
    ``info["final_info"]`` the ended episodes' infos; with ``"disabled"``, ``reset(options={"reset_mask":
    mask})`` (a numpy or torch bool mask) resets the masked envs, as the numpy twin's does.
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, render_mode: str | None = None, obs_mode: str = "vector",
                 max_episode_steps: int | None = None, autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
                 base_scene: dict[str, Any] | None = None, torch_device: str | torch.device = "cpu",
                 dtype: torch.dtype = torch.float64, check_actions: bool = True, target_draw: str = "host",
                 compile_options: dict[str, Any] | None = None, cuda_graph: bool = False, differentiable: bool = False,
                 **scene: Any) -> None:
        if not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs={num_envs!r} must be an int >= 1")
        if render_mode is not None:
            raise ValueError(f"render_mode={render_mode!r}: the torch backend does not render; use backend='numpy'")
        if dtype not in (torch.float64, torch.float32):
            raise ValueError(f"dtype={dtype!r} must be torch.float64 or torch.float32")
        if target_draw not in ("host", "device"):
            raise ValueError(f"target_draw={target_draw!r} must be 'host' or 'device'")
        if compile_options is not None and (not isinstance(compile_options, dict) or target_draw != "device"):
            raise ValueError(f"compile_options={compile_options!r} must be a dict of torch.compile arguments, "
                             f"and needs target_draw='device' (got {target_draw!r}: the host draw reads the host)")
        if cuda_graph and (target_draw != "device" or (compile_options or {}).get("mode") in _GRAPH_MODES):
            raise ValueError(f"cuda_graph=True needs target_draw='device' (got {target_draw!r}) and no compile mode "
                             f"that makes CUDA graphs of its own (got compile_options={compile_options!r})")
        if obs_mode not in ("vector", "dict"):
            raise ValueError(f"obs_mode={obs_mode!r}: the torch backend has 'vector' and 'dict' observations")
        if not isinstance(differentiable, bool):
            raise ValueError(f"differentiable={differentiable!r} must be True or False")
        if differentiable and (compile_options is not None or cuda_graph):
            raise ValueError(f"differentiable=True steps eagerly: it takes neither compile_options={compile_options!r} "
                             f"nor cuda_graph={cuda_graph!r} (their state lives at fixed addresses, written in place)")
        world = World(scene_config(base_scene, scene, f"{type(self).__name__}.__init__()"), obs_mode)
        self.max_episode_steps = episode_limit(max_episode_steps, world.horizon)
        kind = world.device_kind
        if kind.tensors is None:
            raise ValueError(f"device.kind={world.config['device']['kind']!r} has no tensor form (its DeviceKind's "
                             "tensors is None): the torch backend steps 'ideal' and 'laryngoscope'; use backend='numpy'")
        table = world.scene.response
        if not isinstance(table, TabulatedResponse):
            raise ValueError(f"response.model={world.config['response']['model']!r}: the torch backend expresses the "
                             "tabulated response (response.model='exact'); use backend='numpy' for regressors")
        self.world, self.torch_device, self.dtype = world, usable_device(torch_device), dtype
        self.check_actions = check_actions
        self.autoreset_mode = autoreset_mode_of(autoreset_mode)
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        self.num_envs, self.render_mode = int(num_envs), None
        self.single_action_space, self.single_observation_space = world.action_space, world.observation_space
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        t = self._tensor
        self._low, self._inv_step = t(table.low_), t(table.inv_step_)
        grid = table.grid()
        self._flat = t(grid.flat)
        self._strides = torch.as_tensor(grid.strides, dtype=torch.int64, device=self.torch_device)
        self._bits = torch.as_tensor(grid.bits, device=self.torch_device)
        self._offsets = list(grid.offsets)           # the corners' row offsets: constants of the step
        self._inv_sqrt, self._sqrt_var, self._b_rest = t(world.inv_sqrt), t(world.sqrt_variance), t(world.b_rest)
        self._rest_features = t(world.scene.rest_features)
        n, k = self.num_envs, world.k
        self._device = kind.tensors(world.scene, world.config, n, self.torch_device, dtype)
        self.differentiable = differentiable
        if differentiable:
            if not hasattr(self._device, "differentiable"):      # a kind written before the contract had it
                raise ValueError(f"device.kind={world.config['device']['kind']!r} has no differentiable() (see "
                                 "softenv.devices.base.DeviceTensors): its tensor form cannot carry gradients")
            self._device.differentiable()
        self._stiffness: torch.Tensor | None = None        # scene parameters held as leaves (track_params)
        self._target_shift: torch.Tensor | None = None
        self._depth: torch.Tensor | None = None
        self._depth_flat: torch.Tensor | None = None        # the response's sensitivity to the depth, as _flat
        self._high = t(table.high_)
        self._episodes = (HostEpisodes(world, n, t) if target_draw == "host"
                          else DeviceEpisodes(world, n, t, self._response))
        self._z, self._b = t(np.empty((n, k))), t(np.empty((n, k)))
        self._features, self._prev = t(np.empty((n, 4))), t(np.empty((n, 4)))
        self._t = torch.zeros(n, dtype=torch.int64, device=self.torch_device)
        self._agent_cum, self._peak = t(np.zeros(n), sum_dtype("agent_cum", dtype)), t(np.zeros(n))
        self._last_target = t(np.empty((n, k)))
        self._autoreset = torch.zeros(n, dtype=torch.bool, device=self.torch_device)
        self._last_obs: Any = None            # what step() or reset() returned last (autoreset_mode="disabled")
        self._started = False
        self._clock = 0                 # steps since reset(): on the host, for _episodes_may_start
        # the tensor work of a step, compiled when compile_options asks, recorded when cuda_graph asks
        work: Any = self._step_tensors
        if compile_options is not None:
            apart = self._device.compile(compile_options)     # the laryngoscope's substep, its kernel
            if apart:
                run_apart(self._device)
            work = torch.compile(self._step_tensors, fullgraph=not apart, **compile_options)
        self._tensor_work = GraphedStep(work, self._prev) if cuda_graph else work
        if self.torch_device.type == "cuda":
            # Every tensor the step reads stays at one address (the state is written in place: torch_parts.keep),
            # so CUDA graphs (compile_options={"mode": "reduce-overhead"}) may replay on them, state writes included,
            # without copying them in. (Only CUDA has graphs; importing torch._dynamo costs a second.)
            for part in (self, self._episodes):
                for value in vars(part).values():
                    if isinstance(value, torch.Tensor):
                        torch._dynamo.mark_static_address(value)

    def _tensor(self, value: Any, dtype: torch.dtype | None = None) -> torch.Tensor:
        return torch.as_tensor(np.asarray(value, dtype=np.float64), device=self.torch_device).to(dtype or self.dtype)

    # -- gymnasium API --------------------------------------------------------------------------

    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        mask, options = reset_mask_option(options, self.num_envs, self.autoreset_mode)
        if mask is not None and not self._started:
            raise RuntimeError("call reset() without a reset_mask first: there are no episodes to go on from")
        self._episodes.reset(seed, options, mask)
        if mask is None and self.differentiable:
            self.detach()                        # every episode starts afresh: nothing before it has a gradient
        chosen = torch.ones(self.num_envs, dtype=torch.bool, device=self.torch_device) if mask is None \
            else torch.as_tensor(mask, device=self.torch_device)
        if mask is None:
            self._started, self._clock = True, 0
        self._start(chosen)
        self._autoreset &= ~chosen
        obs = self._observe(self._b, self._shifted(self._episodes.first()), self._device_obs(), self._prev)
        if mask is not None:                     # the others' observations are those their last step returned
            obs = _where_rows(chosen, obs, self._last_obs)
        if self.autoreset_mode == AutoresetMode.DISABLED:
            self._last_obs = _clone(obs)
        return obs, {}

    def step(self, actions: Any) -> tuple[Any, torch.Tensor, torch.Tensor, torch.Tensor, dict[str, Any]]:
        if not self._started:
            raise RuntimeError("call reset() before step()")
        a = self._checked(actions)
        if self.autoreset_mode == AutoresetMode.DISABLED:       # a host read of the flags: this mode's price
            disabled_step_check(self._autoreset.cpu().numpy())
        self._clock += 1
        return self._tensor_work(a, self._episodes_may_start())

    def _step_tensors(self, a: torch.Tensor, may_start: bool
                      ) -> tuple[Any, torch.Tensor, torch.Tensor, torch.Tensor, dict[str, Any]]:
        """The step's tensor work: what ``compile_options`` compiles. The host's step count stays outside
        (``may_start``, a bool: one graph for each value). Read by a compiled graph, the count would be
        an int input, and CUDA graphs record a new graph for each value of an int input."""
        infos: dict[str, Any] = {}
        if self.autoreset_mode == AutoresetMode.SAME_STEP:
            obs, reward, terminated, truncated, values = self._advance(a, torch.ones_like(self._autoreset))
            done = terminated | truncated
            _add_masked(infos, values, ~done)
            final_obs = _clone(obs)
            final_info: dict[str, Any] = {}
            _add_masked(final_info, values, done)
            infos.update({"final_obs": final_obs, "_final_obs": done.clone(), "final_info": final_info,
                          "_final_info": done.clone()})
            return self._restart_rows(obs, done, may_start), reward, terminated, truncated, infos
        if self.autoreset_mode == AutoresetMode.DISABLED:
            obs, reward, terminated, truncated, values = self._advance(a, torch.ones_like(self._autoreset))
            _add_masked(infos, values, torch.ones_like(self._autoreset))
            self._autoreset.copy_(terminated | truncated)
            self._last_obs = _clone(obs)
            return obs, reward, terminated, truncated, infos
        reset_now = self._autoreset.clone()
        obs, reward, terminated, truncated, values = self._advance(a, ~reset_now)
        obs = self._restart_rows(obs, reset_now, may_start)
        _add_masked(infos, values, ~reset_now)
        self._autoreset.copy_(terminated | truncated)
        return obs, reward, terminated, truncated, infos

    def detach(self) -> None:
        """Cut autograd's graph at the current state (``differentiable=True``): later steps' gradients stop
        here, and the memory the graph held is freed (truncated backpropagation through time)."""
        for name in ("_z", "_b", "_prev", "_features", "_agent_cum", "_peak", "_last_target"):
            setattr(self, name, getattr(self, name).detach())
        self._device.detach()

    def track_state(self) -> dict[str, torch.Tensor]:
        """Hold the current state as new leaves of autograd's graph (``differentiable=True``, after
        ``reset()``) and return them: ``z`` (the tissue's creep state), ``prev_action`` (the last action,
        which the action-change term reads) and the device's state as ``device.<name>``. A later loss's
        ``backward()`` leaves its gradient with respect to the start state in their ``.grad``; changing
        them in place under ``torch.no_grad()`` before stepping moves the start state (a finite difference)."""
        if not self.differentiable:
            raise ValueError("track_state() needs differentiable=True (make_vec(..., backend='torch', differentiable=True))")
        if not self._started:
            raise RuntimeError("call reset() before track_state(): there is no state to track")
        self.detach()
        self._z = self._z.clone().requires_grad_(True)
        self._prev = self._prev.clone().requires_grad_(True)
        device = self._device.track_state()
        return {"z": self._z, "prev_action": self._prev, **{f"device.{name}": x for name, x in device.items()}}

    def track_params(self, names: tuple[str, ...] | None = None) -> dict[str, torch.Tensor]:
        """Hold scene parameters as leaves of autograd's graph (``differentiable=True``) and return them by
        name (``names``: those this scene has, :meth:`scene_params`; None: all of them). Each is a factor on
        the scene's own value, 1 at first, or a shift, 0 at first:

        * ``tissue_stiffness`` ``(n,)``: each env's tongue modulus over the scene's. The tissue's response
          depends on the force only through ``F / E`` (both laws, the FE tongue's neo-Hookean energy at a
          fixed Poisson ratio), so the step looks the response up at the forces over the factor; forces beyond
          the response table's range (a factor below 1) are held at its edge, where the gradient is 0. On the
          laryngoscope the tongue's contact law and lateral grip take the factor too. Targets stay the
          shapes they are.
        * ``coupling_stiffness``, ``coupling_damping`` ``(n,)`` (laryngoscope): the hand-blade coupling's
          translational stiffness and damping over the scene's.
        * ``rotational_stiffness``, ``rotational_damping`` ``(n,)`` (laryngoscope): the wrist's rotary
          spring and damper over the scene's (the damper's velocity coefficient follows, as Chipmunk's).
        * ``target_shift`` ``(n, k)``: added to every step's target shape parameters: the reward, its
          reference distance and the observation follow the shifted target; the normalized score's anchors
          stay the drawn target's.
        * ``stiffening_depth`` ``(n,)`` (the analytic tongue's stiffening law): the law's depth over the
          scene's. The response is taken to first order in it, ``b(F) + (q - 1) db/dq(F)``, from a table of
          ``db/dq`` by central differences of the analytic tissue
          (:func:`~softenv.envs.scene.depth_sensitivity`, built on first use), and on the laryngoscope the
          tongue's contact law too (:func:`~softenv.devices.contact.depth_derivative`, in the Warp kernel):
          its gradient is the tissue's at the scene's depth; away from it the step is that linear model's
          (its bias: docs/gradients.md).

        They stay across ``reset()`` and ``detach()`` (they are not state); a later ``backward()`` leaves
        each one's gradient in its ``.grad``, and moving one in place under ``torch.no_grad()`` moves the
        scene (a finite difference). At their start values the step is the plain twin's bit for bit."""
        if not self.differentiable:
            raise ValueError("track_params() needs differentiable=True (make_vec(..., backend='torch', differentiable=True))")
        offered = self.scene_params()
        for name in names if names is not None else ():
            if name not in offered:
                raise ValueError(f"names contains {name!r}: on device.kind={self.world.device_kind.name!r} the scene "
                                 f"parameters are {list(offered)}")
        out = {}
        for name in offered if names is None else names:
            shape = (self.num_envs, self.world.k) if name == "target_shift" else (self.num_envs,)
            start = torch.zeros if name == "target_shift" else torch.ones
            out[name] = start(shape, dtype=self.dtype, device=self.torch_device).requires_grad_(True)
        self._stiffness, self._target_shift = out.get("tissue_stiffness"), out.get("target_shift")
        self._depth = out.get("stiffening_depth")
        if self._depth is not None and self._depth_flat is None:
            sensitivity = depth_sensitivity(self.world.scene)
            self._depth_flat = self._tensor(sensitivity.grid().flat)
        carried = getattr(self._device, "scene_params", ())
        if carried:
            self._device.use_params({k: v for k, v in out.items() if k in carried})
        return out

    def scene_params(self) -> tuple[str, ...]:
        """The scene parameters :meth:`track_params` offers here: the target's shift, those the device's
        step carries (``DeviceTensors.scene_params``; none for a kind written before the contract had it),
        and the stiffening law's depth where the tongue is analytic on that law (the response's; a device
        that carries it too moves its own law with it: the laryngoscope's contact)."""
        scene = self.world.scene
        law = ("stiffening_depth",) if scene.fe is None and scene.tissue.law == "stiffening" else ()
        carried = (name for name in getattr(self._device, "scene_params", ()) if name != "stiffening_depth")
        return ("target_shift", *carried, *law)

    def _stiffened(self, f: torch.Tensor) -> torch.Tensor:
        """The force features at which a tongue ``tissue_stiffness`` times as stiff responds as the scene's."""
        s = self._stiffness
        assert s is not None
        if not bool((s > 0).all()):
            i = int((~(s > 0)).nonzero()[0, 0])
            raise ValueError(f"tissue_stiffness[{i}] = {float(s[i].detach())!r}: a modulus factor must be > 0")
        forces = f[:, 2:] / s[:, None]
        forces = torch.minimum(torch.maximum(forces, self._low[2:]), self._high[2:])
        return torch.cat([f[:, :2], forces], dim=-1)

    def _shifted_references(self, target: torch.Tensor, sq_ref: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The shifted target and its reference distance ``max(|b* - b_rest|^2, floor)``, moved from the
        episode's by the shift's change, so that a shift of 0 leaves it as it was bit for bit."""
        shifted, floor = self._shifted(target), self.world.floor_sq
        before, after = (torch.sum((x - self._b_rest) ** 2, dim=-1) for x in (target, shifted))
        moved = torch.where(before >= floor, sq_ref + (after - before), after)
        return shifted, torch.where(after >= floor, moved, torch.full_like(sq_ref, floor))

    def _shifted(self, target: torch.Tensor) -> torch.Tensor:
        return target if self._target_shift is None else target + self._target_shift

    # -- the step -------------------------------------------------------------------------------

    def _checked(self, actions: Any) -> torch.Tensor:
        if not self.check_actions:                     # the unchecked fast path: no host copy, no host sync
            return torch.as_tensor(actions, device=self.torch_device).to(self.dtype)
        if not isinstance(actions, torch.Tensor):      # host data: the numpy twin's one check (it names the problem)
            return torch.as_tensor(check_actions(actions, self.num_envs), device=self.torch_device).to(self.dtype)
        a = actions.to(self.torch_device)
        if tuple(a.shape) != (self.num_envs, 4):
            raise ValueError(f"actions must have shape ({self.num_envs}, 4); got {tuple(a.shape)}")
        if a.is_complex() or a.dtype == torch.bool:
            raise ValueError(f"actions must be real numbers; got dtype {a.dtype}")
        bad = ~((a >= -1.0) & (a <= 1.0))
        if bool(bad.any()):
            i, j = (int(x) for x in bad.nonzero()[0])
            raise ValueError(f"actions[{i}, {j}] = {float(a[i, j])!r}: actions must be finite and within [-1, 1]")
        return a.to(self.dtype)

    def _response(self, x: torch.Tensor) -> torch.Tensor:
        """The response table's multilinear interpolation (as :meth:`TabulatedResponse.lookup`); under
        autograd through :class:`_Lookup`, which keeps the features, not every corner's row."""
        if x.requires_grad:
            return _Lookup.apply(x, self)
        return self._interpolate(x)

    def _corners(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Where ``x`` lies in the table: each axis's pair of weights ``(N, d, 2)`` (1 - frac, frac), the
        corners' weights ``(N, 2**d)`` and the cell's first row ``(N,)``."""
        t = (x - self._low) * self._inv_step
        cell = torch.clamp(torch.floor(t), min=0.0)
        frac = t - cell
        g = torch.stack([1.0 - frac, frac], dim=-1)                      # (N, d, 2)
        w = g[:, 0, self._bits[:, 0]]
        for j in range(1, x.shape[1]):
            w = w * g[:, j, self._bits[:, j]]
        return g, w, torch.sum(cell.to(torch.int64) * self._strides, dim=-1)

    def _interpolate(self, x: torch.Tensor, flat: torch.Tensor | None = None) -> torch.Tensor:
        """``x``'s multilinear interpolation in the response table (``flat``: another table on its grid)."""
        rows = self._flat if flat is None else flat
        _, w, base = self._corners(x)
        # corner by corner, not a gather of rows and a bmm: compiled, one elementwise kernel reading the
        # table's rows where they lie (docs/performance.md: measured choices)
        out = w[:, :1] * rows[base + self._offsets[0]]
        for c in range(1, len(self._offsets)):
            out = out + w[:, c:c + 1] * rows[base + self._offsets[c]]
        return out

    def _advance(self, a: torch.Tensor, stepped: torch.Tensor) -> tuple[Any, torch.Tensor, torch.Tensor, torch.Tensor,
                                                                         dict[str, torch.Tensor]]:
        """The numpy twin's ``_advance`` (the stepped envs commit their state) on tensors."""
        w = self.world
        target, sq_ref, zero, oracle = self._episodes.references(self._t, stepped)
        f, normal, sideways = self._device.act(a, stepped)
        x = f if self._stiffness is None else self._stiffened(f)
        g = self._response(x)
        if self._depth is not None:                  # first order in the depth's factor (track_params)
            assert self._depth_flat is not None
            if not bool((self._depth > 0).all()):
                i = int((~(self._depth > 0)).nonzero()[0, 0])
                raise ValueError(f"stiffening_depth[{i}] = {float(self._depth[i].detach())!r}: a depth factor must be > 0")
            g = g + (self._depth - 1.0)[:, None] * self._interpolate(x, self._depth_flat)
        if self._target_shift is not None:
            target, sq_ref = self._shifted_references(target, sq_ref)
        z = self._z.clone() if w.dynamics.stateful else self._z     # step advances the creep state in place
        b = w.dynamics.step(z, g)
        d = b - target
        sq = torch.sum(d * d, dim=-1)
        change = action_change(a.T, self._prev.T)
        reward, shape, force_term, smooth, ratio, force = reward_terms(sq, sq_ref, normal, sideways,
                                                                       change, w.weights, TorchOps)
        agent_cum = self._agent_cum + ratio.to(torch.float64)
        peak = torch.maximum(self._peak, force)
        score = normalized_score(zero, oracle, agent_cum, TorchOps)
        success = ratio < w.tolerance
        s = stepped
        rows = s[:, None]
        self._z = keep(rows, z, self._z)
        self._b = keep(rows, b, self._b)
        self._prev = keep(rows, a, self._prev)
        self._features = keep(rows, f, self._features)
        self._agent_cum = keep(s, agent_cum, self._agent_cum)
        self._peak = keep(s, peak, self._peak)
        self._last_target = keep(rows, target, self._last_target)
        self._t += s.to(torch.int64)
        terminated = (success & w.terminate_on_success) & s
        truncated = (self._t >= self.max_episode_steps) & s
        values = {"reward_shape": shape, "reward_force": force_term, "reward_smooth": smooth,
                  "shape_error_mm": torch.sqrt(sq / w.n_vertices) * 1e3, "force_N": force, "peak_force_N": peak,
                  "is_success": success, "normalized_score": score}
        extra = self._device.report(values, s)
        reward = reward + extra
        upcoming = self._episodes.upcoming(self._t)      # (the device source moves its target here)
        device_obs = self._device_obs()
        if w.obs_mode == "dict":
            obs = self._observe(self._b, self._last_target, device_obs, self._prev)
            shape = self._goal_shape_term(obs["achieved_goal"], obs["desired_goal"])
            reward = shape + (force_term + smooth + extra)
            values["reward_shape"] = shape
        else:
            obs = self._observe(self._b, self._shifted(upcoming), device_obs, self._prev)
        return obs, torch.where(s, reward, torch.zeros_like(reward)), terminated, truncated, values

    def _goal_shape_term(self, achieved: torch.Tensor, desired: torch.Tensor) -> torch.Tensor:
        """:meth:`World.goal_shape_term` on tensors: the shape term from the float32 goals."""
        b = achieved.to(self.dtype) * self._sqrt_var
        target = desired.to(self.dtype) * self._sqrt_var
        d = b - target
        r = target - self._b_rest
        sq_ref = torch.clamp(torch.sum(r * r, dim=-1), min=self.world.floor_sq)
        return -self.world.weights["shape_weight"] * torch.sqrt(torch.sum(d * d, dim=-1) / sq_ref)

    def _device_obs(self) -> torch.Tensor:
        return self._device.observation(self._features)

    def _observe(self, b: torch.Tensor, target: torch.Tensor, device_obs: torch.Tensor, prev: torch.Tensor) -> Any:
        k = self.world.k
        obs = torch.cat([b * self._inv_sqrt, target * self._inv_sqrt, device_obs, prev], dim=-1).to(torch.float32)
        if self.world.obs_mode == "dict":
            return {"observation": obs[:, 2 * k:].clone(), "achieved_goal": obs[:, :k].clone(),
                    "desired_goal": obs[:, k:2 * k].clone()}
        return obs

    # -- episode starts (the targets come from self._episodes) ----------------------------------

    def _start(self, mask: torch.Tensor) -> None:
        rows = mask[:, None]
        self._z = keep(rows, self._b_rest, self._z)
        self._b = keep(rows, self._b_rest, self._b)
        self._features = keep(rows, self._rest_features, self._features)
        self._prev = keep(rows, self._device.reset(mask), self._prev)
        self._t = keep(mask, torch.zeros_like(self._t), self._t)
        self._agent_cum = keep(mask, torch.zeros_like(self._agent_cum), self._agent_cum)
        self._peak = keep(mask, torch.zeros_like(self._peak), self._peak)
        self._last_target = keep(rows, self._shifted(self._episodes.first()), self._last_target)

    def _episodes_may_start(self) -> bool:
        """Whether an env can start an episode this step. Without success termination every episode lasts
        ``max_episode_steps`` and all began at reset(), so the host knows those steps (no read of the flags):
        one in ``max_episode_steps`` steps (same-step autoreset) or one more (next-step: the step after the end)."""
        if self.autoreset_mode == AutoresetMode.DISABLED:
            return False                  # the caller starts episodes, through reset()
        if self.world.terminate_on_success:
            return True
        period = self.max_episode_steps + (self.autoreset_mode == AutoresetMode.NEXT_STEP)
        return self._clock % period == 0

    def _restart_rows(self, obs: Any, mask: torch.Tensor, may_start: bool) -> Any:
        """Draw new episodes for the masked envs, reset their state and write their first observations."""
        if not may_start or not self._episodes.restart(mask):
            return obs
        self._start(mask)
        return _where_rows(mask, self._observe(self._b, self._shifted(self._episodes.first()), self._device_obs(),
                                               self._prev), obs)


DEVICE_CALLS = ("reset", "act", "observation", "report")     # what a step calls of its device


def run_apart(device: DeviceTensors) -> None:
    """Leave ``device``'s calls out of the env's compiled step: each is a graph break, run as it is
    (``torch.compiler.disable``), and dynamo compiles the env's work before and after it. For a device
    that keeps its step apart (:meth:`~softenv.devices.base.DeviceTensors.compile` returns True)."""
    for name in DEVICE_CALLS:
        setattr(device, name, torch.compiler.disable(getattr(device, name)))


class _Lookup(torch.autograd.Function):
    """The table's interpolation for autograd, saving only the features: a step's corners' rows (``2**d``
    of them, each ``k`` floats) would be most of an episode's graph. Backward gathers them again:
    d out / d x_j = inv_step_j sum_c (+-prod_{i != j} g_i) row_c, the sign that of corner c's bit j (the
    derivative of the weights' product in frac_j; the floor has none)."""

    @staticmethod
    def forward(ctx: Any, x: torch.Tensor, env: SoftSphereTorchVectorEnv) -> torch.Tensor:
        ctx.save_for_backward(x)
        ctx.env = env
        return env._interpolate(x)

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> tuple[torch.Tensor, None]:
        (x,), env = ctx.saved_tensors, ctx.env
        g, _, base = env._corners(x)
        bits, d = env._bits, x.shape[1]
        # each corner's row against the incoming gradient: (N, 2**d)
        dots = torch.stack([torch.sum(env._flat[base + offset] * grad, dim=-1) for offset in env._offsets], dim=-1)
        out = torch.empty_like(x)
        for j in range(d):
            others = torch.ones_like(dots)
            for i in range(d):
                if i != j:
                    others = others * g[:, i, bits[:, i]]
            sign = bits[:, j].to(x.dtype) * 2.0 - 1.0
            out[:, j] = torch.sum(sign * others * dots, dim=-1) * env._inv_step[j]
        return out, None


def usable_device(value: Any) -> torch.device:
    """``value`` as a torch device this process can put tensors on, or a ValueError that names it (torch's
    own errors say neither the argument nor the way out: an AssertionError for CUDA on a CPU build)."""
    try:
        device = torch.device(value)
        torch.empty(0, device=device)
    except (RuntimeError, AssertionError, TypeError) as exc:
        gpu = "a CUDA device is available" if torch.cuda.is_available() else "no CUDA device is available"
        raise ValueError(f"torch_device={value!r} is not a torch device usable here ({gpu}; use 'cpu' or a "
                         f"'cuda:i' that exists): {exc}") from None
    return device


def _where_rows(mask: torch.Tensor, fresh: Any, obs: Any) -> Any:
    """``fresh``'s rows where ``mask``, ``obs``'s elsewhere (observations: a tensor or a dict of them)."""
    if isinstance(obs, dict):
        return {key: torch.where(mask[:, None], fresh[key], value) for key, value in obs.items()}
    return torch.where(mask[:, None], fresh, obs)


def _clone(obs: Any) -> Any:
    return {key: value.clone() for key, value in obs.items()} if isinstance(obs, dict) else obs.clone()


def _add_masked(infos: dict[str, Any], values: dict[str, torch.Tensor], mask: torch.Tensor) -> None:
    """Infos as the numpy twin makes them (zeros where the mask is off, plus ``_key``), on tensors; always
    present (no host branch on the mask)."""
    for key, value in values.items():
        rows = mask.reshape(mask.shape + (1,) * (value.dim() - 1))        # (n, 1, ...) for rows of vectors
        infos[key] = torch.where(rows, value, torch.zeros((), dtype=value.dtype, device=value.device))
        infos[f"_{key}"] = mask.clone()
