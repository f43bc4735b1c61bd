"""Dual-arm hierarchical QP controller (paper §IV): absolute task (cutter pose) strictly above
the relative task (collector pose in the cutter frame), joint limits, self-collision and
velocity dampers against trunk and fruit, a watchdog. One command and one status per joint
state."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, model_validator
from pydantic_settings import SettingsConfigDict

from services.runtime import NodeSpec, ServiceDef, ServiceSettings


class DamperGroup(BaseModel):
    """Velocity-damper parameters of one kind of pair (paper eq. (7)): d_i, d_s, ξ."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    activation_m: float = Field(gt=0, description="d_i: the damper acts below this distance, m.")
    safety_m: float = Field(ge=0, description="d_s: the distance never to go below, m.")
    speed_m_s: float = Field(gt=0, description="ξ: approach speed allowed at d_i, m/s.")

    @model_validator(mode="after")
    def _ordered(self) -> DamperGroup:
        if self.activation_m <= self.safety_m:
            raise ValueError(
                f"activation_m {self.activation_m} must exceed safety_m {self.safety_m}"
            )
        return self


class Settings(ServiceSettings):
    """Settings of the controller. Gains in 1/s, speeds in m/s and rad/s, distances in m."""

    model_config = SettingsConfigDict(env_prefix="HARVEST_CONTROLLER_")

    urdf_path: str = Field(default="", description="Robot URDF; empty: deploy/robot/bazar.urdf.")
    nominal_period_s: float = Field(
        default=1 / 120, gt=0, description="Control period used on the first tick, s."
    )
    joint_state_timeout_ms: float = Field(
        default=100.0, gt=0, description="Watchdog: joint states older than this stop the arms."
    )
    target_timeout_ms: float = Field(
        default=100.0, gt=0, description="Watchdog: a plan target older than this stops the arms."
    )
    watchdog_check_period_ms: float = Field(
        default=20.0, gt=0, description="Live mode: how often the wall-clock watchdog looks, ms."
    )
    require_scene: bool = Field(
        default=True, description="Hold until a scene state (the obstacle set) has arrived."
    )
    # --- task-space law (paper: ẋ = K e) -----------------------------------------------------
    abs_gain_per_s: float = Field(default=3.0, gt=0, description="K of the absolute task, 1/s.")
    rel_gain_per_s: float = Field(default=5.0, gt=0, description="K of the relative task, 1/s.")
    max_tool_speed_m_s: float = Field(default=0.25, gt=0, description="Cutter speed cap, m/s.")
    max_tool_rate_rad_s: float = Field(default=1.0, gt=0, description="Cutter rotation cap, rad/s.")
    max_relative_speed_m_s: float = Field(
        default=0.25, gt=0, description="Collector-in-cutter speed cap, m/s."
    )
    max_relative_rate_rad_s: float = Field(
        default=1.0, gt=0, description="Collector-in-cutter rotation cap, rad/s."
    )
    joint_gain_per_s: float = Field(
        default=3.0, gt=0, description="K of a joint goal (the planner retracing a path), 1/s."
    )
    joint_speed_fraction: float = Field(
        default=0.5,
        gt=0,
        le=1,
        description="A joint goal moves each joint at most this fraction of its velocity limit.",
    )
    converged_position_m: float = Field(
        default=0.001, gt=0, description="Converged: both position errors below this, m."
    )
    converged_orientation_rad: float = Field(
        default=0.01, gt=0, description="Converged: both orientation errors below this, rad."
    )
    # --- QP ---------------------------------------------------------------------------------
    abs_position_weight: float = Field(default=1.0, gt=0, description="Solve 1 weight, m⁻².")
    abs_orientation_weight: float = Field(default=1.0, gt=0, description="Solve 1 weight, rad⁻².")
    rel_position_weight: float = Field(default=1.0, gt=0, description="Solve 2 weight, m⁻².")
    rel_orientation_weight: float = Field(default=1.0, gt=0, description="Solve 2 weight, rad⁻².")
    regularization_abs: float = Field(
        default=1e-6, gt=0, description="‖Δq‖² weight in solve 1 (rad⁻²)."
    )
    regularization_rel: float = Field(
        default=1e-4, gt=0, description="‖Δq‖² weight in solve 2 (rad⁻²); ≪ the relative weights."
    )
    soft_damper_weight: float = Field(
        default=1e4, gt=0, description="Fallback: weight of the dampers' slack when softened."
    )
    max_joint_acceleration_rad_s2: float | None = Field(
        default=None,
        gt=0,
        description="Each joint's command may change by at most this times the control period "
        "from the last command sent (a hold counts as zero), rad/s²; None: no bound. A soft "
        "bound (acceleration_weight) under the hard limits and dampers: a damper that must stop "
        "a link at once still can. Without it the QP's step can flip a wrist joint from +v_max "
        "to -v_max from one tick to the next, which no arm follows. Off by default: on the "
        "orchard, 15 rad/s² had fewer collisions but harvested fewer fruit (BENCHMARKS.md, "
        "Harvest, session 43).",
    )
    acceleration_weight: float = Field(
        default=1e3,
        gt=0,
        description="Weight of the acceleration bound's slack (rad⁻²): far above the task "
        "weights (per-step errors of mm), below soft_damper_weight.",
    )
    limit_margin_rad: float = Field(
        default=0.0,
        ge=0,
        description="A joint closer than this to a position limit is asked (softly, "
        "limit_weight) to move away at limit_gain_per_s times how far it is inside the margin, "
        "in a third solve that holds both tasks' rows: only the tasks' free directions (the "
        "cutter's turn about the vertical, the arms' redundancy) are used, to keep an elbow "
        "off its stop before the goal needs it there. 0: off (no third solve).",
    )
    limit_gain_per_s: float = Field(
        default=1.0, gt=0, description="Speed away from a limit per rad inside the margin, 1/s."
    )
    limit_weight: float = Field(
        default=100.0,
        gt=0,
        description="Weight of the limit rows' slack in solve 3 against 1 for each joint's "
        "distance from solve 2's step (rad⁻²).",
    )
    # --- collision avoidance (paper eq. (7)–(8)) -------------------------------------------
    trunk: DamperGroup = Field(
        default=DamperGroup(activation_m=0.15, safety_m=0.03, speed_m_s=0.3),
        description="Dampers robot–trunk cylinder.",
    )
    fruit: DamperGroup = Field(
        default=DamperGroup(activation_m=0.10, safety_m=0.02, speed_m_s=0.3),
        description="Dampers robot–fruit ellipsoid (except ignore_fruit_ids).",
    )
    branch: DamperGroup = Field(
        default=DamperGroup(activation_m=0.08, safety_m=0.015, speed_m_s=0.3),
        description="Dampers robot–occupied-space sphere (branches seen in depth).",
    )
    branch_pairs_per_body: int = Field(
        default=3,
        ge=1,
        le=64,
        description="Occupied-space spheres per robot body given a distance and a damper: its "
        "nearest ones (a branch is many adjacent spheres; the nearest guard the rest, and the "
        "cycle's cost stays bounded).",
    )
    contact_reflex: bool = Field(
        default=False,
        description="Hold each place the arms feel (the joint state's contacts), outside the "
        "inner working space of the fruit worked on, as a damper sphere from the tick that "
        "reports it (reflex.py): the link backs off at once instead of when the scene's next "
        "state carries the place (up to 8 ticks later). Off: the obstacle set is the scene's.",
    )
    contact_reflex_radius_m: float = Field(
        default=0.01, ge=0.002, le=0.1, description="… a felt place's sphere radius, m."
    )
    contact_reflex_voxel_m: float = Field(
        default=0.02, gt=0.002, le=0.2, description="… felt points are binned at this size, m."
    )
    contact_reflex_hold_ms: float = Field(
        default=500.0, gt=0, description="… a sphere is held this long after last felt, ms."
    )
    contact_reflex_inner_clearance_m: float = Field(
        default=0.05,
        ge=0,
        le=1,
        description="… no sphere within d_v plus this of the worked fruit's centre, nor of its "
        "twig up to d_v plus contact_reflex_inner_twig_m above it (the scene's "
        "occupancy_inner_clearance_m), m.",
    )
    contact_reflex_inner_twig_m: float = Field(
        default=0.10, ge=0, le=0.5, description="See contact_reflex_inner_clearance_m, m."
    )
    contact_reflex_max_spheres: int = Field(
        default=32, ge=1, le=256, description="… at most this many spheres (the latest felt)."
    )
    self_collision: DamperGroup = Field(
        default=DamperGroup(activation_m=0.08, safety_m=0.01, speed_m_s=0.3),
        description="Dampers for the self-collision pairs of collisions.json.",
    )
    damper_margin_m: float = Field(
        default=0.0005,
        ge=0,
        description="Added to every d_s inside the damper law: absorbs the per-step loss to "
        "surface curvature of the linearised law (about 20 µm at 2 mm per step), m.",
    )
    cull_distance_m: float = Field(
        default=0.25,
        gt=0,
        description="Broad phase: obstacle pairs farther than this (lower bound) are skipped, m.",
    )
    min_obstacle_size_m: float = Field(
        default=0.001, gt=0, description="Smaller radius / semi-axis: the scene is refused, m."
    )
    max_obstacle_size_m: float = Field(
        default=2.0, gt=0, description="Larger radius / semi-axis: the scene is refused, m."
    )
    max_obstacles: int = Field(
        default=500,
        gt=0,
        description="More obstacles than this: the scene is refused (and counted). The tick's "
        "cost grows with the count; a 10,000-obstacle scene took over a minute per tick.",
    )
    # --- workspace (targets outside are refused) -------------------------------------------
    workspace_min_world_m: tuple[float, float, float] = Field(
        default=(-0.2, -1.2, 0.3), description="Lower corner of the cutter target box, world, m."
    )
    workspace_max_world_m: tuple[float, float, float] = Field(
        default=(1.6, 1.2, 2.4), description="Upper corner of the cutter target box, world, m."
    )
    max_relative_distance_m: float = Field(
        default=0.6, gt=0, description="Farthest relative target from the cutter tip, m."
    )
    publish_diagnostics: bool = Field(
        default=True, description="Publish diag/controller (timings, counters) every tick."
    )

    @model_validator(mode="after")
    def _cull_covers_dampers(self) -> Settings:
        need = max(self.trunk.activation_m, self.fruit.activation_m, self.branch.activation_m)
        if self.cull_distance_m < need:
            raise ValueError(
                f"cull_distance_m {self.cull_distance_m} < an activation distance {need}"
            )
        return self


SPEC = NodeSpec(
    inputs=("robot/joint_state", "plan/target", "scene/state"),
    outputs=("robot/command", "control/status", "diag/controller"),
    answers={"robot/joint_state": ("robot/command", "control/status")},
    # live mode: act on the freshest state only (lock-step never drops anything)
    conflate=("robot/joint_state", "plan/target", "scene/state"),
)


def _make_core(settings: Settings):
    from services.controller.core import ControllerCore

    return ControllerCore(settings)


SERVICE = ServiceDef(
    "controller", Settings, SPEC, kind="reactive", make_core=_make_core, description=__doc__ or ""
)
