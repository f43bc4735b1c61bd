"""Demo worker: answers every demo tick after a random wall-clock delay (lock-step demo)."""

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from services.runtime import NodeSpec, ServiceDef, ServiceSettings


class Settings(ServiceSettings):
    """Settings of the demo worker."""

    model_config = SettingsConfigDict(env_prefix="HARVEST_DEMO_WORKER_")

    max_delay_ms: float = Field(
        default=3.0, ge=0, description="Upper bound of a random processing delay (wall clock)."
    )
    modulus: int = Field(default=1000003, gt=1, description="Modulus of the state accumulator.")


SPEC = NodeSpec(
    inputs=("demo/tick",), outputs=("demo/answer",), answers={"demo/tick": ("demo/answer",)}
)


def _make_core(settings: Settings):
    from services.demo_worker.core import DemoWorkerCore

    return DemoWorkerCore(settings)


SERVICE = ServiceDef("demo_worker", Settings, SPEC, make_core=_make_core, description=__doc__ or "")
