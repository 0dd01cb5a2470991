"""The batched SoftSphere env: ``num_envs`` envs stepped together in numpy, any device (the device's
batch form, :class:`softenv.devices.base.DeviceBatch`), the single env's physics bit for bit."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .._ops import ArrayOps
from .batching import (add_masked, disabled_step_check, episode_limit, obs_copy, obs_row, reset_mask_option,
                       seeded_episodes)
from .checks import check_actions
from .batching import autoreset_mode as autoreset_mode_of
from .config import scene_config
from .rendering import RENDER_MODES, SceneRenderer, check_render_mode
from .task import action_change, normalized_score, reward_terms
from .world import World


class SoftSphereVectorEnv(VectorEnv):
    """``num_envs`` SoftSphere envs stepped together in numpy, with the scene's device in its batch form.

    Seeding follows Gymnasium's vector envs: ``reset(seed=s)`` seeds env ``i`` with ``s + i``, so
    this env equals ``num_envs`` :class:`~softenv.envs.single.SoftSphereEnv` seeded alike
    (observations, rewards, flags and infos) bit for bit, the laryngoscope included on its default
    engine (``device.batch_engine``: ``"compiled"`` or ``"numpy"``; with ``"pymunk"``, one space, env 0
    does and the others agree to rounding: :mod:`softenv.devices.laryngoscope.part`). ``backend="torch"`` through ``gym.make_vec``
    makes the torch twin instead (:func:`softenv.envs.make.make_vector_env`). Episodes end after the
    scene's ``task.horizon`` steps, or after ``max_episode_steps`` where that is fewer (a time limit, as
    ``gym.make(..., max_episode_steps=m)`` puts on the single env; the task keeps its horizon).
    ``autoreset_mode``: ``"next_step"`` (Gymnasium's default: the step after an episode ends resets
    that env and ignores its action) or ``"same_step"`` (reset at once; ``info["final_obs"]`` and
    ``info["final_info"]`` hold the last observation and info, as SB3 needs) or ``"disabled"`` (an ended
    env is not reset: the caller resets it with ``reset(options={"reset_mask": mask})``, which resets the
    masked envs only, seeds as ``reset`` does, and returns every env's observation; stepping an ended env
    first is refused). Infos are dicts of
    arrays with ``_key`` masks, as :class:`gymnasium.vector.SyncVectorEnv` makes them.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 20, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, render_mode: str | None = None, obs_mode: str = "vector",
                 max_episode_steps: int | None = None, autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
                 base_scene: dict[str, Any] | None = None, **scene: Any) -> None:
        if not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs={num_envs!r} must be an int >= 1")
        check_render_mode(render_mode)
        self.world = World(scene_config(base_scene, scene, f"{type(self).__name__}.__init__()"), obs_mode)
        self.max_episode_steps = episode_limit(max_episode_steps, self.world.horizon)
        self.autoreset_mode = autoreset_mode_of(autoreset_mode)
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
        self._last_obs: Any = None            # what step() or reset() returned last (autoreset_mode="disabled")
        self._episode: Any = None            # the episodes' arrays (world.Episodes) once reset() ran
        # the step's large temporaries, reused (see TableWork: fresh ones can cost a page fault a page)
        self._response_work = self.world.response_work(n)
        self._diff = np.empty((n, k))
        self._renderers: list[SceneRenderer] = []
        self.device = self.world.device_kind.batch(self.world.scene, self.world.config, n)

    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        mask, options = reset_mask_option(options, self.num_envs, self.autoreset_mode)
        if mask is None:
            self._rngs, self._episode = seeded_episodes(self.world, self._rngs, seed, options)
            self._start(np.ones(self.num_envs, dtype=bool))
            obs = self._observe(self._b, self._upcoming_target(), self._device_obs(), self._prev)
        else:
            if self._episode is None:
                raise RuntimeError("call reset() without a reset_mask first: there are no episodes to go on from")
            self._rngs, new = seeded_episodes(self.world, self._rngs, seed, options, mask)
            self._restart(mask, new)
            obs = self._write_rows(obs_copy(self._last_obs), mask)
        self._autoreset[mask if mask is not None else slice(None)] = False
        if self.autoreset_mode == AutoresetMode.DISABLED:
            self._last_obs = obs_copy(obs)
        return obs, {}

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        infos: dict[str, Any] = {}
        if self.autoreset_mode == AutoresetMode.SAME_STEP:
            obs, reward, terminated, truncated, values, final_obs = self.step_values(actions)
            done = terminated | truncated
            add_masked(infos, values, ~done)
            if final_obs is not None:
                final_info: dict[str, Any] = {}
                add_masked(final_info, values, done)
                infos.update({"final_obs": final_obs, "_final_obs": done.copy(), "final_info": final_info,
                              "_final_info": done.copy()})
            return obs, reward, terminated, truncated, infos
        a = self._checked(actions)
        if self.autoreset_mode == AutoresetMode.DISABLED:
            disabled_step_check(self._autoreset)
            obs, reward, terminated, truncated, values = self._advance(a, np.ones(self.num_envs, dtype=bool))
            add_masked(infos, values, np.ones(self.num_envs, dtype=bool))
            self._autoreset, self._last_obs = terminated | truncated, obs_copy(obs)
            return obs, reward, terminated, truncated, infos
        reset_now = self._autoreset.copy()
        obs, reward, terminated, truncated, values = self._advance(a, ~reset_now)
        if reset_now.any():               # next-step autoreset: these envs ignored their action and restart now
            self._restart(reset_now)
            obs = self._write_rows(obs, reset_now)
        add_masked(infos, values, ~reset_now)
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
            final_obs[i] = obs_row(obs, int(i))
        self._restart(done)
        return self._write_rows(obs, done), reward, terminated, truncated, values, final_obs

    def _checked(self, actions: Any) -> np.ndarray:
        if self._episode is None:
            raise RuntimeError("call reset() before step()")
        return check_actions(actions, self.num_envs)

    def _advance(self, a: np.ndarray, stepped: np.ndarray) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray,
                                                                    dict[str, np.ndarray]]:
        """Step the ``stepped`` envs with checked actions ``a`` and commit their state; the others keep
        theirs (zero reward, no flags). Returns observations, rewards, flags and the info terms."""
        w = self.world
        ep = self._episode
        rows = np.arange(self.num_envs)
        device = self.device
        f, normal, sideways = device.act(a, stepped)
        g = w.response(f, self._response_work)
        z = self._z.copy() if w.dynamics.stateful else self._z      # the creep state is committed per row below
        b = w.dynamics.step(z, g)
        target, sq_ref = self._targets(ep.target_b), self._targets(ep.sq_ref)
        d = np.subtract(b, target, out=self._diff)
        sq = np.sum(np.multiply(d, d, out=d), axis=-1)
        change = action_change(a.T, self._prev.T)
        reward, shape, force_term, smooth, ratio, force = reward_terms(sq, sq_ref, normal, sideways, change,
                                                                       w.weights, ArrayOps)
        agent_cum = self._agent_cum + ratio
        peak = np.maximum(self._peak, force)
        hi = np.minimum(self._t, w.horizon - 1)
        score = normalized_score(ep.zero_cum[rows, hi], ep.oracle_cum[rows, hi], agent_cum, ArrayOps)
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
        truncated = (self._t >= self.max_episode_steps) & s
        info_values = {"reward_shape": shape, "reward_force": force_term, "reward_smooth": smooth,
                       "shape_error_mm": np.sqrt(sq / w.n_vertices) * 1e3, "force_N": force, "peak_force_N": peak,
                       "is_success": success, "normalized_score": score}
        extra = device.report(info_values, s)
        reward = reward + extra
        # the device's episode record where the task ends an episode (a shorter max_episode_steps ends it
        # from outside, without one, as TimeLimit does to the single env)
        ended = truncated if self.max_episode_steps == w.horizon else (self._t >= w.horizon) & s
        done = terminated | ended
        if device.episode_info_keys and done.any():
            ended = np.flatnonzero(done)
            records = {int(i): device.episode_info(int(i), self._b[i]) for i in ended}
            for key in device.episode_info_keys:
                column = np.full(self.num_envs, None, dtype=object)
                for i, record in records.items():
                    column[i] = record[key]
                info_values[key] = column
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

    def render(self) -> tuple[Any, ...] | None:
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode")
            return None
        if not self._renderers:
            self._renderers = [SceneRenderer(self.world, self.render_mode) for _ in range(self.num_envs)]
        return tuple(r.frame(self._b[i], self._last_target[i], self._features[i], "", self.device.drawing(i))
                     for i, r in enumerate(self._renderers))

    def close_extras(self, **kwargs: Any) -> None:
        for r in self._renderers:
            r.close()
        self._renderers = []

    def _device_obs(self, mask: np.ndarray | None = None) -> np.ndarray:
        """The device part of the observation, of every env or of the masked ones."""
        features = self._features if mask is None else self._features[mask]
        return self.device.observation(features, mask)

    # -- helpers --------------------------------------------------------------------------------

    def _start(self, mask: np.ndarray) -> None:
        w = self.world
        self._z[mask] = w.b_rest
        self._b[mask] = w.b_rest
        self._features[mask] = w.scene.rest_features
        self._prev[mask] = self.device.reset(mask)
        self._t[mask] = 0
        self._agent_cum[mask] = 0.0
        self._peak[mask] = 0.0
        self._last_target[mask] = self._episode.target_b[mask, 0]

    def _restart(self, mask: np.ndarray, new: Any = None) -> None:
        """Start the masked envs' episodes ``new`` (default: drawn from their own generators) and reset their state."""
        idx = np.flatnonzero(mask)
        new = self.world.start_episodes([self._rngs[i] for i in idx]) if new is None else new
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
