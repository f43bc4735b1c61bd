"""Recording tools: `harvest info FILE` and `harvest recover FILE`."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from rich.table import Table

from services.cli.ui import console
from services.recorder.inspect import MCAP_MAGIC, RecordingError, read_info
from services.recorder.recover import recover


def add_parsers(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "info",
        help="channels, counts, duration and metadata of a recording",
        description="Summarise an MCAP recording.",
    )
    p.add_argument("file", type=Path, help="an MCAP file")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--metadata", action="store_true", help="also print the full run metadata")
    p.set_defaults(func=cmd_info)

    p = sub.add_parser(
        "recover",
        help="make a truncated recording (writer killed) valid",
        description="Copy every complete record of a truncated MCAP into a valid "
        "file (default FILE with '.recovered.mcap').",
    )
    p.add_argument("file", type=Path, help="the damaged MCAP")
    p.add_argument("-o", "--out", type=Path, help="output file")
    p.add_argument("--in-place", action="store_true", help="replace FILE with the result")
    p.set_defaults(func=cmd_recover)


def cmd_info(args: argparse.Namespace) -> int:
    try:
        info = read_info(args.file)
    except RecordingError as exc:
        print(f"harvest info: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(
            json.dumps(
                {
                    "path": str(info.path),
                    "size_bytes": info.size_bytes,
                    "messages": info.message_count,
                    "start_ns": info.start_ns,
                    "end_ns": info.end_ns,
                    "duration_s": info.duration_s,
                    "channels": [vars(c) for c in info.channels],
                    "metadata": info.metadata,
                },
                indent=2,
            )
        )
        return 0
    con = console()
    t = Table(title=str(info.path))
    for col in ("topic", "schema", "encoding", "messages"):
        t.add_column(col, justify="right" if col == "messages" else "left")
    for c in info.channels:
        enc = f"{c.message_encoding} (derived)" if c.derived else c.message_encoding
        t.add_row(c.topic, c.schema_name or "-", enc, str(c.count))
    con.print(t)
    con.print(
        f"{info.message_count} messages, {info.duration_s:.3f} s "
        f"({info.start_ns} → {info.end_ns} ns), {info.size_bytes / 1e6:.2f} MB"
    )
    run = info.run
    if not run:
        con.print("[yellow]no run metadata: not recorded by `harvest run`[/]")
    else:
        keys = (
            "run_id",
            "stack_name",
            "profile",
            "mode",
            "scenario",
            "seed",
            "git_revision",
            "started_utc",
        )
        for k in keys:
            con.print(f"  {k}: {run.get(k, '')}")
        con.print(f"  services: {', '.join(json.loads(run.get('services', '{}')))}")
        if args.metadata:
            for k, v in run.items():
                if k not in keys:
                    con.print(f"  {k}: {v}")
    return 0


def cmd_recover(args: argparse.Namespace) -> int:
    src: Path = args.file
    if not src.exists() or src.stat().st_size == 0:
        print(f"harvest recover: {src}: missing or empty; nothing to recover", file=sys.stderr)
        return 1
    with open(src, "rb") as f:
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            print(f"harvest recover: {src}: not an MCAP file (bad magic bytes)", file=sys.stderr)
            return 1
    dst = src if args.in_place else (args.out or src.with_suffix(".recovered.mcap"))
    report = recover(src, dst)
    state = "truncated at " + report.error if report.truncated else "intact"
    print(
        f"recovered {report.messages} messages on {report.channels} channels "
        f"({report.metadata} metadata records) from {src} ({state}) -> {dst}"
    )
    return 0
