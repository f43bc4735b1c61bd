"""`harvest run`: start a stack under the supervisor and print a summary when it ends; with a
planner in the stack, a line per harvest event, a progress bar of fruit and the harvest table."""

from __future__ import annotations

import argparse
import secrets
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from services.cli.ui import console
from services.recorder.inspect import RecordingError, read_info
from services.runtime.settings import SettingsError, parse_overrides
from services.supervisor.stack import (
    RestartPolicy,
    ServiceEntry,
    Stack,
    StackError,
    deep_merge,
    load_stack,
)
from services.supervisor.supervisor import RunResult, Supervisor

DEFAULT_STACK = Path("deploy/stack.yaml")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run",
        help="run a stack (default: deploy/stack.yaml) and record it",
        description="Start the router, the recorder and every service of a "
        "stack; stop in order on Ctrl-C or when the main service ends.",
    )
    p.add_argument("--stack", type=Path, default=DEFAULT_STACK, help="stack file (YAML)")
    p.add_argument("--profile", help="a profile of the stack file to overlay")
    p.add_argument(
        "--set",
        action="append",
        metavar="SERVICE.KEY=VALUE",
        help="override a service setting, e.g. sim.duration_s=60; repeatable",
    )
    p.add_argument("--run-id", help="run id (default run-<date>-<time>-<random>)")
    p.add_argument("--listen", help="router endpoint (overrides the stack's router.listen)")
    p.add_argument(
        "--host",
        help="multi-host stacks: run only this host's router, recorder and services "
        "(deploy/multihost/README.md)",
    )
    p.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help="where this host reaches the router (overrides router.connect; repeatable)",
    )
    p.add_argument("--no-record", action="store_true", help="do not record an MCAP")
    p.add_argument("--quiet", action="store_true", help="no service logs on the terminal")
    p.add_argument(
        "--view",
        action="store_true",
        help="add the viz service and open a Rerun viewer (served on --viz-port when there is "
        "no display)",
    )
    p.add_argument("--save", type=Path, metavar="RRD", help="add the viz service; write an .rrd")
    p.add_argument("--viz-port", type=int, default=9876, help="gRPC port of the viewer (--view)")
    p.add_argument("--phases", action="store_true", help="also print every harvest phase change")
    p.set_defaults(func=cmd_run)


def with_viz(stack: Stack, view: bool, save: Path | None, port: int) -> dict[str, ServiceEntry]:
    """The stack's services plus the viz service (its settings merged if the stack has one)."""
    from services.viz.sink import has_display

    settings: dict[str, object] = {"grpc_port": port}
    if view:
        settings["viewer"] = "spawn" if has_display() else "serve"
    if save is not None:
        settings["save_path"] = str(save.resolve())
    old = stack.services.get("viz")
    entry = (
        old.model_copy(update={"settings": deep_merge(old.settings, settings), "enabled": True})
        if old is not None
        else ServiceEntry(settings=settings, restart=RestartPolicy(policy="on-failure"))
    )
    return {**stack.services, "viz": entry}


def new_run_id() -> str:
    return time.strftime("run-%Y%m%d-%H%M%S-") + secrets.token_hex(2)


