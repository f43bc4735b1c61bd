"""Entry point shared by every service: flags, settings, the Node, signals and exit codes.

Exit codes: 0 stopped normally, 1 runtime failure (bus, lock-step stall), 2 bad configuration.
"""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

from services.bus import BusError, add_bus_args, bus_settings_from_args
from services.runtime.lockstep import LockstepPlan, LockstepStall
from services.runtime.node import Node
from services.runtime.settings import (
    ServiceSettings,
    SettingsError,
    config_hash,
    load_settings,
    parse_overrides,
    read_yaml,
)
from services.runtime.spec import NodeSpec

log = logging.getLogger("service")


class ConfigError(ValueError):
    """A core refuses its configuration (e.g. a weights file that does not match)."""


@dataclass(frozen=True)
class ServiceDef:
    """What the supervisor and the runtime need to know about one service (cheap to import)."""

    name: str
    settings: type[ServiceSettings]
    spec: NodeSpec
    kind: Literal["reactive", "source", "process"] = "reactive"
    make_core: Callable[[Any], Any] | None = field(default=None, compare=False)
    description: str = ""


def add_service_args(ap: argparse.ArgumentParser) -> None:
    g = ap.add_argument_group("service")
    g.add_argument("--settings", metavar="FILE", help="YAML file with this service's settings")
    g.add_argument("--settings-json", metavar="JSON", help="settings as a JSON object")
    g.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help="override one setting (dotted key, YAML value); repeatable",
    )
    g.add_argument(
        "--time-mode",
        choices=["lockstep", "live"],
        default="live",
        help="time mode (default live; the supervisor passes the stack's mode)",
    )
    g.add_argument(
        "--lockstep-plan",
        metavar="JSON",
        help="clock master only: answers to await per topic, and consumers",
    )
    g.add_argument(
        "--print-settings", action="store_true", help="print the resolved settings as JSON and exit"
    )
    g.add_argument("--log-level", default="INFO", help="logging level (default INFO)")


def resolve_settings(d: ServiceDef, args: argparse.Namespace) -> ServiceSettings:
    layer: dict[str, Any] = {}
    if args.settings:
        from pathlib import Path

        layer.update(read_yaml(Path(args.settings)))
    if args.settings_json:
        try:
            layer.update(json.loads(args.settings_json))
        except json.JSONDecodeError as exc:
            raise SettingsError(f"--settings-json is not valid JSON: {exc}") from None
    return load_settings(d.settings, layer, parse_overrides(args.set), service=d.name)


def setup_logging(name: str, level: str = "INFO") -> None:
    logging.basicConfig(
        level=level.upper(),
        stream=sys.stderr,
        format=f"%(levelname).1s {name}.%(name)s: %(message)s",
        force=True,
    )


def run_service(d: ServiceDef, argv: Sequence[str] | None = None) -> int:
    """Parse flags, build settings and core, run until SIGTERM/SIGINT or the core is done."""
    ap = argparse.ArgumentParser(
        prog=f"python -m services.{d.name}", description=d.description or d.name
    )
    add_bus_args(ap)
    add_service_args(ap)
    args = ap.parse_args(argv)
    setup_logging(d.name, args.log_level)
    try:
        settings = resolve_settings(d, args)
    except SettingsError as exc:
        print(f"{d.name}: {exc}", file=sys.stderr)
        return 2
    if args.print_settings:
        print(settings.model_dump_json(indent=2))
        return 0
    try:
        plan = LockstepPlan.model_validate_json(args.lockstep_plan) if args.lockstep_plan else None
        bus_settings = bus_settings_from_args(args)
    except ValueError as exc:
        print(f"{d.name}: bad flags: {exc}", file=sys.stderr)
        return 2
    if d.make_core is None:
        raise TypeError(f"service {d.name} has no core")
    try:
        core = d.make_core(settings)
    except ConfigError as exc:
        print(f"{d.name}: refused to start: {exc}", file=sys.stderr)
        return 2
    try:
        node = Node(d.name, d.spec, bus_settings, args.time_mode, config_hash(settings), plan)
    except BusError as exc:
        log.error("%s", exc)
        return 1
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: node.stop())
    node.ready()
    try:
        if d.kind == "source":
            node.run_source(core)
        else:
            node.run_reactive(core)
    except LockstepStall as exc:
        log.error("lock-step stalled: %s", exc)
        return 1
    finally:
        node.close()
    return 0
