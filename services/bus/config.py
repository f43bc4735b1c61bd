"""Zenoh session configuration: Zenoh's own json5 files plus the standard transport flags."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
_NS_RE = re.compile(r"^[A-Za-z0-9_\-]+(/[A-Za-z0-9_\-]+)*$")


class BusSettings(BaseModel):
    """How a process joins the bus. Multicast scouting is off unless asked for."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    mode: Literal["client", "peer", "router"] = Field(
        default="client",
        description="Zenoh mode. Services are clients of the run's router: one star, so "
        "messages keep their causal order (what lock-step relies on).",
    )
    connect: tuple[str, ...] = Field(default=(DEFAULT_ENDPOINT,), description="Endpoints.")
    listen: tuple[str, ...] = Field(default=(), description="Endpoints to listen on.")
    namespace: str | None = Field(default=None, description="Key prefix of the run.")
    config_file: Path | None = Field(default=None, description="Zenoh json5 config file.")
    multicast_scouting: bool = Field(default=False, description="Zenoh multicast discovery.")
    lease_ms: int = Field(
        default=1000, gt=0, description="Link lease: a hung peer is dropped after this, ms."
    )

    @field_validator("namespace")
    @classmethod
    def _ns(cls, v: str | None) -> str | None:
        if v is not None and not _NS_RE.match(v):
            raise ValueError(f"namespace {v!r} must be key chunks of [A-Za-z0-9_-] joined by '/'")
        return v


def make_zenoh_config(s: BusSettings):
    """A zenoh.Config: the json5 file first (if any), then our settings on top."""
    import zenoh

    conf = zenoh.Config.from_file(str(s.config_file)) if s.config_file else zenoh.Config()
    conf.insert_json5("mode", json.dumps(s.mode))
    if s.connect and s.mode != "router":
        conf.insert_json5("connect/endpoints", json.dumps(list(s.connect)))
    if s.listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(s.listen)))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(s.multicast_scouting))
    if s.mode == "peer" and not s.multicast_scouting:
        # Peers would otherwise gossip and open direct links, breaking the single-star order.
        conf.insert_json5("scouting/gossip/enabled", "false")
    conf.insert_json5("transport/link/tx/lease", str(s.lease_ms))
    conf.insert_json5("transport/link/tx/keep_alive", "4")
    if s.namespace:
        conf.insert_json5("namespace", json.dumps(s.namespace))
    return conf


def add_bus_args(ap: argparse.ArgumentParser) -> None:
    """The transport flags every program takes (as in the zenoh-python examples)."""
    g = ap.add_argument_group("bus (Zenoh)")
    g.add_argument(
        "-e",
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help=f"endpoint to connect to (repeatable; default {DEFAULT_ENDPOINT})",
    )
    g.add_argument(
        "-l",
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help="endpoint to listen on (repeatable)",
    )
    g.add_argument("-m", "--mode", choices=["client", "peer", "router"], help="Zenoh mode")
    g.add_argument("--namespace", help="the run's key prefix")
    g.add_argument("--zenoh-config", type=Path, metavar="FILE", help="Zenoh json5 config file")
    g.add_argument(
        "--no-multicast-scouting",
        action="store_true",
        help="disable multicast scouting (the default; kept for compatibility)",
    )
    g.add_argument(
        "--multicast-scouting",
        action="store_true",
        help="enable multicast scouting (never in tests)",
    )


def bus_settings_from_args(args: argparse.Namespace, **defaults: object) -> BusSettings:
    """BusSettings from parsed flags; ``defaults`` fill what the flags leave unset."""
    values: dict[str, object] = dict(defaults)
    if args.mode:
        values["mode"] = args.mode
    if args.connect:
        values["connect"] = tuple(args.connect)
    if args.listen:
        values["listen"] = tuple(args.listen)
    if args.namespace:
        values["namespace"] = args.namespace
    if args.zenoh_config:
        values["config_file"] = args.zenoh_config
    if args.multicast_scouting and not args.no_multicast_scouting:
        values["multicast_scouting"] = True
    return BusSettings.model_validate(values)


def bus_args(s: BusSettings) -> list[str]:
    """The command-line flags that reproduce ``s`` (used by the supervisor to start services)."""
    out: list[str] = ["-m", s.mode]
    for e in s.connect:
        out += ["-e", e]
    for e in s.listen:
        out += ["-l", e]
    if s.namespace:
        out += ["--namespace", s.namespace]
    if s.config_file:
        out += ["--zenoh-config", str(s.config_file)]
    if s.multicast_scouting:
        out += ["--multicast-scouting"]
    return out
