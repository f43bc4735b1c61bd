"""`harvest replay FILE` (playback into a live graph) and `harvest resim FILE --services a,b`."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from rich.progress import Progress
from rich.table import Table

from services.bus import BusError, add_bus_args, keyexpr_intersects
from services.cli.live import open_run_bus
from services.cli.ui import console
from services.recorder.inspect import RecordingError, iter_messages, read_info
from services.registry import UnknownServiceError
from services.replay.player import OutputCollector, Player
from services.replay.resim import ResimError, resim
from services.runtime.settings import SettingsError, parse_overrides
from services.runtime.spec import answer_maps


def add_parsers(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "replay",
        help="play a recording into a live run",
        description="Republish a recording's messages into a live run: at the "
        "recorded pace × --speed, or in lock-step with the live services.",
    )
    p.add_argument("file", type=Path, help="an MCAP recording")
    add_bus_args(p)
    p.add_argument("--run", metavar="RUN_ID", help="the live run to play into")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument(
        "--speed",
        type=float,
        default=1.0,
        help="pace factor (1 = recorded pace, 0 = as fast as possible)",
    )
    mode.add_argument(
        "--lockstep",
        action="store_true",
        help="wait for the live services' outputs before each next input",
    )
    p.add_argument(
        "--include",
        action="append",
        metavar="KEYEXPR",
        help="only these topics (repeatable; default all)",
    )
    p.add_argument(
        "--exclude", action="append", metavar="KEYEXPR", help="never these topics (repeatable)"
    )
    p.add_argument("--timeout", type=float, default=10.0, help="lock-step wait per output, s")
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser(
        "resim",
        help="re-run services on recorded inputs and diff their outputs",
        description="Start SERVICES fresh on a private bus, feed them their "
        "recorded inputs in lock-step, and report per topic how many outputs "
        "were identical, different or missing.",
    )
    p.add_argument("file", type=Path, help="an MCAP recording made by `harvest run`")
    p.add_argument("--services", required=True, help="comma-separated service names")
    p.add_argument(
        "--set",
        action="append",
        metavar="SERVICE.KEY=VALUE",
        help="change a setting of a service under resim, on top of its recorded settings "
        "(e.g. to see what a new threshold changes); repeatable",
    )
    p.add_argument("--timeout", type=float, default=10.0, help="wait per output, s")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=cmd_resim)


def topic_filter(include: list[str] | None, exclude: list[str] | None):
    def keep(topic: str) -> bool:
        if include and not any(keyexpr_intersects(p, topic) for p in include):
            return False
        return not (exclude and any(keyexpr_intersects(p, topic) for p in exclude))

    return keep


def cmd_replay(args: argparse.Namespace) -> int:
    try:
        info = read_info(args.file)
        bus = open_run_bus(args, "replay")
    except (RecordingError, BusError) as exc:
        print(f"harvest replay: {exc}", file=sys.stderr)
        return 1
    keep = topic_filter(args.include, args.exclude)
    recorded = {c.topic for c in info.channels if not c.derived}  # derived: never replayed
    published = {t for t in recorded if keep(t)}
    with bus:
        awaited: set[str] = set()
        collector = None
        caused_by: dict[str, tuple[str, ...]] = {}
        alongside: dict[str, tuple[str, ...]] = {}
        if args.lockstep:
            specs = [s.spec for s in bus.query_status()]
            live_outputs = {t for s in specs for t in s.outputs}
            awaited = (recorded & live_outputs) - published
            collector = OutputCollector(bus, awaited)
            caused_by, alongside = answer_maps(published, specs)
        player = Player(
            bus,
            lambda t: t in published,
            awaited,
            collector,
            args.timeout,
            caused_by=caused_by,
            alongside=alongside,
        )
        with Progress(transient=True) as bar:
            task = bar.add_task("replay", total=info.message_count)
            player.progress = lambda i: bar.update(task, completed=i + 1)
            stats = player.run(
                iter_messages(args.file), speed=None if args.lockstep else args.speed
            )
    print(
        f"published {stats.published} messages ({', '.join(sorted(published))}); awaited "
        f"{stats.awaited}, {stats.timed_out} timed out; {stats.wall_s:.1f} s"
    )
    return 0 if stats.timed_out == 0 else 1


def cmd_resim(args: argparse.Namespace) -> int:
    names = [n.strip() for n in args.services.split(",") if n.strip()]
    try:
        overrides = parse_overrides(args.set)
        with Progress(transient=True, disable=args.json) as bar:
            task = bar.add_task("resim", total=None)
            report = resim(
                args.file,
                names,
                args.timeout,
                overrides,
                progress=lambda i, n: bar.update(task, completed=i + 1, total=n),
            )
    except (RecordingError, ResimError, UnknownServiceError, BusError, SettingsError) as exc:
        print(f"harvest resim: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(report.to_json(), indent=2))
        return 0 if report.ok else 1
    con = console()
    t = Table(title=f"resim {', '.join(names)} on {args.file}")
    for col in ("topic", "recorded", "identical", "different", "missing", "extra"):
        t.add_column(col, justify="left" if col == "topic" else "right")
    for d in report.topics:
        if not d.compared:  # wall-clock diagnostics: expected to differ, never counted against
            t.add_row(d.topic, str(d.recorded), f"[dim]{d.verdict}[/]", "", str(d.missing), "")
            continue
        t.add_row(
            d.topic,
            str(d.recorded),
            str(d.identical),
            str(d.different),
            str(d.missing),
            str(d.extra),
        )
    con.print(t)
    for w in report.warnings:
        con.print(f"[yellow]warning:[/] {w}")
    verdict = "[green]identical[/]" if report.ok else "[red]outputs differ[/]"
    con.print(
        f"{100 * report.identical_ratio:.2f} % identical: {verdict} ({report.play.wall_s:.1f} s)"
    )
    return 0 if report.ok else 1
