"""`harvest eval scene`: the scene estimator's fruit centres, d_v and trunk axis vs sim/truth."""

from __future__ import annotations

import argparse
import json
import sys

from services.cli.ui import console


def add_parser(esub: argparse._SubParsersAction) -> None:
    from services.cli.evaluate import parse_seeds

    p = esub.add_parser(
        "scene",
        help="fruit centre, d_v and trunk axis errors vs the sim's truth (depth noise on)",
        description="Runs the sim in-process on SCENARIO for each seed (D435-like depth noise "
        "on, robot still) and feeds every frame to the scene core with tracks made from the "
        "truth's visible boxes (a perfect detector and tracker: this measures localisation). "
        "Scores fruit 0.4-1.0 m from the camera and the trunk axis (horizontal distance).",
    )
    p.add_argument("--scenario", required=True, help="scenario name or YAML path")
    p.add_argument("--seeds", type=parse_seeds, default=[0, 1, 2], help="A-B or A,B,C (0-2)")
    p.add_argument("--seconds", type=float, default=3.0, help="sim seconds per seed (3.0)")
    p.add_argument(
        "--min-visible",
        type=float,
        default=0.5,
        help="a fruit becomes a track when this share of it is visible (0.5)",
    )
    p.add_argument(
        "--box-noise-px",
        type=float,
        default=0.0,
        help="move each box edge by seeded Gaussian noise of this σ, px (a detector's boxes "
        "are not pixel-exact; default 0)",
    )
    p.add_argument(
        "--set", action="append", metavar="KEY=VALUE", help="scene setting, e.g. fruit_method=paper"
    )
    p.add_argument(
        "--tracks",
        choices=["truth"],
        default="truth",
        help="where tracks come from: 'truth' (visible boxes of sim/truth)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_eval_scene)


def cmd_eval_scene(args: argparse.Namespace) -> int:
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeRemainingColumn,
    )

    from services.runtime.settings import SettingsError, load_settings, parse_overrides
    from services.scene import Settings
    from services.scene.evaluate import evaluate_seed, summary
    from services.sim.scenario import ScenarioError

    err = console(stderr=True)
    if not (args.seconds > 0 and 0 < args.min_visible <= 1 and args.box_noise_px >= 0):
        err.print("[red]--seconds must be > 0, --min-visible in (0, 1], --box-noise-px >= 0[/]")
        return 2
    try:
        settings = load_settings(Settings, {}, parse_overrides(args.set), service="scene")
    except SettingsError as exc:
        err.print(f"[red]{exc}[/]")
        return 2
    _import_pybullet_quietly()
    frames_per_seed = int(args.seconds * 15) + 1
    results = []
    with Progress(
        TextColumn("eval scene {task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        console=err,
        disable=not sys.stderr.isatty(),
    ) as bar:
        task = bar.add_task(args.scenario, total=frames_per_seed * len(args.seeds))
        for seed in args.seeds:
            bar.update(task, description=f"{args.scenario} seed {seed}")
            try:
                res = evaluate_seed(
                    args.scenario,
                    seed,
                    args.seconds,
                    settings,  # type: ignore[arg-type]
                    args.min_visible,
                    on_frame=lambda: bar.advance(task),
                    box_noise_px=args.box_noise_px,
                )
            except (ScenarioError, ValueError) as exc:
                err.print(f"[red]{args.scenario} seed {seed}: {exc}[/]")
                return 2
            results.append(res)
    out = summary(
        results,
        settings,  # type: ignore[arg-type]
        scenario=args.scenario,
        seeds=args.seeds,
        seconds_per_seed=args.seconds,
        min_visible=args.min_visible,
        box_noise_px=args.box_noise_px,
        tracks=args.tracks,
    )
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        print_table(out)
    return 0


GOALS = {
    "center_err_median_m": 0.010,
    "center_err_p95_m": 0.025,
    "dv_err_median_m": 0.005,
    "trunk_err_m": 0.020,
}


def print_table(out: dict) -> None:
    from rich.table import Table

    from services.scene.evaluate import VISIBLE_SHARE

    con = console()
    noise = f", box noise σ {out['box_noise_px']} px" if out["box_noise_px"] else ""
    t = Table(title=f"scene vs sim/truth: {out['scenario']}, seeds {_seeds(out['seeds'])}{noise}")
    t.add_column("figure")
    t.add_column("value", justify="right")
    t.add_column("goal", justify="right")
    whole, part = f"≥ {VISIBLE_SHARE:.0%}", f"{out['min_visible']:.0%}-{VISIBLE_SHARE:.0%}"
    rows = [
        ("fruit centre error, median", "center_err_median_m"),
        ("fruit centre error, p95", "center_err_p95_m"),
        ("fruit centre error, max", "center_err_max_m"),
        ("d_v error, median", "dv_err_median_m"),
        ("d_v error, p95", "dv_err_p95_m"),
        ("d_h error, median", "dh_err_median_m"),
        (f"range bias, fruit {whole} visible (−: nearer)", "range_bias_visible_m"),
        (f"range bias, fruit {part} visible", "range_bias_hidden_m"),
        (f"d_h bias, fruit {whole} visible", "dh_bias_visible_m"),
        (f"d_h bias, fruit {part} visible", "dh_bias_hidden_m"),
        ("trunk axis error (horizontal), median", "trunk_err_m"),
        ("trunk axis error (horizontal), p95", "trunk_err_p95_m"),
    ]
    for label, key in rows:
        v, goal = out[key], GOALS.get(key)
        mark = "" if goal is None or v is None else (" ✓" if v <= goal else " ✗")
        t.add_row(label, _mm(v) + mark, _mm(goal) if goal else "")
    share = out["trunk_found_share"]
    t.add_row("frames with the trunk found", "-" if share is None else f"{100 * share:.0f} %", "")
    es = out["estimate_share"]
    t.add_row(
        "fruit estimates / tracks in 0.4-1.0 m",
        f"{out['fruit_estimates']} / {out['in_range_tracks']}"
        + ("" if es is None else f" ({100 * es:.1f} %)"),
        "",
    )
    t.add_row("frames", str(out["frames"]), "")
    ms = out["core_ms_median"]
    t.add_row("scene core per frame, median", "-" if ms is None else f"{ms:.1f} ms", "")
    con.print(t)
    if out["flags"]:
        con.print(
            "flags on scored estimates: " + ", ".join(f"{k} {v}" for k, v in out["flags"].items())
        )
    if out["core_counters"]:
        con.print(
            "core counters: " + ", ".join(f"{k} {v}" for k, v in out["core_counters"].items())
        )
    con.print(f"methods: fruit {out['fruit_method']}, trunk {out['trunk_method']}")


def _import_pybullet_quietly() -> None:
    """pybullet prints its build time with C's printf on import; that text would land in the
    middle of --json output (C stdio flushes it at exit), so send it to stderr."""
    import ctypes
    import os

    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        import pybullet  # noqa: F401

        ctypes.CDLL(None).fflush(None)
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def _mm(v: float | None) -> str:
    return "-" if v is None else f"{1000 * v:.2f} mm"


def _seeds(seeds: list[int]) -> str:
    if len(seeds) > 2 and seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f"{seeds[0]}-{seeds[-1]}"
    return ",".join(map(str, seeds))
