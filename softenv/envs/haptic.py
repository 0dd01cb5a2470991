"""SoftSphereHaptic: reach a laryngoscopy shape of the tongue through a simulated laryngoscope (the
single env and its natively batched twin, side by side). The tissue, response, targets, dynamics and
reward are SoftSphere's (:mod:`softenv.envs.soft_sphere`); the device is the laryngoscope of
:mod:`softenv.devices.laryngoscope` (this module imports pymunk)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import clinical
from .._ops import ArrayOps, ScalarOps
from ..devices.contact import TongueContact
from ..devices.laryngoscope import Laryngoscope, LaryngoscopeBatch, LaryngoscopeParams
from .soft_sphere import GOAL_TWINS, GoalReward, SoftSphereEnv, SoftSphereVectorEnv
from .world import World

WALL_FACTOR = 1e3       # the saturated tongue's wall: this many times the coupling's stiffness


def device_parts(world: World) -> tuple[LaryngoscopeParams, TongueContact]:
    """The laryngoscope's parameters and contact law for a scene whose device is the laryngoscope."""
    dev = world.config["device"]
    if dev["kind"] != "laryngoscope":
        raise ValueError(f"device.kind={dev['kind']!r}: the SoftSphereHaptic envs drive the laryngoscope; "
                         "use SoftSphere-v0 and its kin for the ideal device")
    contact = TongueContact(world.scene.contact_curve(dev["max_normal_force"]), dev["friction"],
                            wall_stiffness=WALL_FACTOR * dev["coupling_stiffness"])
    return LaryngoscopeParams.from_config(world.config), contact


def glottic_view(world: World, b: np.ndarray) -> float:
    """The glottic-view proxy (%) of one env's shape ``b`` (:func:`softenv.clinical.glottic_view`)."""
    return clinical.glottic_view(clinical.sagittal_profile(world.vertices(b), world.scene.mesh.triangles), 1.0)