def cmd_run(args: argparse.Namespace) -> int:
    con = console()
    try:
        overrides = parse_overrides(args.set)
        stack = load_stack(args.stack, args.profile, overrides)
    except (StackError, SettingsError) as exc:
        con.print(f"[red]refused to start:[/] {exc}")
        return 2
    updates: dict[str, object] = {}
    if args.no_record:
        updates["recording"] = stack.recording.model_copy(update={"enabled": False})
    router_updates: dict[str, object] = {}
    if args.listen:
        router_updates["listen"] = (args.listen,)
    if args.connect:
        router_updates["connect"] = tuple(args.connect)
    if router_updates:
        updates["router"] = stack.router.model_copy(update=router_updates)
    if args.host:
        updates["host"] = args.host
    if args.view or args.save:
        updates["services"] = with_viz(stack, args.view, args.save, args.viz_port)
    if updates:
        stack = stack.model_copy(update=updates)
    stack = label_planner(stack)
    try:
        sup = Supervisor(
            stack, args.stack, args.run_id or new_run_id(), args.profile, quiet=args.quiet
        )
    except OSError as exc:  # e.g. the recording folder is not writable: nothing started yet
        con.print(
            f"[red]refused to start:[/] cannot write the run log in {stack.recording.dir}: {exc}"
        )
        return 2
    watch = None
    if "planner" in stack.enabled():
        from services.cli.harvest_view import HarvestWatch

        watch = HarvestWatch(con, show_phases=args.phases)
        sup.on_bus.append(watch.attach)
    try:
        result = sup.run()
    except StackError as exc:
        con.print(f"[red]refused to start:[/] {exc}")
        return 2
    finally:
        if watch is not None:
            watch.stop()
    print_summary(con, result)
    if watch is not None:
        print_harvest(con, watch, result)
    return result.exit_code


def label_planner(stack: Stack) -> Stack:
    """The planner labels its run summary with the scenario and seed: the sim's (or the
    stack's) unless the planner's settings name them."""
    planner, sim = stack.services.get("planner"), stack.services.get("sim")
    if planner is None:
        return stack
    sim_settings = sim.settings if sim is not None else {}
    label = {
        "scenario": sim_settings.get("scenario", stack.scenario),
        "seed": sim_settings.get("seed", stack.seed),
    }
    settings = {**{k: v for k, v in label.items() if v not in (None, "")}, **planner.settings}
    entry = planner.model_copy(update={"settings": settings})
    return stack.model_copy(update={"services": {**stack.services, "planner": entry}})


def print_harvest(console: Console, watch: object, r: RunResult) -> None:
    """The harvest tables when the planner published its summary."""
    from services.cli.harvest_view import HarvestWatch, summary_tables

    assert isinstance(watch, HarvestWatch)
    if watch.summary is None:
        console.print("[yellow]no harvest summary was published (the planner did not finish)[/]")
        return
    for t in summary_tables(watch.summary, watch.sim_contacts, r.wall_s, r.mcap):
        console.print(t)


def print_summary(console: Console, r: RunResult) -> None:
    t = Table(title=f"run {r.run_id}", show_header=True)
    t.add_column("service")
    t.add_column("restarts", justify="right")
    t.add_column("back live after, s", justify="right")
    t.add_column("exit codes")
    for name, c in r.children.items():
        back = ", ".join(f"{x:.2f}" for x in c.restart_s) or "-"
        t.add_row(name, str(c.restarts), back, ",".join(map(str, c.proc.exit_codes)) or "-")
    console.print(t)
    for i, part in enumerate(r.mcap_parts or ([r.mcap] if r.mcap else [])):
        _print_recording(console, part, table=i == 0)
    console.print(f"wall time {r.wall_s:.1f} s; log {r.log}")
    for w in r.warnings:
        console.print(f"[yellow]warning:[/] {w}")
    if r.exit_code == 0:
        console.print("[green]run finished[/]")
    elif r.exit_code == 130:
        console.print("[yellow]run interrupted; recording finished cleanly[/]")
    else:
        console.print(f"[red]run failed:[/] {r.failure}")


def _print_recording(console: Console, path: Path, table: bool) -> None:
    """Counts of one recording file; a file cut by a crash says how to repair it."""
    if not path.exists():
        console.print(f"[yellow]recording:[/] {path} was not written")
        return
    try:
        info = read_info(path)
    except RecordingError as exc:
        console.print(f"[yellow]recording:[/] {exc}")
        return
    if table:
        tt = Table(title=f"recording {path}")
        tt.add_column("topic")
        tt.add_column("messages", justify="right")
        for ch in info.channels:
            tt.add_row(ch.topic, str(ch.count))
        console.print(tt)
    console.print(
        f"{path}: {info.message_count} messages, "
        f"{info.duration_s:.2f} s of stamps, {info.size_bytes / 1e6:.1f} MB"
    )
