"""Live tools, as in ROS 2 and dora: `harvest topics`, `harvest echo KEY`, `harvest status`."""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from collections import defaultdict

from rich.table import Table

from schemas.camera import RgbdFrame
from schemas.codec import DecodeError
from schemas.topics import TOPICS
from services.bus import Bus, BusError, RawSample, add_bus_args, bus_settings_from_args
from services.cli.ui import console


def add_parsers(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "topics",
        help="live keys with rate and bandwidth",
        description="Listen to the run for a while; list every key with its "
        "message rate and bandwidth.",
    )
    _common(p)
    p.add_argument("--duration", type=float, default=2.0, help="seconds to listen (default 2)")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.set_defaults(func=cmd_topics)

    p = sub.add_parser(
        "echo",
        help="print decoded messages of a key",
        description="Print every message on KEY (a key expression) as JSON; "
        "RGB-D frames print their header only.",
    )
    _common(p)
    p.add_argument("key", help="key expression, e.g. robot/joint_state or 'perception/**'")
    p.add_argument("-n", "--count", type=int, default=0, help="stop after N messages")
    p.add_argument("--timeout", type=float, default=0.0, help="stop after this many seconds")
    p.set_defaults(func=cmd_echo)

    p = sub.add_parser(
        "status",
        help="status of every live service",
        description="Query svc/*/status: state, counts, rejections, config hash.",
    )
    _common(p)
    p.add_argument("name", nargs="?", default="*", help="one service (default: all)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_status)


def _common(p: argparse.ArgumentParser) -> None:
    add_bus_args(p)
    p.add_argument("--run", metavar="RUN_ID", help="the run (namespace harvest/RUN_ID)")


def open_run_bus(args: argparse.Namespace, name: str) -> Bus:
    """A client session in the run's namespace; the namespace is discovered when unique."""
    if args.run:
        args.namespace = f"harvest/{args.run}"
    if args.tls_dir and not args.tls_identity:
        args.tls_identity = "operator"  # people's tools present the operator certificate
    if not args.namespace:
        with Bus(name, bus_settings_from_args(args)) as probe:
            found = probe.discover_namespaces()
        if not found:
            raise BusError("no live run found on the bus (start one with `harvest run`)")
        if len(found) > 1:
            raise BusError(
                f"several runs are live: {', '.join(found)}; choose one with --namespace or --run"
            )
        args.namespace = found[0]
    return Bus(name, bus_settings_from_args(args))


def cmd_topics(args: argparse.Namespace) -> int:
    try:
        bus = open_run_bus(args, "cli-topics")
    except BusError as exc:
        print(f"harvest topics: {exc}", file=sys.stderr)
        return 1
    counts: dict[str, list[int]] = defaultdict(lambda: [0, 0])
    lock = threading.Lock()

    def on_sample(s: RawSample) -> None:
        with lock:
            c = counts[s.key]
            c[0] += 1
            c[1] += len(s.payload)

    with bus:
        bus.subscribe_raw("**", on_sample)
        time.sleep(args.duration)
    rows = [
        {
            "key": k,
            "messages": n,
            "rate_hz": n / args.duration,
            "kbytes_per_s": b / 1e3 / args.duration,
            "schema": TOPICS[k].schema_name if k in TOPICS else "(undeclared)",
        }
        for k, (n, b) in sorted(counts.items())
    ]
    if args.json:
        print(json.dumps({"namespace": args.namespace, "topics": rows}, indent=2))
        return 0
    t = Table(title=f"{args.namespace} ({args.duration:.1f} s)")
    for col in ("key", "schema", "rate Hz", "kB/s"):
        t.add_column(col, justify="right" if col in ("rate Hz", "kB/s") else "left")
    for r in rows:
        t.add_row(r["key"], r["schema"], f"{r['rate_hz']:.1f}", f"{r['kbytes_per_s']:.1f}")
    console().print(t)
    return 0


def render(key: str, payload: bytes) -> str:
    """One message as JSON text; an error line when it does not decode."""
    t = TOPICS.get(key)
    if t is None:
        return json.dumps({"key": key, "undeclared": True, "bytes": len(payload)})
    try:
        msg = t.codec.decode(payload)
    except DecodeError as exc:
        return json.dumps({"key": key, "rejected": exc.reason})
    if isinstance(msg, RgbdFrame):
        body = json.loads(msg.meta.model_dump_json())
        body["pixels"] = {"rgb": list(msg.rgb.shape), "depth": list(msg.depth.shape)}
    else:
        body = json.loads(msg.model_dump_json())
    return json.dumps({"key": key, **body})


def cmd_echo(args: argparse.Namespace) -> int:
    try:
        bus = open_run_bus(args, "cli-echo")
    except BusError as exc:
        print(f"harvest echo: {exc}", file=sys.stderr)
        return 1
    done = threading.Event()
    n = [0]

    def on_sample(s: RawSample) -> None:
        if done.is_set():
            return
        print(render(s.key, s.payload), flush=True)
        n[0] += 1
        if args.count and n[0] >= args.count:
            done.set()

    with bus:
        bus.subscribe_raw(args.key, on_sample)
        done.wait(args.timeout or None)
    return 0


def cmd_status(args: argparse.Namespace) -> int:
    try:
        bus = open_run_bus(args, "cli-status")
    except BusError as exc:
        print(f"harvest status: {exc}", file=sys.stderr)
        return 1
    with bus:
        statuses = bus.query_status(args.name)
    if args.json:
        print(json.dumps([json.loads(s.model_dump_json()) for s in statuses], indent=2))
        return 0 if statuses else 1
    t = Table(title=f"services in {args.namespace}")
    for col in (
        "service",
        "state",
        "mode",
        "pid",
        "config",
        "received",
        "published",
        "rejected",
        "errors",
    ):
        t.add_column(col)
    for s in statuses:
        tot = [
            sum(getattr(c, f) for c in s.topics.values())
            for f in ("received", "published", "rejected")
        ]
        t.add_row(
            s.name,
            s.state,
            s.mode,
            str(s.pid),
            s.config_hash,
            str(tot[0]),
            str(tot[1]),
            str(tot[2] + s.rejected_unknown),
            str(s.errors),
        )
    console().print(t)
    return 0 if statuses else 1
