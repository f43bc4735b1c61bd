"""Demo clock master: the foundation's lock-step demo source (replaced by the sim later)."""

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from services.runtime import NodeSpec, ServiceDef, ServiceSettings


class Settings(ServiceSettings):
    """Settings of the demo clock."""

    model_config = SettingsConfigDict(env_prefix="HARVEST_DEMO_CLOCK_")

    ticks: int = Field(default=200, ge=1, description="Ticks to run before exiting.")
    period_ms: float = Field(default=10.0, gt=0, description="Sim time per tick, ms.")
    seed: int = Field(default=7, description="Seed of the initial value.")
    gain: float = Field(default=0.5, description="Feedback gain applied to the worker's answer.")


SPEC = NodeSpec(inputs=("demo/answer",), outputs=("demo/tick",))


def _make_core(settings: Settings):
    from services.demo_clock.core import DemoClockCore

    return DemoClockCore(settings)


SERVICE = ServiceDef(
    "demo_clock", Settings, SPEC, kind="source", make_core=_make_core, description=__doc__ or ""
)