class SoftSphereHapticEnv(SoftSphereEnv):
    """
    ## Description

    The SoftSphere task (press and sweep a tongue-like sphere into a laryngoscopy target shape)
    through a simulated laryngoscope. The agent moves a *hand*; the hand drags a Macintosh 3 blade
    (a rigid body in pymunk) through a virtual spring-damper coupling; the blade's underside presses
    the tongue, whose contact force follows the scene's tissue (a held press of ``F`` newtons indents
    it exactly as the response's shape for ``F``); the contact point and force vector give the
    tongue's PCA shape through the scene's response, with creep on top where the scene has it. The
    upper incisors sit above the blade at the mouth: levering on them is possible, and penalised.
    The same physics runs as a 1 kHz haptic loop (:class:`softenv.haptics.HapticLoop`).

    ## Action Space

    ``Box(-1, 1, (4,), float32)``: the hand's velocities, in the hand's frame at the start of the
    control period (``device`` section):

    | index | meaning | +1 |
    |---|---|---|
    | 0 | insert: along the blade toward its tip (-1 withdraws) | ``max_hand_speed`` = 0.2 m/s |
    | 1 | press: along the blade's normal into the tongue (the clinical "lift") | 0.2 m/s |
    | 2 | sweep: sideways, toward +y | ``max_sweep_speed`` = 0.1 m/s |
    | 3 | wrist pitch rate: counter-clockwise, tip down | ``max_pitch_rate`` = 1 rad/s |

    The hand stops at the walls of its workspace (2.5 cm in, beyond which the handle would enter the
    mouth; 5 cm out; 4 cm up; down to a level blade at the tongue's centre; +-0.5 rad of pitch; +- the
    radius sideways). Actions outside
    ``[-1, 1]``, non-finite, or of another shape raise ``ValueError`` and leave the env as it was.

    ## Observation Space

    ``obs_mode="vector"``: ``Box(float32, (2 k + 19,))``:

    | slice | meaning | units |
    |---|---|---|
    | ``[0, k)`` | current shape parameters ``b / sqrt(lambda)`` | PCA standard deviations |
    | ``[k, 2k)`` | target ``b* / sqrt(lambda)`` for the next action | PCA standard deviations |
    | ``[2k, 2k+15)`` | device: blade pose (x, z, pitch, lateral y) and velocity, hand pose (x, z, pitch, y), tongue normal and sideways force, incisor force | ``v / (1 + abs(v))`` of ``v`` = value / scale (5 cm, 0.5 rad, 2 cm, 0.2 m/s, 2 rad/s, 0.1 m/s, ``max_normal_force``, ``max_sideways_force``): in (-1, 1) |
    | ``[2k+15, 2k+19)`` | previous action | [-1, 1] |

    Poses are relative to the start pose; names in :data:`softenv.devices.LARYNGOSCOPE_OBS`.
    ``obs_mode="dict"`` (HER): ``observation`` (the last 19 entries), ``achieved_goal``,
    ``desired_goal``, with a vectorised :meth:`compute_reward`; ``"vertices"`` appends the surface.

    ## Rewards

    ``reward = shape + force + smooth + incisor``: SoftSphere's terms (``reward_shape``,
    ``reward_force`` on the tongue force above ``reward.safe_force``, ``reward_smooth``) plus

    | term (``info`` key) | formula | weight argument |
    |---|---|---|
    | ``reward_incisor`` | ``-w F_incisor / F_safe`` (any force on the teeth is an error of technique) | ``reward.incisor_weight`` = 1 |

    ``normalized_score`` keeps SoftSphere's running anchors: 0 = no motion (the blade never touches,
    the shape stays at rest), 100 = the ideal device holding the target's equilibrium shape from the
    first step. A device with mass, coupling and speed limits needs time to get there, so scores here
    stay below 100. ``softenv compare`` normalizes by its oracle that plans every episode through this
    device instead (``baselines.planner.TrajectoryOracle``).

    ## Starting State

    Blade level, 5 mm above the tongue's top, its heel 4 cm in front of the tongue's centre line
    (tip over the back of the tongue); the hand at the grip, everything at rest, no contact (so the
    shape is ``b_rest``). The target is drawn as in SoftSphere (``reset(options={"target": a})``
    fixes it in the ideal device's action units).

    ## Episode End

    * Termination: only with ``task.terminate_on_success=True``, on ``is_success``.
    * Truncation: after ``task.horizon`` steps (``SoftSphereHaptic-v0``: 250 steps of 20 ms = 5 s;
      ``SoftSphereHapticProcedure-v0``: 500 = 10 s).

    ``info`` at every step: SoftSphere's keys (``force_N`` is the tongue force), plus
    ``tongue_force_N`` (contact force on the tongue, N), ``incisor_force_N`` (mean over the control
    period, N), ``haptic_force_N`` (``(3,)``, world x, y, z: the force the ``device.haptic_preset``
    device would render to the hand, N), ``blade_pose`` (``(4,)``: x, z (m), pitch (rad), lateral y
    (m) of the blade's centre of mass; the tongue's centre is the origin). At an episode's last step
    (success or the horizon): ``clinical``, the episode's clinical metrics (:mod:`softenv.clinical`).

    ## Arguments

    ``gym.make("SoftSphereHaptic-v0", render_mode=None, obs_mode="vector", **scene)``; the scene's
    ``device`` section holds the laryngoscope's parameters (masses, coupling stiffness and damping,
    speed limits, friction, substep, haptic preset; ``softenv.describe_config()`` lists them with
    units and ranges). Scene sections merge key by key into the id's own.

    | id | scene |
    |---|---|
    | ``SoftSphereHaptic-v0`` | laryngoscope, quasi-static tissue, exact response, reach one target; dt = 20 ms |
    | ``SoftSphereHapticProcedure-v0`` | as above, the target moving insert -> press -> sweep over 10 s |

    ## Version History

    * v0: initial release.
    """

    def __init__(self, render_mode: str | None = None, obs_mode: str = "vector",
                 base_scene: dict[str, Any] | None = None, **scene: Any) -> None:
        super().__init__(render_mode, obs_mode, base_scene, **scene)
        self.laryngoscope = Laryngoscope(*device_parts(self.world))
        self._box = (self.world.scene.workspace.low, self.world.scene.workspace.high)
        self._rest = self.world.scene.rest_features.tolist()
        self.clinical = clinical.ClinicalRecorder(1, self.world.config["dynamics"]["dt"], self.world.horizon)

    def _start_device(self) -> list[float]:
        self.laryngoscope.reset()
        self.clinical.start(0, self.laryngoscope._clinical(ScalarOps))
        return [0.0, 0.0, 0.0, 0.0]

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = super().step(action)
        self.clinical.record_one(self.laryngoscope._clinical(ScalarOps))
        if terminated or truncated:
            info["clinical"] = self.clinical_summary()
        return obs, reward, terminated, truncated, info

    def clinical_summary(self) -> dict[str, float]:
        """The episode's clinical metrics so far (:mod:`softenv.clinical`); in ``info["clinical"]`` at
        its last step."""
        return self.clinical.summary(0, glottic_view(self.world, self._b))

    def _actuate(self, a: list[float]) -> tuple[list[float], float, float]:
        dev = self.laryngoscope
        dev.control_step(a)
        f = dev.features()
        P, Q = dev.normal_force, dev.sideways_force
        if f is None:
            return self._rest, P, Q
        lo, hi = self._box
        return [min(max(x, low), high) for x, low, high in zip(f, lo, hi)], P, Q

    def _device_obs(self, features: list[float]) -> list[float]:
        return self.laryngoscope.observation()

    def _device_terms(self, info: dict[str, Any]) -> float:
        dev, w = self.laryngoscope, self.world.weights
        incisor = dev.incisor_force
        term = -w["incisor_weight"] * (incisor / w["safe_force"])
        info.update({"reward_incisor": term, "tongue_force_N": dev.tongue_force, "incisor_force_N": incisor,
                     "haptic_force_N": dev.haptic_force()[0], "blade_pose": dev.blade_pose()[0]})
        return term

    def _render_device(self) -> Any:
        return self.laryngoscope.drawing()[0]

    def __getstate__(self) -> dict[str, Any]:
        state = super().__getstate__()
        state["laryngoscope"] = self.laryngoscope.state()          # pymunk's space is rebuilt, not pickled
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        device_state = state.pop("laryngoscope")
        self.__dict__.update(state)
        self.laryngoscope = Laryngoscope(*device_parts(self.world))
        self.laryngoscope.load_state(device_state)


