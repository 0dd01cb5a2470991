"""SoftSphere: press and sweep a tongue-like elastic sphere into a target shape (single env and its
natively batched twin, side by side, as in Gymnasium's ``cartpole.py``)."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .config import scene_config
from .._ops import ArrayOps, ScalarOps
from .._validation import real_array
from .parts import reward_terms
from .rendering import RENDER_MODES, SceneRenderer, check_render_mode
from .world import World

_add_reduce = np.add.reduce


class SoftSphereEnv(gym.Env):
    """
    ## Description

    A laryngoscope blade presses on the dorsum of a tongue-like elastic sphere (radius 30 mm) and
    sweeps it sideways. The tissue's surface is a PCA shape model (Sotiropoulos et al.): a force vector
    maps to shape parameters ``b`` (the scene's *response*: the tabulated analytic tissue by default,
    or one of the paper's regressors), and ``b`` rebuilds the surface. The agent commands the force
    through a device and must bring the surface to a target shape: the equilibrium shape of a force
    drawn from the laryngoscopy family (compress at an insertion depth, push toward +y), so every
    target is reachable.

    ## Action Space

    ``Box(-1, 1, (4,), float32)``, mapped linearly onto the device's workspace (``device`` section):

    | index | meaning | -1 | +1 |
    |---|---|---|---|
    | 0 | insertion: contact position along the midline (arc from the front) | 30 deg | 120 deg |
    | 1 | lateral: contact position off the midline | -20 deg | +20 deg |
    | 2 | normal force (pressing) | 0 N | 40 N |
    | 3 | sideways force (toward +y) | -10 N | +10 N |

    Actions outside ``[-1, 1]``, non-finite, or of another shape raise ``ValueError`` (nothing is
    clipped; the env's state is left as it was).

    ## Observation Space

    ``obs_mode="vector"`` (default): ``Box(float32, (2 k + 8,))`` with finite bounds from the
    response's range (``k`` = the scene's PCA components; 28 at the default scene):

    | slice | meaning | units |
    |---|---|---|
    | ``[0, k)`` | current shape parameters ``b / sqrt(lambda)`` | PCA standard deviations |
    | ``[k, 2k)`` | target ``b* / sqrt(lambda)`` for the next action | PCA standard deviations |
    | ``[2k, 2k+4)`` | device state: applied force, normalised like the action | [-1, 1] |
    | ``[2k+4, 2k+8)`` | previous action (for the ideal device it equals the device state) | [-1, 1] |

    ``obs_mode="dict"``: ``observation`` (the last 8 entries), ``achieved_goal`` (``b / sqrt(lambda)``)
    and ``desired_goal`` (the target the last step was scored against), with a vectorised
    :meth:`compute_reward` for HER. ``obs_mode="vertices"``: the vector observation followed by the
    ``3 n`` surface coordinates over the radius (decoded only in this mode).

    ## Rewards

    ``reward = shape + force + smooth`` with

    | term (``info`` key) | formula | weight argument |
    |---|---|---|
    | ``reward_shape`` | ``-w ||b - b*|| / max(||b* - b_rest||, floor)``: RMS surface error over the target's RMS displacement | ``reward.shape_weight`` = 1 |
    | ``reward_force`` | ``-w max(|F| - F_safe, 0) / F_safe`` | ``reward.force_weight`` = 0, ``reward.safe_force`` = 30 N |
    | ``reward_smooth`` | ``-w ||a - a_prev||^2 / 4`` | ``reward.smoothness_weight`` = 0 |

    Distances are taken in b-space (orthonormal components: equal to the surface distance within the
    model, no vertex rebuilt). ``floor`` is 10 % of the family centre's displacement (keeps the ratio
    finite for small targets in the procedure task).

    ## Starting State

    No force at the middle of the contact range (``b = b_rest``, device state ``[0, 0, -1, 0]``);
    the target is drawn from the ``task.split`` cells of the family with the env's ``np_random``.
    ``reset(options={"target": a})`` fixes the target force in action units instead.

    ## Episode End

    * Termination: only with ``task.terminate_on_success=True``, when ``is_success``
      (``shape error < task.tolerance`` x target displacement; default 10 %).
    * Truncation: after ``task.horizon`` steps (100; the registered ``max_episode_steps``).

    ``info`` at every step: the reward terms, ``shape_error_mm`` (RMS over vertices),
    ``force_N``, ``peak_force_N`` (episode so far), ``is_success`` and ``normalized_score``: the
    episode's score so far, 0 for the zero-force policy and 100 for the exact oracle (which holds the
    target force), from the shape term alone; read it at the episode's last step. With creep
    (viscoelastic scenes) holding the target force is not optimal -- the shape lags it -- so a policy
    that presses harder at first can score above 100.

    ## Arguments

    ``gym.make("SoftSphere-v0", render_mode=None, obs_mode="vector", **scene)`` where ``scene`` are
    section dicts overriding :func:`softenv.default_config` (``tissue``, ``mesh``, ``shape_model``,
    ``response``, ``device``, ``dynamics``, ``task``, ``reward``, ``render``); e.g.
    ``gym.make("SoftSphere-v0", tissue={"law": "stiffening"}, reward={"force_weight": 0.5})``. Unknown
    keys or values out of range raise ``ValueError`` listing what is valid. ``softenv.describe_config()``
    prints every setting with units.

    | id | scene |
    |---|---|
    | ``SoftSphere-v0`` | ideal device, quasi-static tissue, exact response, reach one target |
    | ``SoftSphereViscoelastic-v0`` | as v0 with viscoelastic creep (r = 0.7, tau = 5.8 s, dt = 0.05 s) |
    | ``SoftSphereProcedure-v0`` | as v0 with the target moving insert -> press -> sweep |

    ## Version History

    * v0: initial release.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 20}

    def __new__(cls, *args: Any, obs_mode: str = "vector", **kwargs: Any) -> "SoftSphereEnv":
        # goal-conditioned tools detect a GoalEnv by its compute_reward: only dict observations have one
        if obs_mode == "dict" and cls in GOAL_TWINS:
            cls = GOAL_TWINS[cls]
        return super().__new__(cls)

    def __init__(self, render_mode: str | None = None, obs_mode: str = "vector",
                 base_scene: dict[str, Any] | None = None, **scene: Any) -> None:
        check_render_mode(render_mode)
        self.world = World(scene_config(base_scene, scene, f"{type(self).__name__}.__init__()"), obs_mode)
        self.metadata = {**self.metadata, "render_fps": self.world.config["render"]["fps"]}
        self.render_mode = render_mode
        self.action_space = self.world.action_space
        self.observation_space = self.world.observation_space
        self._device = self.world.device
        self._renderer: SceneRenderer | None = None
        self._episode = None

    # -- gymnasium API --------------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        target = _target_option(self.world, options)     # check everything before the seed changes anything
        super().reset(seed=seed)
        ep = self.world.start_episodes([self.np_random], [target])
        self._target_features, self._target_b = ep.target_features[0], ep.target_b[0]
        self._targets = list(self._target_b)           # row views made once, not every step
        self._last_index = len(self._targets) - 1
        self._sq_ref = ep.sq_ref[0].tolist()
        self._zero_cum, self._oracle_cum = ep.zero_cum[0].tolist(), ep.oracle_cum[0].tolist()
        self._episode = ep
        w = self.world
        self._z = w.b_rest.copy()
        self._b = w.b_rest.copy()
        self._features = w.scene.rest_features.tolist()
        self._prev = self._start_device()
        self._t, self._agent_cum, self._peak = 0, 0.0, 0.0
        self._last_target = self._target_b[0]
        obs = w.observe(self._b, self._target_b[0], self._device_obs(self._features), self._prev)
        return obs, {}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        if self._episode is None:
            raise RuntimeError("call reset() before step()")
        a = _check_action_one(action)
        w = self.world
        f, normal, sideways = self._actuate(a)
        b = w.dynamics.step(self._z, w.response_one(f))
        t = self._t
        ti = t if t < self._last_index else self._last_index
        target = self._targets[ti]
        d = b - target
        sq = float(_add_reduce(d * d))                   # the batched twin's np.sum(..., axis=-1), row by row
        p = self._prev
        change = (a[0] - p[0]) * (a[0] - p[0]) + (a[1] - p[1]) * (a[1] - p[1]) + (a[2] - p[2]) * (a[2] - p[2]) \
            + (a[3] - p[3]) * (a[3] - p[3])
        reward, shape, force_term, smooth, ratio, force = reward_terms(sq, self._sq_ref[ti], normal, sideways, change,
                                                                       w.weights, ScalarOps)
        self._agent_cum += ratio
        self._peak = force if force > self._peak else self._peak
        hi = min(t, w.horizon - 1)
        zero, oracle = self._zero_cum[hi], self._oracle_cum[hi]
        score = 100.0 * (zero - self._agent_cum) / max(zero - oracle, 1e-12)
        success = ratio < w.tolerance
        self._t, self._b, self._prev, self._features, self._last_target = t + 1, b, a, f, target
        info = {"reward_shape": shape, "reward_force": force_term, "reward_smooth": smooth,
                "shape_error_mm": math.sqrt(sq / w.n_vertices) * 1e3, "force_N": force, "peak_force_N": self._peak,
                "is_success": success, "normalized_score": score}
        extra = self._device_terms(info)
        reward += extra
        upcoming = self._targets[t + 1 if t + 1 < self._last_index else self._last_index]
        if w.obs_mode == "dict":
            obs = w.observe(b, target, self._device_obs(f), a)
            shape = float(w.goal_shape_term(obs["achieved_goal"], obs["desired_goal"]))
            reward = shape + (force_term + smooth + extra)
            info["reward_shape"] = shape
        else:
            obs = w.observe(b, upcoming, self._device_obs(f), a)
        terminated = w.terminate_on_success and success
        return obs, reward, terminated, self._t >= w.horizon, info

    # -- the device (the ideal one here; the laryngoscope env overrides these) ---------------------

    def _start_device(self) -> list[float]:
        """Put the device at rest; returns the previous action an episode starts with."""
        return self._device.rest_action.astype(np.float64).tolist()

    def _actuate(self, a: list[float]) -> tuple[list[float], float, float]:
        """Apply a checked action: force features for the response, and the normal and sideways force (N)."""
        f = self._device.features_one(a)
        return f, f[2], f[3]

    def _device_obs(self, features: list[float]) -> list[float]:
        return self._device.normalised_one(features)

    def _device_terms(self, info: dict[str, Any]) -> float:
        """Add the device's own terms to ``info``; returns their reward (none for the ideal device)."""
        return 0.0

    def _render_device(self) -> Any:
        """What the renderer draws of the device beside the sphere (nothing for the ideal device)."""
        return None

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' or 'human' to make()")
            return None
        if self._episode is None:
            raise RuntimeError("call reset() before render()")
        if self._renderer is None:
            self._renderer = SceneRenderer(self.world, self.render_mode)
        caption = f"step {self._t}   force {math.hypot(self._features[2], self._features[3]):.1f} N"
        return self._renderer.frame(self._b, self._last_target, np.array(self._features), caption, self._render_device())

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderer"] = None            # figures are rebuilt on demand, never pickled
        return state


