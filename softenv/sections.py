"""The scene config's sections as typed dicts: what ``softenv.make_config`` returns and every part of the
package reads, so that mypy checks each key's name and type. ``softenv.envs.config.SCHEMA`` holds each
key's default, unit, range and check; ``tests/test_config.py`` holds these to it, key for key."""

from __future__ import annotations

from typing import TypedDict


class TissueSection(TypedDict):
    model: str                          # analytic | fem
    law: str                            # linear | neo_hookean
    E: float | None                     # Pa (None: the law's default)
    nu: float | None
    radius: float                       # m
    patch_radius: float                 # m
    fe_cells: int


class MeshSection(TypedDict):
    kind: str
    resolution: int


class ShapeModelSection(TypedDict):
    n_components: float                 # a count, or a share of the variance below 1
    n_contacts: int
    n_loads: int
    seed: int


class ResponseSection(TypedDict):
    model: str
    table_nodes: tuple[int, ...]


class DeviceSection(TypedDict):
    kind: str
    insertion_deg: tuple[float, float]
    lateral_deg: float
    max_normal_force: float             # N
    max_sideways_force: float           # N
    blade_mass: float                   # kg
    handle_mass: float                  # kg
    coupling_stiffness: float           # N/m
    coupling_damping: float             # N s/m
    rotational_stiffness: float         # N m/rad
    rotational_damping: float           # N m s/rad
    max_hand_speed: float               # m/s
    max_sweep_speed: float              # m/s
    max_pitch_rate: float               # rad/s
    friction: float
    max_substep: float                  # s
    haptic_preset: str
    batch_engine: str


class DynamicsSection(TypedDict):
    kind: str
    dt: float                           # s
    relaxed_fraction: float
    time_constant: float                # s


class TaskSection(TypedDict):
    kind: str
    split: str
    horizon: int                        # steps
    tolerance: float
    terminate_on_success: bool
    target_insertion_deg: tuple[float, float]
    target_lateral_deg: tuple[float, float]
    target_normal_force: tuple[float, float]      # N
    target_sideways_force: tuple[float, float]    # N


class RewardSection(TypedDict):
    shape_weight: float
    force_weight: float
    safe_force: float                   # N
    smoothness_weight: float
    incisor_weight: float


class AirwaySection(TypedDict):
    grade: int                          # 1-4 (softenv.airway.GRADES)
    mouth_opening: float | None         # mm (None: the grade's)
    neck_extension: float | None        # rad
    larynx_depth: float | None          # deg
    larynx_lift: float | None
    tongue_stiffness: float | None
    interincisal_gap: float | None      # mm


class RenderSection(TypedDict):
    size: int                           # px
    fps: int                            # 1/s


class SceneConfig(TypedDict):
    """A whole scene, every section checked and complete (``softenv.make_config``)."""

    tissue: TissueSection
    mesh: MeshSection
    shape_model: ShapeModelSection
    response: ResponseSection
    device: DeviceSection
    dynamics: DynamicsSection
    task: TaskSection
    reward: RewardSection
    airway: AirwaySection
    render: RenderSection
