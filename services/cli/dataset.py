"""`harvest dataset ...`: synthetic training data from the sim (see services/sim/dataset.py)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from services.cli.ui import console


def add_parsers(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "dataset",
        help="datasets: synthetic RGB-D frames with fruit boxes",
        description="Make datasets for the detector.",
    )
    dsub = p.add_subparsers(dest="dataset", metavar="WHAT")
    dsub.required = True
    s = dsub.add_parser(
        "synth",
        help="domain-randomised sim renders: images, depth, boxes with visible fraction",
        description="Renders N random scenes with the sim's renderer (random trees, fruit, "
        "colours, textures, backgrounds, lighting, camera pose, blur, sensor noise) and writes "
        "OUT/images, OUT/depth, OUT/intrinsics.json and OUT/labels.json in the format of "
        "shared/data/oranges_real (plus depth and visible_fraction). Same seed, same files.",
    )
    s.add_argument("--out", type=Path, required=True, help="output folder")
    s.add_argument("--frames", type=int, required=True, help="number of frames")
    s.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    s.set_defaults(func=cmd_synth)


def cmd_synth(args: argparse.Namespace) -> int:
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    from services.sim.dataset import synth

    con = console(stderr=True)
    if args.frames < 1:
        con.print("[red]--frames must be at least 1[/]")
        return 2
    t0 = time.monotonic()
    with Progress(
        TextColumn("synth"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TimeRemainingColumn(),
        console=con,
    ) as bar:
        task = bar.add_task("frames", total=args.frames)
        labels = synth(args.out, args.frames, args.seed, lambda n: bar.update(task, completed=n))
    boxes = sum(len(e["boxes"]) for e in labels)
    con.print(
        f"wrote {len(labels)} frames, {boxes} boxes to {args.out} "
        f"in {time.monotonic() - t0:.1f} s ({args.out / 'labels.json'})"
    )
    return 0
