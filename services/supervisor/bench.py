"""`harvest bench faults`: kills and hangs survived under the supervisor, fuzz cases and crashes,
messages lost after a kill, restart time, and how fast the controller stops the arms when its
inputs go stale. Every figure is measured here; BENCHMARKS.md quotes the output."""

from __future__ import annotations

import itertools
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from services.bus import Bus, BusSettings

KILLABLE = ("controller", "viz", "recorder")
"""Services of the running stack that are restarted by policy (the sim is the run's clock);
the router is killed once too (restarted by `router.restart`, clients re-dial it)."""
FAST = "{policy: on-failure, max_restarts: 3, backoff_s: 0.05}"
TICK_HZ = 120
HARVEST_FAULTED = ("detector", "tracker", "scene", "planner")
"""Killed (then, in a second run, hung) one after another during one real harvest."""
LAB_TREE: dict[str, Any] = {
    "name": "bench-faults-lab",
    "seed": 3,
    "tree": {
        "trunk_xy_world_m": [1.15, 0.02],
        "extra_branches": 1,
        "leaf_clusters": 2,
        "leaves_per_cluster": 4,
    },
    "fruits": [
        {"position_world_m": [0.6, -0.12, 1.32], "radius_m": 0.04, "leaf_cover": "none"},
        {"position_world_m": [0.7, 0.05, 1.25], "radius_m": 0.04, "leaf_cover": "none"},
    ],
}
"""A small lab tree (few leaves: fast to render) with two reachable fruit: the harvest of
tests/integration/test_faults_harvest.py."""


def stack_yaml(d: Path, sim_s: float) -> str:
    return f"""
name: bench-faults
mode: lockstep
master: sim
scenario: paper-exp1
router: {{restart: {{policy: on-failure, max_restarts: 3, backoff_s: 0.2}}}}
recording: {{enabled: true, dir: {d / "rec"}, restart: {FAST}}}
services:
  controller: {{restart: {FAST}}}
  viz: {{restart: {FAST}, settings: {{viewer: none, save_path: {d / "viz.rrd"}}}}}
  sim:
    main: true
    settings: {{scenario: paper-exp1, duration_s: {sim_s}}}
"""


def harvest_stack_yaml(d: Path, scenario: Path) -> str:
    """The harvest of deploy/stack.yaml on the lab tree, every service restarted on failure."""
    return f"""
name: bench-faults-harvest
mode: lockstep
master: sim
recording: {{enabled: true, dir: {d / "rec"}, restart: {FAST}}}
services:
  sim:
    settings: {{scenario: {scenario}, seed: 5, duration_s: 90.0}}
  detector: {{restart: {FAST}}}
  tracker: {{restart: {FAST}}}
  scene: {{restart: {FAST}}}
  controller: {{restart: {FAST}}}
  planner:
    main: true
    restart: {FAST}
    settings: {{finish_after_s: 0.5}}
"""


def _wait(pred: Callable[[], Any], timeout_s: float, what: str) -> Any:
    deadline = time.monotonic() + timeout_s
    while True:
        v = pred()
        if v:
            return v
        if time.monotonic() > deadline:
            raise TimeoutError(f"timed out after {timeout_s:.0f} s waiting for {what}")
        time.sleep(0.01)


def _received(bus: Bus, name: str) -> int:
    st = bus.query_status(name, 1.0)
    return sum(c.received for c in st[0].topics.values()) if st else 0


def fault_run(name: str, sig: int, sim_s: float = 6.0) -> dict[str, Any]:
    """One supervised lock-step run; ``sig`` sent to ``name`` after 100 received messages."""
    d = Path(tempfile.mkdtemp(prefix="hvb-", dir="/tmp"))
    try:
        return _fault_run(d, name, sig, sim_s)
    finally:
        shutil.rmtree(d, ignore_errors=True)