class GoalReward:
    """Mixin for ``obs_mode="dict"``: HER's ``compute_reward``."""

    world: World

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> Any:
        """Reward from goals, vectorised over leading axes (see :meth:`World.compute_reward`)."""
        return self.world.compute_reward(achieved_goal, desired_goal, info)


class SoftSphereGoalEnv(GoalReward, SoftSphereEnv):
    """:class:`SoftSphereEnv` with ``obs_mode="dict"`` (made by it): adds HER's ``compute_reward``."""


# env class -> its goal-conditioned twin, which ``__new__`` picks for dict observations
GOAL_TWINS: dict[type, type] = {SoftSphereEnv: SoftSphereGoalEnv}


class SoftSphereVectorEnv(VectorEnv):
    """``num_envs`` SoftSphere envs stepped together in numpy: the same physics, bit for bit.

    Seeding follows Gymnasium's vector envs: ``reset(seed=s)`` seeds env ``i`` with ``s + i``, so
    this env equals ``num_envs`` :class:`SoftSphereEnv` seeded alike (observations, rewards, flags
    and infos). Episodes end after ``max_episode_steps`` (default: the scene's ``task.horizon``).
    ``autoreset_mode``: ``"next_step"`` (Gymnasium's default: the step after an episode ends resets
    that env and ignores its action) or ``"same_step"`` (reset at once; ``info["final_obs"]`` and
    ``info["final_info"]`` hold the last observation and info, as SB3 needs). Infos are dicts of
    arrays with ``_key`` masks, as :class:`gymnasium.vector.SyncVectorEnv` makes them.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 20, "autoreset_mode": AutoresetMode.NEXT_STEP}
    episode_end_info_keys: tuple[str, ...] = ()      # info keys present only on steps where an episode ends

    def __new__(cls, *args: Any, backend: str = "numpy", **kwargs: Any) -> Any:
        # backend="torch": the ideal-device twin on torch tensors (softenv.envs.torch_twin; imports torch)
        if backend == "numpy":
            return super().__new__(cls)
        if backend != "torch":
            raise ValueError(f"backend={backend!r} must be 'numpy' or 'torch'")
        if cls is not SoftSphereVectorEnv:
            raise ValueError(f"backend='torch' covers the ideal-device ids; {cls.__name__} steps with numpy only")
        from .torch_twin import SoftSphereTorchVectorEnv

        return SoftSphereTorchVectorEnv(*args, **kwargs)

    def __init__(self, num_envs: int = 1, render_mode: str | None = None, obs_mode: str = "vector",
                 max_episode_steps: int | None = None, autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
                 base_scene: dict[str, Any] | None = None, backend: str = "numpy", **scene: Any) -> None:
        if not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs={num_envs!r} must be an int >= 1")
        check_render_mode(render_mode)
        if max_episode_steps is not None:
            scene = {**scene, "task": {**scene.get("task", {}), "horizon": max_episode_steps}}
        self.world = World(scene_config(base_scene, scene, f"{type(self).__name__}.__init__()"), obs_mode)
        self.autoreset_mode = _autoreset_mode(autoreset_mode)
        self.metadata = {**self.metadata, "render_fps": self.world.config["render"]["fps"],
                         "autoreset_mode": self.autoreset_mode}
        self.num_envs = int(num_envs)
        self.render_mode = render_mode
        self.single_action_space = self.world.action_space
        self.single_observation_space = self.world.observation_space
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        n, k = self.num_envs, self.world.k
        self._rngs = [np.random.default_rng() for _ in range(n)]
        self._z = np.empty((n, k))
        self._b = np.empty((n, k))
        self._features = np.empty((n, 4))
        self._prev = np.empty((n, 4))
        self._t = np.zeros(n, dtype=np.int64)
        self._agent_cum = np.zeros(n)
        self._peak = np.zeros(n)
        self._last_target = np.empty((n, k))
        self._autoreset = np.zeros(n, dtype=bool)
        self._episode = None
        # the step's large temporaries, reused (see TableWork: fresh ones can cost a page fault a page)
        self._response_work = self.world.response_work(n)
        self._diff = np.empty((n, k))
        self._renderers: list[SceneRenderer] = []

    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        self._rngs, self._episode = seeded_episodes(self.world, self._rngs, seed, options)
        self._start(np.ones(self.num_envs, dtype=bool))
        self._autoreset[:] = False
        return self._observe(self._b, self._upcoming_target(), self._device_obs(), self._prev), {}

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        infos: dict[str, Any] = {}
        if self.autoreset_mode == AutoresetMode.SAME_STEP:
            obs, reward, terminated, truncated, values, final_obs = self.step_values(actions)
            done = terminated | truncated
            _add_masked(infos, values, ~done)
            if final_obs is not None:
                final_info: dict[str, Any] = {}
                _add_masked(final_info, values, done)
                infos.update({"final_obs": final_obs, "_final_obs": done.copy(), "final_info": final_info,
                              "_final_info": done.copy()})
            return obs, reward, terminated, truncated, infos
        a = self._checked(actions)
        reset_now = self._autoreset.copy()
        obs, reward, terminated, truncated, values = self._advance(a, ~reset_now)
        if reset_now.any():               # next-step autoreset: these envs ignored their action and restart now
            self._restart(reset_now)
            obs = self._write_rows(obs, reset_now)
        _add_masked(infos, values, ~reset_now)
        self._autoreset = terminated | truncated
        return obs, reward, terminated, truncated, infos

    def step_values(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray],
                                                 np.ndarray | None]:
        """One step with same-step autoreset (the twin's ``autoreset_mode="same_step"``), for adapters that
        format infos their own way: ``obs, reward, terminated, truncated, values, final_obs`` with
        ``values`` the info terms of every env (unmasked arrays) and ``final_obs`` the ended envs' last
        observations (an object array, ``None`` where an env goes on; ``None`` when none ended)."""
        if self.autoreset_mode != AutoresetMode.SAME_STEP:
            raise RuntimeError("step_values() needs autoreset_mode='same_step'")
        a = self._checked(actions)
        obs, reward, terminated, truncated, values = self._advance(a, np.ones(self.num_envs, dtype=bool))
        done = terminated | truncated
        if not done.any():
            return obs, reward, terminated, truncated, values, None
        final_obs = np.full(self.num_envs, None, dtype=object)
        for i in np.flatnonzero(done):
            final_obs[i] = _row(obs, i)
        self._restart(done)
        return self._write_rows(obs, done), reward, terminated, truncated, values, final_obs

    def _checked(self, actions: Any) -> np.ndarray:
        if self._episode is None:
            raise RuntimeError("call reset() before step()")
        return _check_actions(actions, self.num_envs)

    def _advance(self, a: np.ndarray, stepped: np.ndarray) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray,
                                                                    dict[str, np.ndarray]]:
        """Step the ``stepped`` envs with checked actions ``a`` and commit their state; the others keep
        theirs (zero reward, no flags). Returns observations, rewards, flags and the info terms."""
        w = self.world
        ep = self._episode
        rows = np.arange(self.num_envs)
        f, normal, sideways = self._actuate(a, stepped)
        g = w.response(f, self._response_work)
        z = self._z.copy() if w.dynamics.stateful else self._z      # the creep state is committed per row below
        b = w.dynamics.step(z, g)
        target, sq_ref = self._targets(ep.target_b), self._targets(ep.sq_ref)
        d = np.subtract(b, target, out=self._diff)
        sq = np.sum(np.multiply(d, d, out=d), axis=-1)
        c = a - self._prev
        change = c[:, 0] * c[:, 0] + c[:, 1] * c[:, 1] + c[:, 2] * c[:, 2] + c[:, 3] * c[:, 3]
        reward, shape, force_term, smooth, ratio, force = reward_terms(sq, sq_ref, normal, sideways, change,
                                                                       w.weights, ArrayOps)
        agent_cum = self._agent_cum + ratio
        peak = np.maximum(self._peak, force)
        hi = np.minimum(self._t, w.horizon - 1)
        score = w.score(ep.zero_cum[rows, hi], ep.oracle_cum[rows, hi], agent_cum)
        success = ratio < w.tolerance
        # commit the stepped envs only (next-step autoreset leaves the others to _start below)
        s = stepped
        if s.all():         # every env steps (always in same-step mode): fresh arrays become the state
            self._z, self._b, self._features, self._agent_cum = z, b, f, agent_cum
            # copied: the caller's actions, episode rows, and peak (returned in info)
            self._prev[:], self._last_target[:], self._peak[:] = a, target, peak
            self._t += 1
        else:
            self._z[s], self._b[s], self._prev[s], self._features[s] = z[s], b[s], a[s], f[s]
            self._agent_cum[s], self._peak[s], self._last_target[s] = agent_cum[s], peak[s], target[s]
            self._t[s] += 1
        terminated = (success & w.terminate_on_success) & s
        truncated = (self._t >= w.horizon) & s
        info_values = {"reward_shape": shape, "reward_force": force_term, "reward_smooth": smooth,
                       "shape_error_mm": np.sqrt(sq / w.n_vertices) * 1e3, "force_N": force, "peak_force_N": peak,
                       "is_success": success, "normalized_score": score}
        extra = self._device_terms(info_values)
        reward = reward + extra
        device_obs = self._device_obs()
        if w.obs_mode == "dict":
            obs = self._observe(self._b, self._last_target, device_obs, self._prev)
            shape = w.goal_shape_term(obs["achieved_goal"], obs["desired_goal"])
            reward = shape + (force_term + smooth + extra)
            info_values["reward_shape"] = shape
        else:
            obs = self._observe(self._b, self._upcoming_target(), device_obs, self._prev)
        reward = np.where(s, reward, 0.0)
        return obs, reward, terminated, truncated, info_values

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> Any:
        return self.world.compute_reward(achieved_goal, desired_goal, info)

    def render(self) -> tuple[np.ndarray | None, ...] | None:
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode")
            return None
        if not self._renderers:
            self._renderers = [SceneRenderer(self.world, self.render_mode) for _ in range(self.num_envs)]
        return tuple(r.frame(self._b[i], self._last_target[i], self._features[i], "", self._render_device(i))
                     for i, r in enumerate(self._renderers))

    def close_extras(self, **kwargs: Any) -> None:
        for r in self._renderers:
            r.close()
        self._renderers = []

    # -- the device (the ideal one here; the laryngoscope env overrides these) ---------------------

    def _start_device(self, mask: np.ndarray) -> np.ndarray:
        """Put the masked envs' devices at rest; returns the previous action an episode starts with."""
        return self.world.device.rest_action

    def _actuate(self, a: np.ndarray, stepped: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Apply checked actions (the stepped rows count): force features, normal and sideways force (N)."""
        f = self.world.device.features(a)
        return f, f[:, 2], f[:, 3]

    def _device_obs(self, mask: np.ndarray | None = None) -> np.ndarray:
        """The device part of the observation, of every env or of the masked ones."""
        features = self._features if mask is None else self._features[mask]
        return self.world.device.normalised(features)

    def _device_terms(self, info: dict[str, np.ndarray]) -> Any:
        return 0.0

    def _render_device(self, i: int) -> Any:
        return None

    # -- helpers --------------------------------------------------------------------------------

    def _start(self, mask: np.ndarray) -> None:
        w = self.world
        self._z[mask] = w.b_rest
        self._b[mask] = w.b_rest
        self._features[mask] = w.scene.rest_features
        self._prev[mask] = self._start_device(mask)
        self._t[mask] = 0
        self._agent_cum[mask] = 0.0
        self._peak[mask] = 0.0
        self._last_target[mask] = self._episode.target_b[mask, 0]

    def _restart(self, mask: np.ndarray) -> None:
        """Draw new episodes for the masked envs (from their own generators) and reset their state."""
        idx = np.flatnonzero(mask)
        new = self.world.start_episodes([self._rngs[i] for i in idx])
        ep = self._episode
        for name in ("target_features", "target_b", "sq_ref", "zero_cum", "oracle_cum"):
            getattr(ep, name)[idx] = getattr(new, name)
        self._start(mask)

    def _upcoming_target(self) -> np.ndarray:
        return self._targets(self._episode.target_b)

    def _targets(self, per_step: np.ndarray) -> np.ndarray:
        """Each env's row of an ``(N, T, ...)`` episode array at its current step (a view for reach tasks)."""
        T = per_step.shape[1]
        if T == 1:
            return per_step[:, 0]
        return per_step[np.arange(self.num_envs), np.minimum(self._t, T - 1)]

    def _observe(self, b: np.ndarray, target: np.ndarray, device_obs: np.ndarray, prev: np.ndarray) -> Any:
        return self.world.observe(b, target, device_obs, prev)

    def _write_rows(self, obs: Any, mask: np.ndarray) -> Any:
        """Replace the masked rows of ``obs`` with the fresh episodes' first observations."""
        fresh = self._observe(self._b[mask], self._episode.target_b[mask, 0], self._device_obs(mask), self._prev[mask])
        if isinstance(obs, dict):
            for key in obs:
                obs[key][mask] = fresh[key]
        else:
            obs[mask] = fresh
        return obs


# -- shared checks and info helpers --------------------------------------------------------------


def _check_action_one(action: Any) -> list[float]:
    a = real_array(action, "action", (4,))
    values = a.tolist() if a.dtype.kind == "f" else [float(x) for x in a.tolist()]
    for i, x in enumerate(values):
        if not -1.0 <= x <= 1.0:          # also rejects NaN
            raise ValueError(f"action[{i}] = {x!r}: actions must be finite and within [-1, 1]")
    return values


def _check_actions(actions: Any, n: int) -> np.ndarray:
    a = real_array(actions, "actions", (n, 4)).astype(np.float64, copy=False)
    bad = ~((a >= -1.0) & (a <= 1.0))
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise ValueError(f"actions[{i}, {j}] = {float(a[i, j])!r}: actions must be finite and within [-1, 1]")
    return a


def _autoreset_mode(value: str | AutoresetMode) -> AutoresetMode:
    names = {"next_step": AutoresetMode.NEXT_STEP, "same_step": AutoresetMode.SAME_STEP,
             AutoresetMode.NEXT_STEP.value: AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP.value: AutoresetMode.SAME_STEP}
    mode = value if isinstance(value, AutoresetMode) else names.get(value)
    if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
        raise ValueError(f"autoreset_mode={value!r} is not supported; use 'next_step' or 'same_step' "
                         "(or gymnasium.vector.AutoresetMode.NEXT_STEP / SAME_STEP)")
    return mode


def seeded_episodes(world: World, rngs: list[np.random.Generator], seed: int | list[int | None] | None,
                    options: dict[str, Any] | None) -> tuple[list[np.random.Generator], Any]:
    """A batched reset's generators and episodes: ``seed=s`` seeds env ``i`` with ``s + i``, a list seeds
    each env, ``None`` continues each env's generator (as SyncVectorEnv's reset does). Everything is
    checked before a generator changes."""
    n = len(rngs)
    if seed is None:
        seeds: list[int | None] = [None] * n
    elif isinstance(seed, (int, np.integer)):
        seeds = [int(seed) + i for i in range(n)]
    else:
        seeds = list(seed)
        if len(seeds) != n:
            raise ValueError(f"seed has {len(seeds)} entries; num_envs={n}")
    fresh = [rng if s is None else gym.utils.seeding.np_random(s)[0] for rng, s in zip(rngs, seeds)]
    target = _target_option(world, options)
    return fresh, world.start_episodes(fresh, [target] * n)


def _target_option(world: World, options: dict[str, Any] | None) -> np.ndarray | None:
    if not options:
        return None
    unknown = set(options) - {"target"}
    if unknown:
        raise ValueError(f"unknown reset options {sorted(unknown)}; valid: ['target'] (target force in action units)")
    return world.target_from_action(options["target"])


def _add_masked(infos: dict[str, Any], values: dict[str, np.ndarray], mask: np.ndarray) -> None:
    """Vector-env infos as SyncVectorEnv builds them: zeros where the mask is off, plus ``_key``."""
    if not mask.any():
        return
    everyone = mask.all()
    for key, value in values.items():
        if value.dtype == object:        # per-env nested infos (a dict, None where absent), nested as SyncVectorEnv does
            present = mask & np.array([v is not None for v in value])
            if present.any():
                infos[key], infos[f"_{key}"] = _nested(value, present), present
            continue
        if everyone:
            infos[key] = value.copy()
        else:
            rows = mask.reshape(mask.shape + (1,) * (value.ndim - 1))       # per-env vectors: mask each row
            infos[key] = np.where(rows, value, np.zeros((), dtype=value.dtype))
        infos[f"_{key}"] = mask.copy()


def _nested(value: np.ndarray, present: np.ndarray) -> dict[str, np.ndarray]:
    """The dicts of the ``present`` envs as one dict of per-env arrays (zeros elsewhere) with ``_key`` masks."""
    rows = np.flatnonzero(present)
    out: dict[str, np.ndarray] = {}
    for key, first in value[rows[0]].items():
        column = np.zeros(len(value), dtype=type(first))
        column[rows] = [value[i][key] for i in rows]
        out[key], out[f"_{key}"] = column, present.copy()
    return out


def _row(obs: Any, i: int) -> Any:
    if isinstance(obs, dict):
        return {key: value[i].copy() for key, value in obs.items()}
    return obs[i].copy()
