"""The simulation world: the robot in pybullet, orange trees, the D435-like camera, truth."""

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from services.runtime import NodeSpec, ServiceDef, ServiceSettings

CONTROL_PERIOD_NS = 8_333_333  # 120 Hz
CAMERA_EVERY_TICKS = 8  # 8 x 8 333 333 ns = 66.7 ms: 15 Hz


class Settings(ServiceSettings):
    """Settings of the sim."""

    model_config = SettingsConfigDict(env_prefix="HARVEST_SIM_")

    scenario: str = Field(
        default="paper-exp1", description="Scenario name (deploy/scenarios/) or a YAML path."
    )
    seed: int | None = Field(default=None, ge=0, description="Overrides the scenario's seed.")
    fruit_count: int | None = Field(
        default=None, ge=1, le=60, description="Random fruit instead of the scenario's fruit."
    )
    duration_s: float | None = Field(
        default=None, gt=0, description="Sim time after which the sim exits (None: never), s."
    )
    control_period_ns: int = Field(
        default=CONTROL_PERIOD_NS, ge=1_000_000, le=20_000_000, description="Tick, ns (≥ 50 Hz)."
    )
    camera_every_ticks: int = Field(
        default=CAMERA_EVERY_TICKS, ge=1, le=1000, description="A camera frame every N ticks."
    )
    physics_substeps: int = Field(default=2, ge=1, le=20, description="Physics steps per tick.")
    depth_noise: bool = Field(default=True, description="D435-like depth noise and holes.")
    rgb_noise_std: float = Field(default=1.5, ge=0, le=30, description="Colour noise, counts.")
    render_cache: bool = Field(
        default=True, description="Cache still objects between frames (same pixels, faster)."
    )
    contact_sensing: bool = Field(
        default=True,
        description="Each joint state carries the external contacts the arms feel "
        "(JointState.contacts: the link and the point, as an LWR4's joint-torque observer "
        "would estimate them; here exact). False: always empty.",
    )
    cut_tolerance_m: float = Field(
        default=0.015, gt=0, le=0.1, description="Cutter tip to peduncle distance for a cut, m."
    )
    command_max_age_ticks: int = Field(
        default=0,
        ge=0,
        le=100,
        description="Ticks a joint/tool command may lag its stamp and still apply (0: only the "
        "tick it answers, lock-step; ≥ 1 in live mode).",
    )
    basket_empty_after_s: float = Field(
        default=1.0, gt=0, description="A collected fruit is taken out of the basket after, s."
    )


SPEC = NodeSpec(
    inputs=("robot/command", "robot/tool"),
    outputs=("camera/rgbd", "robot/joint_state", "robot/basket", "sim/truth", "sim/events"),
    answers={},
)


def _make_core(settings: Settings):
    from services.sim.core import SimCore

    return SimCore(settings)


SERVICE = ServiceDef(
    "sim", Settings, SPEC, kind="source", make_core=_make_core, description=__doc__ or ""
)