def _fault_run(d: Path, name: str, sig: int, sim_s: float) -> dict[str, Any]:
    (d / "stack.yaml").write_text(stack_yaml(d, sim_s))
    ep = f"unixsock-stream/{d}/router.sock"
    run_id = "bench"
    argv = [sys.executable, "-m", "services.cli", "run", "--stack", str(d / "stack.yaml")]
    argv += ["--run-id", run_id, "--listen", ep, "--quiet"]
    with open(d / "out.log", "wb") as log:
        p = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    events: list[tuple[float, bool]] = []
    lock = threading.Lock()

    def on_health(n: str, up: bool) -> None:
        if n == name:
            with lock:
                events.append((time.monotonic(), up))

    def bus() -> Bus | None:
        try:
            return Bus("bench-observer", BusSettings(connect=(ep,), namespace=f"harvest/{run_id}"))
        except Exception:
            return None

    obs: Bus = _wait(bus, 60, "the run's router")
    try:
        obs.watch_health(on_health)
        watched = "controller" if name == "router" else name  # the router serves no status
        st = _wait(lambda: obs.query_status(watched, 1.0), 60, f"status of {watched}")
        pid = _router_pid(ep) if name == "router" else st[0].pid
        _wait(lambda: p.poll() is None and _received(obs, watched) > 100, 120, "progress")
        t_fault, wall_fault_ns = time.monotonic(), time.time_ns()
        os.kill(pid, sig)

        def after(up: bool, since: float) -> float | None:
            with lock:
                return next((t for t, u in events if u is up and t > since), None)

        t_down = _wait(lambda: after(False, t_fault), 30, f"{name}'s liveliness to go")
        t_up = _wait(lambda: after(True, t_down), 60, f"{name} back")
    finally:
        obs.close()
    rc = p.wait(timeout=300)
    run_log = d / "rec" / f"{run_id}.log"  # --quiet: the supervisor's lines are only here
    out = run_log.read_text(errors="replace") if run_log.exists() else ""
    lost = _lost(d / "rec", run_id, name, wall_fault_ns, sim_s)
    return {
        "service": name,
        "signal": signal.Signals(sig).name,
        "survived": rc == 0
        and ("restarting the router" if name == "router" else f"restarting {name}") in out,
        "liveliness_lost_s": t_down - t_fault,
        "back_live_s": t_up - t_fault,
        **lost,
    }


def harvest_fault_run(sig: int) -> dict[str, Any]:
    """One supervised harvest of the lab tree; ``sig`` sent in turn to the detector, tracker
    and scene (each after 20 more received messages) and to the planner (once the first fruit
    is in the basket), each time waiting until the target is live again."""
    d = Path(tempfile.mkdtemp(prefix="hvh-", dir="/tmp"))
    try:
        return _harvest_fault_run(d, sig)
    finally:
        shutil.rmtree(d, ignore_errors=True)


