"""SoftSphere: press and sweep a tongue-like elastic sphere into a target shape through a force device
(one env class for every device; its batched twin is :mod:`softenv.envs.vector`)."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

from .._ops import ScalarOps
from .checks import check_action_one, check_seed, target_option
from ..sections import SceneConfig
from .config import check_config, scene_config, validate_config
from .rendering import RENDER_MODES, SceneRenderer, check_render_mode
from .task import action_change, normalized_score, reward_terms
from .world import Episodes, World

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

    The env is the task plus a device, chosen by the scene's ``device.kind``
    (:mod:`softenv.devices.base`): ``"ideal"`` (the action is the force), ``"laryngoscope"`` (a
    blade in pymunk moved by a hand through a virtual coupling, levering on the incisors), or a
    ``"module:attribute"`` naming a :class:`~softenv.devices.base.DeviceKind` of your own.

    ## Action Space

    ``Box(-1, 1, (4,), float32)``. Actions outside ``[-1, 1]``, non-finite, or of another shape raise
    ``ValueError`` (nothing is clipped; the env's state is left as it was).

    ``device.kind="ideal"``: mapped linearly onto the device's workspace (``device`` section):

    | index | meaning | -1 | +1 |
    |---|---|---|---|
    | 0 | insertion: contact position along the midline (arc from the front) | 30 deg | 120 deg |
    | 1 | lateral: contact position off the midline | -20 deg | +20 deg |
    | 2 | normal force (pressing) | 0 N | 40 N |
    | 3 | sideways force (toward +y) | -10 N | +10 N |

    ``device.kind="laryngoscope"``: the hand's velocities, in the hand's frame at the start of the
    control period. The hand stops at the walls of its workspace (2.5 cm in, 5 cm out, 4 cm up, down
    to a level blade at the tongue's centre, +-0.5 rad of pitch, +- the radius sideways).

    | index | meaning | +1 |
    |---|---|---|
    | 0 | insert: along the blade toward its tip (-1 withdraws) | ``max_hand_speed`` = 0.2 m/s |
    | 1 | press: along the blade's normal into the tongue (the clinical "lift") | 0.2 m/s |
    | 2 | sweep: sideways, toward +y | ``max_sweep_speed`` = 0.1 m/s |
    | 3 | wrist pitch rate: counter-clockwise, tip down | ``max_pitch_rate`` = 1 rad/s |

    ## Observation Space

    ``obs_mode="vector"`` (default): ``Box(float32, (2 k + d + 4,))`` with finite bounds from the
    response's range (``k`` = the scene's PCA components, 28 at the default scene; ``d`` = the
    device's slice, 4 ideal, 15 laryngoscope):

    | slice | meaning | units |
    |---|---|---|
    | ``[0, k)`` | current shape parameters ``b / sqrt(lambda)`` | PCA standard deviations |
    | ``[k, 2k)`` | target ``b* / sqrt(lambda)`` for the next action | PCA standard deviations |
    | ``[2k, 2k+d)`` | the device's slice (``env.device.obs_names``) | [-1, 1] |
    | ``[2k+d, 2k+d+4)`` | previous action | [-1, 1] |

    The ideal device's slice is the applied force, normalised like the action. The laryngoscope's is
    the blade's pose (x, z, pitch, lateral y) and velocity, the hand's pose, the tongue's normal and
    sideways force and the incisor force, each ``v / (1 + abs(v))`` of ``v`` = value / scale (5 cm,
    0.5 rad, 2 cm, 0.2 m/s, 2 rad/s, 0.1 m/s, ``max_normal_force``, ``max_sideways_force``); poses
    relative to the start pose (:data:`softenv.devices.laryngoscope.LARYNGOSCOPE_OBS`).

    ``obs_mode="dict"``: ``observation`` (the last ``d + 4`` entries), ``achieved_goal``
    (``b / sqrt(lambda)``) and ``desired_goal`` (the target the last step was scored against), with a
    vectorised :meth:`compute_reward` for HER. ``obs_mode="vertices"``: the vector observation
    followed by the ``3 n`` surface coordinates over the radius (decoded only in this mode).

    ## Rewards

    ``reward = shape + force + smooth`` plus the device's terms, with

    | term (``info`` key) | formula | weight argument |
    |---|---|---|
    | ``reward_shape`` | ``-w ||b - b*|| / max(||b* - b_rest||, floor)``: RMS surface error over the target's RMS displacement | ``reward.shape_weight`` = 1 |
    | ``reward_force`` | ``-w max(|F| - F_safe, 0) / F_safe`` (``F``: the tongue's force) | ``reward.force_weight`` = 0, ``reward.safe_force`` = 30 N |
    | ``reward_smooth`` | ``-w ||a - a_prev||^2 / 4`` | ``reward.smoothness_weight`` = 0 |
    | ``reward_incisor`` (laryngoscope) | ``-w F_incisor / F_safe`` (any force on the teeth is an error of technique) | ``reward.incisor_weight`` = 1 |

    Distances are taken in b-space (orthonormal components: equal to the surface distance within the
    model, no vertex rebuilt). ``floor`` is 10 % of the family centre's displacement (keeps the ratio
    finite for small targets in the procedure task).

    ## Starting State

    No force: ``b = b_rest``. The ideal device starts at the middle of the contact range (device
    state ``[0, 0, -1, 0]``); the laryngoscope's blade level, 5 mm above the tongue's top, its heel
    4 cm in front of the tongue's centre line, the hand at the grip, everything at rest. The target
    is drawn from the ``task.split`` cells of the family with the env's ``np_random``;
    ``reset(options={"target": a})`` fixes the target force in the ideal device's action units instead.

    ## Episode End

    * Termination: only with ``task.terminate_on_success=True``, when ``is_success``
      (``shape error < task.tolerance`` x target displacement; default 10 %).
    * Truncation: after ``task.horizon`` steps. The env truncates there itself (the ids register no
      ``max_episode_steps``), so a horizon set through ``gym.make``, ``gym.make_vec`` in any mode, or the
      torch backend is honoured alike; ``max_episode_steps=m`` adds a time limit of ``m`` steps on
      every path, the task keeping its horizon.

    ``info`` at every step: the reward terms, ``shape_error_mm`` (RMS over vertices),
    ``force_N`` (the tongue's force), ``peak_force_N`` (episode so far), ``is_success`` and
    ``normalized_score``: the episode's score so far, 0 for the zero-force policy and 100 for the
    ideal device holding the target's equilibrium force from the first step, from the shape term
    alone; read it at the episode's last step. With creep (viscoelastic scenes) holding the target
    force is not optimal -- the shape lags it -- so a policy that presses harder at first can score
    above 100; a device with mass, coupling and speed limits needs time to get there, so its scores
    stay below 100 (``softenv compare`` normalises by an oracle that plans through the device).

    The laryngoscope adds ``tongue_force_N``, ``incisor_force_N`` (mean over the control period),
    ``haptic_force_N`` (``(3,)``, world x, y, z: what the ``device.haptic_preset`` device would render
    to the hand), ``blade_pose`` (``(4,)``: x, z (m), pitch (rad), lateral y (m)), and at an episode's
    last step ``clinical``, the episode's clinical metrics (:mod:`softenv.devices.laryngoscope.clinical`).

    ## Arguments

    ``gym.make("SoftSphere-v0", render_mode=None, obs_mode="vector", **scene)`` where ``scene`` are
    section dicts merged key by key into the id's scene and :func:`softenv.default_config`
    (``tissue``, ``mesh``, ``shape_model``, ``response``, ``device``, ``dynamics``, ``task``,
    ``reward``, ``airway``, ``render``); e.g. ``gym.make("SoftSphere-v0", tissue={"law": "stiffening"},
    reward={"force_weight": 0.5})`` or ``gym.make("SoftSphere-v0", device={"kind": "laryngoscope"})``.
    Unknown keys or values out of range raise ``ValueError`` listing what is valid.
    ``softenv.describe_config()`` prints every setting with units.

    | id | scene |
    |---|---|
    | ``SoftSphere-v0`` | ideal device, quasi-static tissue, exact response, reach one target |
    | ``SoftSphereViscoelastic-v0`` | as v0 with viscoelastic creep (r = 0.7, tau = 5.8 s, dt = 0.05 s) |
    | ``SoftSphereProcedure-v0`` | as v0 with the target moving insert -> press -> sweep |
    | ``SoftSphereHaptic-v0`` | laryngoscope, dt = 20 ms (20 substeps of 1 ms), reach one target in 250 steps |
    | ``SoftSphereHapticProcedure-v0`` | laryngoscope, the procedure over 500 steps (10 s) |
    | ``SoftSphereAirway-v0`` | as SoftSphereHaptic-v0 on a device range of 60 N and 15 N, for difficult airways: ``airway={"grade": g}``, g = 1 (normal) to 4 (:mod:`softenv.airway`) |

    ## Version History

    * v0: initial release. Since 2026-11-25 the ids register no ``max_episode_steps``
      (``env.spec.max_episode_steps`` is ``None``; read ``env.unwrapped.world.horizon``) and HER's
      ``compute_reward`` includes the device's reward terms. Since 2026-11-28 an ``airway`` section
      (grade 1, the normal airway, leaves every scene as it was: the same keys, caches and anchors),
      and ``SoftSphereAirway-v0``.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 20}

    def __init__(self, render_mode: str | None = None, obs_mode: str = "vector",
                 base_scene: dict[str, Any] | None = None, **scene: Any) -> None:
        self._build(scene_config(base_scene, scene, f"{type(self).__name__}.__init__()"), render_mode, obs_mode)

    def _build(self, config: SceneConfig, render_mode: str | None, obs_mode: str) -> None:
        check_render_mode(render_mode)
        self.world = World(config, obs_mode)
        self.metadata = {**self.metadata, "render_fps": self.world.config["render"]["fps"]}
        self.render_mode = render_mode
        self.action_space = self.world.action_space
        self.observation_space = self.world.observation_space
        self.device = self.world.device_kind.single(self.world.scene, self.world.config)
        if obs_mode == "dict":
            # HER's reward from goals (World.compute_reward): an attribute of dict-observation envs alone, as
            # goal-conditioned tools (SB3's HER and env checker) take any env that has one for a goal env
            self.compute_reward = self.world.compute_reward
        self._renderer: SceneRenderer | None = None
        self._episode: Episodes | None = None

    @classmethod
    def from_config(cls, config: SceneConfig, render_mode: str | None = None,
                    obs_mode: str = "vector") -> SoftSphereEnv:
        """The env of a config already made (:func:`softenv.make_config`): its shape and values checked here,
        not merged from the defaults again; for callers that made a scene once and derive envs from it (the
        trainee wing's replays)."""
        env = cls.__new__(cls)
        env._build(validate_config(check_config(config)), render_mode, obs_mode)
        return env

    # -- gymnasium API --------------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        target = target_option(self.world, options)     # check everything before the seed changes anything
        super().reset(seed=check_seed(seed))
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
        self._prev = self.device.reset()
        self._t, self._agent_cum, self._peak = 0, 0.0, 0.0
        self._last_target = self._target_b[0]
        obs = w.observe(self._b, self._target_b[0], self.device.observation(self._features), self._prev)
        return obs, {}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        if self._episode is None:
            raise RuntimeError("call reset() before step()")
        a = check_action_one(action)
        w, device = self.world, self.device
        f, normal, sideways = device.act(a)
        b = w.dynamics.step(self._z, w.response_one(f))
        t = self._t
        ti = t if t < self._last_index else self._last_index
        target = self._targets[ti]
        d = b - target
        sq = float(_add_reduce(d * d))                   # the batched twin's np.sum(..., axis=-1), row by row
        change = action_change(a, self._prev)
        reward, shape, force_term, smooth, ratio, force = reward_terms(sq, self._sq_ref[ti], normal, sideways, change,
                                                                       w.weights, ScalarOps)
        self._agent_cum += ratio
        self._peak = force if force > self._peak else self._peak
        hi = min(t, w.horizon - 1)
        zero, oracle = self._zero_cum[hi], self._oracle_cum[hi]
        score = normalized_score(zero, oracle, self._agent_cum, ScalarOps)
        success = ratio < w.tolerance
        self._t, self._b, self._prev, self._features, self._last_target = t + 1, b, a, f, target
        info = {"reward_shape": shape, "reward_force": force_term, "reward_smooth": smooth,
                "shape_error_mm": math.sqrt(sq / w.n_vertices) * 1e3, "force_N": force, "peak_force_N": self._peak,
                "is_success": success, "normalized_score": score}
        extra = device.report(info)
        reward += extra
        upcoming = self._targets[t + 1 if t + 1 < self._last_index else self._last_index]
        if w.obs_mode == "dict":
            obs = w.observe(b, target, device.observation(f), a)
            shape = float(w.goal_shape_term(obs["achieved_goal"], obs["desired_goal"]))
            reward = shape + (force_term + smooth + extra)
            info["reward_shape"] = shape
        else:
            obs = w.observe(b, upcoming, device.observation(f), a)
        terminated = w.terminate_on_success and success
        truncated = self._t >= w.horizon
        if terminated or truncated:
            info.update(device.episode_info(b))
        return obs, reward, terminated, truncated, info

    @property
    def b(self) -> np.ndarray:
        """The tissue's shape parameters now (a copy)."""
        if self._episode is None:
            raise RuntimeError("call reset() before reading the shape")
        return np.array(self._b)

    @property
    def target_b(self) -> np.ndarray:
        """The episode's target shape parameters, ``(T, k)`` (``T = 1`` for a reach task; a copy)."""
        if self._episode is None:
            raise RuntimeError("call reset() before reading the target")
        return self._target_b.copy()

    @property
    def success_error_mm(self) -> float:
        """The shape error (mm) under which the next step's target counts as reached (``is_success``):
        ``task.tolerance`` times the target's RMS displacement from rest (floored)."""
        if self._episode is None:
            raise RuntimeError("call reset() before reading the target")
        ti = self._t if self._t < self._last_index else self._last_index
        return self.world.tolerance * math.sqrt(self._sq_ref[ti] / self.world.n_vertices) * 1e3

    @property
    def target_features(self) -> np.ndarray:
        """The episode's target force features, ``(T, 4)`` (a copy)."""
        if self._episode is None:
            raise RuntimeError("call reset() before reading the target")
        return self._target_features.copy()

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' or 'human' to make()")
            return None
        if self._episode is None:
            raise RuntimeError("call reset() before render()")
        if self._renderer is None:
            self._renderer = SceneRenderer(self.world, self.render_mode)
        caption = f"step {self._t}   force {math.hypot(self._features[2], self._features[3]):.1f} N"
        return self._renderer.frame(self._b, self._last_target, np.array(self._features), caption,
                                    self.device.drawing())

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderer"] = None            # figures are rebuilt on demand, never pickled
        return state
