"""`harvest bench ...`: benchmarks (bus, viz, sim, controller, detector, tracker, harvest,
faults)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from services.cli import bench_perception


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "bench",
        help="benchmarks (see BENCHMARKS.md)",
        description="Measure speed figures; --json prints one object.",
    )
    bsub = p.add_subparsers(dest="bench", metavar="WHAT")
    bsub.required = True
    b = bsub.add_parser(
        "bus",
        help="our bus vs raw zenoh: latency, frames, recorder CPU",
        description="Two processes on loopback through a Python router: p50/p99 "
        "latency of ~200-byte messages at 1 kHz and 640x480 RGB-D frames at "
        "30 Hz through our bus and raw zenoh-python; recorder CPU at 15 Hz.",
    )
    b.add_argument("--seconds", type=float, default=3.0, help="duration of each measurement")
    b.add_argument("--rounds", type=int, default=3, help="repetitions, ours and raw interleaved")
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.set_defaults(func=cmd_bench_bus)
    v = bsub.add_parser(
        "viz",
        help="what drawing a run costs: log vs send_columns, offline, live CPU",
        description="Rerun log calls per row vs buffered send_columns; `harvest view` speed "
        "on a synthetic 640x480 recording; CPU of the live viz service at 15 Hz RGB-D and "
        "100 Hz joint states (default settings and raw images); .rrd size per sim minute.",
    )
    v.add_argument("--seconds", type=float, default=10.0, help="sim seconds per measurement")
    v.add_argument("--rounds", type=int, default=3, help="repetitions (medians are reported)")
    v.add_argument("--json", action="store_true", help="print one JSON object")
    v.set_defaults(func=cmd_bench_viz)
    s = bsub.add_parser(
        "sim",
        help="sim: render ms per 640x480 RGB-D frame, real-time factor on one core",
        description="Runs the sim core in-process pinned to one core, camera at 15 Hz and "
        "control at 120 Hz, with a fake controller moving both arms through the view, then "
        "still; every output encoded. Also an uncached render and pybullet's TinyRenderer.",
    )
    s.add_argument("--scenario", default="paper-exp1", help="scenario (default paper-exp1)")
    s.add_argument("--seconds", type=float, default=10.0, help="sim seconds with arms moving")
    s.add_argument("--no-tiny", action="store_true", help="skip the TinyRenderer comparison")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=cmd_bench_sim)
    c = bsub.add_parser(
        "controller",
        help="controller: cycle time vs fruit obstacles, closed-loop reach",
        description="The controller core in closed loop with a kinematic sim: p50/p99 cycle "
        "time with 0, 10, 50 and 200 fruit (message I/O apart), then reach success, time and "
        "constraint violations on a fixed set of random targets the IK reaches.",
    )
    c.add_argument("--ticks", type=int, default=2000, help="control ticks per obstacle count")
    c.add_argument("--targets", type=int, default=100, help="reach targets (0: skip reach)")
    c.add_argument("--seed", type=int, default=6, help="seed of the scenes and the targets")
    c.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="controller setting for the bench, e.g. limit_margin_rad=0.3; repeatable",
    )
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(func=cmd_bench_controller)
    f = bsub.add_parser(
        "faults",
        help="faults: kills and hangs survived, fuzz crashes, restart and arm-stop times",
        description="SIGKILL and SIGSTOP each restartable service (controller, viz, recorder) "
        "of a supervised lock-step sim run, once each: survived, liveliness lost and back, "
        "joint-state ticks lost, the recorder's lost tail after `harvest recover`; fuzz cases "
        "per registered service (seeded) and crashes; the live controller's time from its last "
        "joint state to a zero-velocity command.",
    )
    f.add_argument("--fuzz-cases", type=int, default=500, help="fuzz cases per service")
    f.add_argument("--sim-seconds", type=float, default=6.0, help="sim seconds of each run")
    f.add_argument(
        "--no-harvest",
        action="store_true",
        help="skip the two harvest runs (detector, tracker, scene, planner killed / hung)",
    )
    f.add_argument("--json", action="store_true", help="print one JSON object")
    f.set_defaults(func=cmd_bench_faults)
    bench_perception.add_parsers(bsub)
    h = bsub.add_parser(
        "harvest",
        help="the whole harvest over seeds, for each harvest-order policy",
        description="Runs the harvest (sim, detector, tracker, scene, controller, planner) on a "
        "scenario for each seed and each order policy; judged against the sim's truth: fruit "
        "harvested and reachable (IK on the true fruit, with the fruit in its way first), "
        "success rate, unreachable fruit "
        "identified, collisions (sim contacts), median sim seconds per harvested fruit, wall "
        "time, real-time factor, and where each reachable fruit went (harvested, stalled, "
        "blocked, cut failed, never detected, ...). --mode inproc runs every core in one "
        "process in lock-step order; --mode stack runs the real stack under the supervisor "
        "(slower).",
    )
    h.add_argument("--scenario", default="orchard", help="scenario (default orchard)")
    h.add_argument("--seeds", default="0-19", help="seeds: A-B, A,B,C or A (default 0-19)")
    h.add_argument(
        "--orders", default="nearest,planned", help="order policies (default nearest,planned)"
    )
    h.add_argument("--fruit-count", type=int, help="random fruit per tree (sim fruit_count)")
    h.add_argument("--mode", choices=["inproc", "stack"], default="inproc", help="how to run")
    h.add_argument("--max-s", type=float, default=240.0, help="sim seconds per run at most")
    h.add_argument(
        "--jobs",
        type=int,
        default=1,
        metavar="N",
        help="inproc runs at once, each in its own process (default 1; the rows are the same "
        "for any N: each run is deterministic on its own). Wall times and the real-time factor "
        "are then per run under that load",
    )
    h.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SERVICE.KEY=VALUE",
        help="override a service's setting for the run (sim, detector, tracker, scene, "
        "controller, planner), e.g. scene.occupancy=false; repeatable",
    )
    h.add_argument(
        "--events-out",
        type=Path,
        metavar="DIR",
        help="write each run's harvest and sim events to DIR/ORDER-SEED.jsonl (diagnosis)",
    )
    h.add_argument(
        "--rows",
        type=Path,
        metavar="FILE",
        help="append each finished run's row to FILE (JSON lines) and take the runs FILE "
        "already holds for the same scenario, settings and commit from it: a bench stopped "
        "part-way resumes (rows of uncommitted code are written, never reused)",
    )
    h.add_argument(
        "--from-rows",
        type=Path,
        nargs="+",
        metavar="FILE",
        help="run nothing: the table (or --json) of the rows in these files (--rows of benches "
        "run apart, e.g. seeds split over processes); rows of different settings or code "
        "are refused",
    )
    h.add_argument("--json", action="store_true", help="print one JSON object")
    h.set_defaults(func=cmd_bench_harvest)


def cmd_bench_bus(args: argparse.Namespace) -> int:
    from services.bus.bench import run_bus_bench, table

    result = run_bus_bench(args.seconds, args.rounds, progress=not args.json)
    print(json.dumps(result, indent=2) if args.json else table(result))
    return 0


def cmd_bench_viz(args: argparse.Namespace) -> int:
    from services.viz.bench import run_viz_bench

    result = run_viz_bench(args.seconds, args.rounds, progress=not args.json)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for k, v in result.items():
            if not k.endswith("_rounds"):
                print(f"{k:40} {v:10.2f}")
    return 0


def cmd_bench_sim(args: argparse.Namespace) -> int:
    from services.sim.bench import run_sim_bench, table

    result = run_sim_bench(args.scenario, args.seconds, tiny=not args.no_tiny)
    print(json.dumps(result, indent=2) if args.json else table(result))
    return 0


def cmd_bench_controller(args: argparse.Namespace) -> int:
    import sys

    from services.controller.bench import run_controller_bench, table
    from services.runtime.settings import SettingsError, parse_overrides

    try:
        result = run_controller_bench(
            args.ticks,
            args.targets,
            args.seed,
            progress=not args.json,
            sets=parse_overrides(args.set),
        )
    except SettingsError as exc:
        print(f"harvest bench controller: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(result, indent=2) if args.json else table(result))
    return 0


def cmd_bench_faults(args: argparse.Namespace) -> int:
    from services.supervisor.bench import run_faults_bench, table

    result = run_faults_bench(
        args.fuzz_cases, args.sim_seconds, progress=not args.json, harvest=not args.no_harvest
    )
    print(json.dumps(result, indent=2) if args.json else table(result))
    ok = result["kills_survived"] == result["kills_tried"] and result["crashes"] == 0
    return 0 if ok else 1


def cmd_bench_harvest(args: argparse.Namespace) -> int:
    import sys

    from services.planner.bench import (
        BenchConfig,
        BenchError,
        from_rows,
        parse_seeds,
        parse_sets,
        run_harvest_bench,
        table,
    )

    def say(line: str) -> None:
        print(line, file=sys.stderr)

    try:
        if args.from_rows:
            result = from_rows(args.from_rows, say)
            print(json.dumps(result, indent=2) if args.json else table(result))
            return 0
        cfg = BenchConfig(
            args.scenario,
            parse_seeds(args.seeds),
            tuple(o.strip() for o in args.orders.split(",") if o.strip()),
            args.fruit_count,
            args.mode,
            args.max_s,
            settings=parse_sets(args.set),
            jobs=args.jobs,
            events_dir=args.events_out,
            rows_path=args.rows,
        )
        if cfg.jobs < 1:
            raise BenchError(f"--jobs must be at least 1, got {cfg.jobs}")
        if cfg.events_dir is not None:
            try:  # before the runs: a bad path must not cost an hour of them
                cfg.events_dir.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise BenchError(f"--events-out {cfg.events_dir}: {exc.strerror}") from None
        bad = [o for o in cfg.orders if o not in ("nearest", "planned")]
        if bad:
            raise BenchError(f"unknown order policies {bad} (nearest, planned)")
        if cfg.rows_path is not None and cfg.rows_path.is_dir():
            raise BenchError(f"--rows {cfg.rows_path}: a directory, not a rows file")
        result = run_harvest_bench(cfg, progress=say)
    except BenchError as exc:
        print(f"harvest bench harvest: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(result, indent=2) if args.json else table(result))
    return 0