def _harvest_fault_run(d: Path, sig: int) -> dict[str, Any]:
    import yaml

    from schemas import TOPICS
    from services.recorder.inspect import iter_messages

    scenario = d / "lab.yaml"
    scenario.write_text(yaml.safe_dump(LAB_TREE))
    (d / "stack.yaml").write_text(harvest_stack_yaml(d, scenario))
    ep = f"unixsock-stream/{d}/router.sock"
    run_id = "bench-harvest"
    argv = [sys.executable, "-m", "services.cli", "run", "--stack", str(d / "stack.yaml")]
    argv += ["--run-id", run_id, "--listen", ep, "--quiet"]
    t0 = time.monotonic()
    with open(d / "out.log", "wb") as log:
        p = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    health: list[tuple[float, str, bool]] = []
    collected: list[int] = []
    lock = threading.Lock()

    def on_health(n: str, up: bool) -> None:
        with lock:
            health.append((time.monotonic(), n, up))

    def on_event(_key: str, ev: Any) -> None:
        if ev.event == "fruit_collected":
            with lock:
                collected.append(ev.fruit_id)

    def bus() -> Bus | None:
        try:
            return Bus("bench-observer", BusSettings(connect=(ep,), namespace=f"harvest/{run_id}"))
        except Exception:
            return None

    def after(name: str, up: bool, since: float) -> float | None:
        with lock:
            return next((t for t, n, u in health if n == name and u is up and t > since), None)

    def running_received(name: str) -> int:
        if p.poll() is not None:
            raise RuntimeError(f"the run ended early (exit code {p.returncode})")
        return _received(obs, name)

    def fault_one(name: str) -> dict[str, Any]:
        st = _wait(lambda: obs.query_status(name, 1.0), 120, f"status of {name}")
        if name == "planner":
            _wait(lambda: collected or p.poll() is not None, 300, "the first fruit")
        else:
            base = running_received(name)
            _wait(lambda: running_received(name) >= base + 20, 180, f"{name} progress")
        t_fault = time.monotonic()
        os.kill(st[0].pid, sig)
        t_down = _wait(lambda: after(name, False, t_fault), 30, f"{name}'s liveliness to go")
        t_up = _wait(lambda: after(name, True, t_down), 60, f"{name} back")
        return {
            "service": name,
            "signal": signal.Signals(sig).name,
            "liveliness_lost_s": t_down - t_fault,
            "back_live_s": t_up - t_fault,
        }

    rows: list[dict[str, Any]] = []
    obs: Bus = _wait(bus, 60, "the run's router")
    try:
        obs.watch_health(on_health)
        obs.subscribe("harvest/events", on_event)
        for name in HARVEST_FAULTED:
            rows.append(fault_one(name))
    finally:
        obs.close()
    rc = p.wait(timeout=400)
    wall_s = time.monotonic() - t0
    run_log = d / "rec" / f"{run_id}.log"
    out = run_log.read_text(errors="replace") if run_log.exists() else ""
    states: set[int] = set()
    answered: set[int | None] = set()
    summary = None
    cmd, summ = TOPICS["robot/command"].codec, TOPICS["harvest/summary"].codec
    for m in iter_messages(d / "rec" / f"{run_id}.mcap"):
        if m.topic == "robot/joint_state":
            states.add(m.sequence)
        elif m.topic == "robot/command":
            answered.add(cmd.decode(m.payload).header.answers_seq)
        elif m.topic == "harvest/summary":
            summary = summ.decode(m.payload)
    ticks = max(states) + 1 if states else 0
    fruit = len(LAB_TREE["fruits"])
    harvested = summary is not None and summary.harvested == summary.detected == fruit
    no_collision = summary is not None and summary.collisions == 0
    for r in rows:
        r["restarted"] = f"restarting {r['service']}" in out
        r["survived"] = rc == 0 and r["restarted"] and harvested and no_collision
        r["joint_states_lost"] = ticks - len(states)  # in the whole run, every fault together
        r["ticks_unanswered_in_recording"] = len(states - answered)
    return {
        "signal": signal.Signals(sig).name,
        "exit_code": rc,
        "wall_s": wall_s,
        "ticks": ticks,
        "joint_states_lost": ticks - len(states),
        "ticks_unanswered": len(states - answered),
        "detected": summary.detected if summary else None,
        "harvested": summary.harvested if summary else None,
        "collisions": summary.collisions if summary else None,
        "sim_time_s": summary.sim_time_s if summary else None,
        "planner_resumed": "resumed from" in out,
        "fruit_outcomes": [f"{f.fruit_id}: {f.outcome} {f.reason}".strip() for f in summary.fruits]
        if summary
        else [],
        "faults": rows,
    }


