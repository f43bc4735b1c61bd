"""The bus layer: the only code that imports zenoh (sessions, typed pub/sub, health, status)."""

from services.bus.bus import Bus, BusError, Counters, Publisher, RawSample, keyexpr_intersects
from services.bus.config import (
    DEFAULT_ENDPOINT,
    BusSettings,
    add_bus_args,
    bus_args,
    bus_settings_from_args,
)

__all__ = [
    "DEFAULT_ENDPOINT",
    "Bus",
    "BusError",
    "BusSettings",
    "Counters",
    "Publisher",
    "RawSample",
    "add_bus_args",
    "bus_args",
    "bus_settings_from_args",
    "keyexpr_intersects",
]
