"""`harvest view FILE.mcap [--out FILE.rrd] [--screenshot PNG]`: a recording in Rerun, drawn by
the same conversion core as the live viz service."""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from rich.progress import Progress

from services.cli.ui import console
from services.recorder.inspect import RecordingError, RecordingInfo, read_info
from services.runtime.settings import SettingsError, load_settings, parse_overrides
from services.viz import Settings


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "view",
        help="show a recording in Rerun (or convert it to .rrd)",
        description="Draw an MCAP recording in Rerun: camera with boxes and trunk mask, the "
        "robot, fruit, trunk and targets in 3D, plots and events. Without --out a viewer is "
        "spawned (or, with --serve, served for a browser or `rerun --connect`).",
    )
    p.add_argument("file", type=Path, help="an MCAP recording")
    p.add_argument("-o", "--out", type=Path, help="write an .rrd file instead of opening a viewer")
    p.add_argument(
        "--screenshot",
        type=Path,
        metavar="PNG",
        help="also render a headless screenshot of the result (needs a Vulkan driver; "
        "CPU-only: apt-get install mesa-vulkan-drivers)",
    )
    p.add_argument(
        "--window-size",
        default="1600x900",
        metavar="WxH",
        help="size of the headless viewer for --screenshot, logical points (default 1600x900)",
    )
    p.add_argument("--serve", action="store_true", help="serve a gRPC + web viewer; Ctrl-C ends")
    p.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help="a viz setting, e.g. image_max_rate_hz=5 or urdf_path=other.urdf; repeatable",
    )
    p.set_defaults(func=cmd_view)


def cmd_view(args: argparse.Namespace) -> int:
    try:
        info = read_info(args.file)
        values = parse_overrides(args.set)
        if args.serve:
            values["viewer"] = "serve"
        elif args.out is None and args.screenshot is None:
            values["viewer"] = "spawn"
        settings = load_settings(Settings, values, service="viz")
    except (RecordingError, SettingsError) as exc:
        print(f"harvest view: {exc}", file=sys.stderr)
        return 1
    assert isinstance(settings, Settings)
    out = args.out
    if out is None and args.screenshot is not None:
        out = Path(tempfile.mkdtemp(prefix="harvest-view-")) / f"{args.file.stem}.rrd"
    return _convert(args, info, settings, out)


def _convert(
    args: argparse.Namespace, info: RecordingInfo, settings: Settings, out: Path | None
) -> int:
    from services.viz.offline import convert, recording_id
    from services.viz.sink import SinkError, open_stream

    con = console()
    try:
        rec = open_stream(settings, recording_id(info), out)
    except (SinkError, OSError) as exc:
        print(f"harvest view: {exc}", file=sys.stderr)
        return 1
    t0 = time.monotonic()
    with Progress(transient=True, console=con) as bar:
        task = bar.add_task(f"drawing {args.file.name}", total=info.message_count)
        report = convert(
            args.file, rec, settings, lambda i, n: bar.update(task, completed=i), info=info
        )
    rec.flush()
    rec.disconnect()
    for line in report.lines():
        con.print(line)
    con.print(f"{report.messages} messages in {time.monotonic() - t0:.1f} s")
    if out is not None:
        con.print(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB); open it with `rerun {out}`")
    if args.screenshot is not None:
        from services.viz.screenshot import ScreenshotError, screenshot

        assert out is not None
        try:
            w, h = (int(x) for x in args.window_size.lower().split("x"))
            con.print(f"screenshot {screenshot(out, args.screenshot, (w, h))}")
        except ValueError:
            print(f"harvest view: --window-size {args.window_size!r} is not WxH", file=sys.stderr)
            return 1
        except ScreenshotError as exc:
            print(f"harvest view: screenshot failed: {exc}", file=sys.stderr)
            return 1
    if settings.viewer == "serve":
        con.print("serving; Ctrl-C to stop")
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass
    return 0