def _router_pid(endpoint: str) -> int:
    """The pid of the run's router process (found by its listen endpoint)."""
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            cmd = (proc / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"services.router" in cmd and endpoint.encode() in cmd:
            return int(proc.name)
    raise RuntimeError(f"no router process listening on {endpoint}")


def _lost(rec: Path, run_id: str, name: str, wall_fault_ns: int, sim_s: float) -> dict[str, Any]:
    """Messages lost: joint-state ticks missing from the recording (all parts; a killed part
    recovered first) and ticks without a command; for the recorder also the lost tail."""
    from schemas import TOPICS
    from services.recorder.inspect import iter_messages
    from services.recorder.recover import recover

    first = rec / f"{run_id}.mcap"
    parts = sorted(rec.glob(f"{run_id}*.mcap"))
    out: dict[str, Any] = {}
    if name == "recorder":
        fixed = rec / "recovered.mcap"
        recover(first, fixed)
        log_ns = [m.log_time_ns for m in iter_messages(fixed)]
        out["recorder_lost_tail_s"] = (wall_fault_ns - max(log_ns)) * 1e-9 if log_ns else None
        parts = [fixed, *[p for p in parts if p != first and p != fixed]]
    states: set[int] = set()
    answered: set[int | None] = set()
    cmd = TOPICS["robot/command"].codec
    for part in parts:
        for m in iter_messages(part):
            if m.topic == "robot/joint_state":
                states.add(m.sequence)
            elif m.topic == "robot/command":
                answered.add(cmd.decode(m.payload).header.answers_seq)
    ticks = round(sim_s * TICK_HZ) + 1
    out["joint_states_lost"] = ticks - len(states & set(range(ticks)))
    if name == "router":  # the outage as the recorder saw it: the longest silence
        t = sorted(m.log_time_ns for m in iter_messages(first) if m.topic == "robot/joint_state")
        out["outage_s"] = max(b - a for a, b in itertools.pairwise(t)) * 1e-9
    out["ticks_unanswered_in_recording"] = len(states - answered)
    return out


def arm_stop(rounds: int = 5) -> dict[str, Any]:
    """The controller as a live process: joint states at 120 Hz for 0.5 s, then none; the time
    from the last joint state sent to the zero-velocity command received, per round."""
    from services.controller import SERVICE
    from services.controller.kinsim import KinematicSim
    from services.controller.scenarios import harvest_target, scene
    from services.runtime.settings import load_settings

    timeout_ms = float(load_settings(SERVICE.settings, {}).model_dump()["joint_state_timeout_ms"])
    d = Path(tempfile.mkdtemp(prefix="hvs-", dir="/tmp"))
    ep = f"unixsock-stream/{d}/r.sock"
    flags = ["-e", ep, "--namespace", "bench/armstop"]
    procs = [
        subprocess.Popen(
            [sys.executable, "-m", "services.router", "-l", ep, "--namespace", "bench/armstop"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    ]
    stops_ms: list[float] = []
    try:
        settings = BusSettings(connect=(ep,), namespace="bench/armstop")
        bus: Bus = _wait(lambda: _try(lambda: Bus("bench", settings)), 30, "router")
        procs.append(
            subprocess.Popen(
                [sys.executable, "-m", "services.controller", *flags, "--time-mode", "live"],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
        )
        _wait(lambda: "controller" in bus.live_services(0.3), 60, "controller")
        got: list[tuple[float, Any]] = []
        lock = threading.Lock()

        def on_cmd(key: str, msg: Any) -> None:
            with lock:
                got.append((time.monotonic(), msg))

        bus.subscribe("robot/command", on_cmd)
        sim = KinematicSim()
        pubs = {k: bus.publisher(k) for k in ("scene/state", "plan/target", "robot/joint_state")}
        fruit = (0.75, 0.05, 1.05)
        seq = itertools.count()
        for _ in range(rounds):
            pubs["scene/state"].put(scene(stamp_ns=sim.stamp_ns, seq=next(seq)))
            t_next = time.monotonic()
            for _ in range(TICK_HZ // 2):
                pubs["plan/target"].put(harvest_target(fruit, stamp_ns=sim.stamp_ns, seq=next(seq)))
                pubs["robot/joint_state"].put(sim.joint_state())
                t_last = time.monotonic()
                sim.tick += 1
                t_next += 1 / TICK_HZ
                time.sleep(max(0.0, t_next - time.monotonic()))

            def stop_cmd(since: float = t_last) -> float | None:
                with lock:
                    for t, m in got:
                        zero = all(v == 0.0 for a in m.arms.values() for v in a.velocity_rad_s)
                        if t > since and m.hold and m.header.answers_seq is None and zero:
                            return t
                return None

            t_stop = _wait(stop_cmd, 5, "the watchdog's zero-velocity command")
            stops_ms.append((t_stop - t_last) * 1e3)
            time.sleep(0.3)
        bus.close()
    finally:
        for pr in reversed(procs):
            pr.terminate()
            pr.wait(timeout=10)
        shutil.rmtree(d, ignore_errors=True)
    return {
        "watchdog_timeout_ms": timeout_ms,
        "arm_stop_ms_rounds": stops_ms,
        "arm_stop_ms": max(stops_ms),
        "arm_stop_ms_median": statistics.median(stops_ms),
        "arm_stop_after_stale_ms": max(stops_ms) - timeout_ms,
    }


def _try(fn: Callable[[], Any]) -> Any:
    try:
        return fn()
    except Exception:
        return None


def run_faults_bench(
    fuzz_cases: int = 500, sim_s: float = 6.0, progress: bool = True, harvest: bool = True
) -> dict[str, Any]:
    """Kill and hang every restartable service once (controller, viz, recorder on a sim-only
    run; detector, tracker, scene, planner during a real harvest), fuzz every service, time
    the arm stop."""
    from services.testkit.fuzz_targets import fuzz_all

    def say(text: str) -> None:
        if progress:
            print(text, file=sys.stderr, flush=True)

    runs = []
    for name in KILLABLE:
        for sig in (signal.SIGKILL, signal.SIGSTOP):
            say(f"fault: {signal.Signals(sig).name} {name} ...")
            runs.append(fault_run(name, sig, sim_s))
    say("fault: SIGKILL router ...")
    router = fault_run("router", signal.SIGKILL, sim_s)
    harvests = []
    for sig in (signal.SIGKILL, signal.SIGSTOP) if harvest else ():
        say(f"harvest: {signal.Signals(sig).name} of {', '.join(HARVEST_FAULTED)} in turn ...")
        harvests.append(harvest_fault_run(sig))
    runs += [r for h in harvests for r in h["faults"]]
    say(f"fuzz: {fuzz_cases} cases per service ...")
    fuzz = fuzz_all(fuzz_cases)
    outcomes = {k: v for k, v in fuzz.items() if not isinstance(v, str)}
    say("arm stop: controller watchdog in live mode ...")
    stop = arm_stop()
    kills = [r for r in runs if r["signal"] == "SIGKILL"]
    hangs = [r for r in runs if r["signal"] == "SIGSTOP"]
    return {
        "kills_tried": len(kills),
        "kills_survived": sum(r["survived"] for r in kills),
        "hangs_tried": len(hangs),
        "hangs_survived": sum(r["survived"] for r in hangs),
        "restart_s_max": max(r["back_live_s"] for r in kills),
        "hang_detected_s_max": max(r["liveliness_lost_s"] for r in hangs),
        "hang_back_live_s_max": max(r["back_live_s"] for r in hangs),
        "messages_lost_after_kill": sum(
            r["joint_states_lost"] for r in kills if r["service"] not in HARVEST_FAULTED
        )
        + sum(h["joint_states_lost"] for h in harvests if h["signal"] == "SIGKILL"),
        "lost_by_service": {r["service"]: r["joint_states_lost"] for r in kills},
        "harvest_runs": [{k: v for k, v in h.items() if k != "faults"} for h in harvests],
        "recorder_lost_tail_s": next(
            r["recorder_lost_tail_s"] for r in kills if r["service"] == "recorder"
        ),
        "router_restart_survived": router["survived"],
        "router_back_live_s": router["back_live_s"],
        "router_outage_s": router["outage_s"],
        "router_ticks_lost": router["joint_states_lost"],
        "fuzz_cases": sum(o.cases for o in outcomes.values()),
        "fuzz_rejected": sum(o.rejected_decode + o.dropped_order for o in outcomes.values()),
        "crashes": sum(len(o.crashes) for o in outcomes.values()),
        "crash_samples": [c for o in outcomes.values() for c in o.crashes][:5],
        "fuzz_per_service": {
            k: (v if isinstance(v, str) else {"cases": v.cases, "crashes": len(v.crashes)})
            for k, v in fuzz.items()
        },
        **stop,
        "runs": [*runs, router],
    }


def table(r: dict[str, Any]) -> str:
    skip = ("runs", "fuzz_per_service", "harvest_runs")
    lines = [f"{k:32} {v}" for k, v in r.items() if k not in skip]
    for h in r.get("harvest_runs", []):
        lines.append(f"{'harvest run, ' + h['signal']:32} {h}")
    lines.append("")
    lines.append(f"{'service':12} {'signal':8} {'survived':9} {'lost s':>7} {'back s':>7} lost")
    for x in r["runs"]:
        lines.append(
            f"{x['service']:12} {x['signal']:8} {x['survived']!s:9} "
            f"{x['liveliness_lost_s']:7.2f} {x['back_live_s']:7.2f} {x['joint_states_lost']}"
        )
    return "\n".join(lines)