class SoftSphereHapticGoalEnv(GoalReward, SoftSphereHapticEnv):
    """:class:`SoftSphereHapticEnv` with ``obs_mode="dict"`` (made by it): adds HER's ``compute_reward``."""


GOAL_TWINS[SoftSphereHapticEnv] = SoftSphereHapticGoalEnv


class SoftSphereHapticVectorEnv(SoftSphereVectorEnv):
    """``num_envs`` SoftSphereHaptic envs in one pymunk space, stepped with numpy and ``pymunk.batch``.

    Seeding, autoreset modes and infos as :class:`~softenv.envs.soft_sphere.SoftSphereVectorEnv`.
    Env 0 equals a single :class:`SoftSphereHapticEnv` seeded alike bit for bit; env ``i`` sits at
    its own place in the shared space (1 m apart), which changes the rounding of its positions, so it
    agrees with a single env to rounding only (see :mod:`softenv.devices.laryngoscope`).
    """

    episode_end_info_keys = ("clinical",)

    def __init__(self, num_envs: int = 1, render_mode: str | None = None, obs_mode: str = "vector",
                 max_episode_steps: int | None = None, autoreset_mode: Any = "next_step",
                 base_scene: dict[str, Any] | None = None, **scene: Any) -> None:
        super().__init__(num_envs, render_mode, obs_mode, max_episode_steps, autoreset_mode, base_scene, **scene)
        self.laryngoscopes = LaryngoscopeBatch(*device_parts(self.world), self.num_envs)
        self._start_state = self.laryngoscopes.start_state(self.num_envs)
        self.clinical = clinical.ClinicalRecorder(self.num_envs, self.world.config["dynamics"]["dt"],
                                                  self.world.horizon)

    def _start_device(self, mask: np.ndarray) -> np.ndarray:
        self.laryngoscopes.load_state(self._start_state, rows=mask)
        self.clinical.start(mask, self._clinical_values()[mask])
        return np.zeros(4)

    def _clinical_values(self) -> np.ndarray:
        return np.stack(np.broadcast_arrays(*self.laryngoscopes._clinical(ArrayOps)), axis=1)

    def _advance(self, a: np.ndarray, stepped: np.ndarray) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray,
                                                                    dict[str, np.ndarray]]:
        obs, reward, terminated, truncated, values = super()._advance(a, stepped)
        rows = np.flatnonzero(stepped)
        self.clinical.record(rows, self._clinical_values()[rows])
        done = terminated | truncated
        if done.any():                                 # the episode's clinical metrics where it ends
            summaries = np.full(self.num_envs, None, dtype=object)
            for i in np.flatnonzero(done):
                summaries[i] = self.clinical_summary(int(i))
            values["clinical"] = summaries
        return obs, reward, terminated, truncated, values

    def clinical_summary(self, i: int) -> dict[str, float]:
        """Env ``i``'s episode so far (see :meth:`SoftSphereHapticEnv.clinical_summary`)."""
        return self.clinical.summary(i, glottic_view(self.world, self._b[i]))

    def _actuate(self, a: np.ndarray, stepped: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        dev, scene = self.laryngoscopes, self.world.scene
        dev.control_step(a, moving=stepped)
        features, touching = dev.features()
        clipped = np.minimum(np.maximum(features, scene.workspace.low), scene.workspace.high)
        return np.where(touching[:, None], clipped, scene.rest_features), dev.normal_force, dev.sideways_force

    def _device_obs(self, mask: np.ndarray | None = None) -> np.ndarray:
        obs = self.laryngoscopes.observation()
        return obs if mask is None else obs[mask]

    def _device_terms(self, info: dict[str, np.ndarray]) -> np.ndarray:
        dev, w = self.laryngoscopes, self.world.weights
        incisor = dev.incisor_force
        term = -w["incisor_weight"] * (incisor / w["safe_force"])
        info.update({"reward_incisor": term, "tongue_force_N": dev.tongue_force, "incisor_force_N": incisor,
                     "haptic_force_N": dev.haptic_force(), "blade_pose": dev.blade_pose()})
        return term

    def _render_device(self, i: int) -> Any:
        return self.laryngoscopes.drawing()[i]
