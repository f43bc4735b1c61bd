"""`harvest bench controller`: cycle time against the number of fruit obstacles, and reach on a
fixed set of random reachable targets, in closed loop with the kinematic sim.

* Cycle: the controller core's whole tick (`core.handle(joint_state)`: distances, dampers, both
  QPs, the limit check, building the output messages), with 0, 10, 50 and 200 fruit (plus the
  trunk) while it drives the cutter through a sequence of harvest targets. Message I/O — decoding
  the joint-state payload and encoding the command, status and diagnostics — is timed apart.
* Reach: 100 targets drawn (seeded) in the camera's view and kept when the position-level IK of
  `services/robot/reach.py` reaches them; each run starts from the ready posture and counts as
  reached when the status says converged within the time limit. An independent monitor checks
  joint limits, velocity limits and self-collision distances on every tick.
"""

from __future__ import annotations

import gc
import os
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from schemas import TOPICS
from services.controller.kinsim import SIM_PERIOD_NS, KinematicSim, SafetyMonitor
from services.controller.scenarios import (
    LoopResult,
    branch_field,
    fruit,
    fruit_field,
    harvest_target,
    run_loop,
    scene,
)

OBSTACLE_COUNTS = (0, 10, 50, 200)
BRANCH_CASE = (50, 200)  # 50 fruit and the scene's cap of occupied-space spheres (branches)
CYCLE_TARGETS = ((0.75, 0.05, 1.05), (0.7, -0.25, 0.95), (0.85, 0.2, 1.2), (0.6, 0.0, 1.3))
TRUNK_XY_M = (1.05, 0.0)


def _pct(xs: list[float], p: float) -> float:
    return float(np.percentile(np.array(xs), p)) if xs else float("nan")


def cycle_times(
    n_fruit: int, ticks: int, seed: int, settings: Any, n_spheres: int = 0
) -> dict[str, float]:
    """Per-tick wall times (ms) of the core and of the message I/O with ``n_fruit`` fruit (and
    ``n_spheres`` occupied-space spheres along branches from the trunk)."""
    from services.controller.core import ControllerCore

    rng = np.random.default_rng(seed)
    core = ControllerCore(settings)
    sim = KinematicSim()
    jcodec = TOPICS["robot/joint_state"].codec
    # n_fruit in all: the fruit of the targets (each ignored while it is the target) and the
    # rest spread around; 0 leaves the trunk alone.
    targets = [fruit(i + 1, p) for i, p in enumerate(CYCLE_TARGETS)][:n_fruit]
    field = fruit_field(n_fruit - len(targets), rng) if n_fruit > len(targets) else []
    sc = scene([*targets, *field], trunk_xy_m=TRUNK_XY_M)
    if n_spheres:
        spheres = branch_field(n_spheres, rng, TRUNK_XY_M, keep_clear_of=CYCLE_TARGETS)
        sc = sc.model_copy(
            update={"obstacles": sc.obstacles.model_copy(update={"spheres": tuple(spheres)})}
        )
    core.handle("scene/state", sc)
    cycle, cpu, io, dist, solve, near, dampers = [], [], [], [], [], [], []
    per_target = max(1, ticks // len(CYCLE_TARGETS))
    warmup = 20
    for k in range(ticks + warmup):
        t_i = min(k // per_target, len(CYCLE_TARGETS) - 1)
        tgt = harvest_target(CYCLE_TARGETS[t_i], fruit_id=t_i + 1, stamp_ns=sim.stamp_ns, seq=k)
        core.handle("plan/target", tgt)
        t0 = time.perf_counter()
        js = jcodec.decode(jcodec.encode(sim.joint_state()))  # what the Node hands the core
        t1 = time.perf_counter()
        c1 = time.thread_time()
        outs = core.handle("robot/joint_state", js)
        c2 = time.thread_time()
        t2 = time.perf_counter()
        for topic, msg in outs:
            TOPICS[topic].codec.encode(msg)
        t3 = time.perf_counter()
        o = dict(outs)
        sim.apply(o["robot/command"])
        if k < warmup:
            continue
        cycle.append((t2 - t1) * 1e3)
        cpu.append((c2 - c1) * 1e3)
        # the I/O a Node adds: decode the input (its encode is the sim's), encode the outputs
        io.append(((t1 - t0) / 2 + (t3 - t2)) * 1e3)
        d = o["diag/controller"]
        dist.append(d.distance_ms)
        solve.append(d.solve_ms)
        near.append(d.obstacles_near)
        dampers.append(o["control/status"].active_dampers)
    return {
        "cycle_p50_ms": _pct(cycle, 50),
        "cycle_p99_ms": _pct(cycle, 99),
        "cycle_max_ms": max(cycle),
        # CPU time of the thread: the work itself, without the time other processes held
        # the core (this machine is shared; wall-clock tails are mostly preemption)
        "cycle_cpu_p50_ms": _pct(cpu, 50),
        "cycle_cpu_p99_ms": _pct(cpu, 99),
        "io_p50_ms": _pct(io, 50),
        "io_p99_ms": _pct(io, 99),
        "distance_p50_ms": _pct(dist, 50),
        "solve_p50_ms": _pct(solve, 50),
        "solve_p99_ms": _pct(solve, 99),
        "obstacles_near_mean": float(np.mean(near)),
        "active_dampers_mean": float(np.mean(dampers)),
        "ticks": len(cycle),
    }


def reachable_targets(
    n: int, seed: int, progress: Callable[[int], None] | None = None
) -> list[np.ndarray]:
    """``n`` fruit positions (world, m) drawn in the camera's view that the IK reaches."""
    from services.robot.reach import ReachSolver

    rng = np.random.default_rng(seed)
    ik = ReachSolver()
    out: list[np.ndarray] = []
    while len(out) < n:
        depth = rng.uniform(0.4, 0.9)
        p = ik.fruit_in_camera(
            depth, rng.uniform(-0.35, 0.35) * depth, rng.uniform(-0.2, 0.2) * depth
        )
        if ik.reach(p).reached:
            out.append(p)
            if progress:
                progress(len(out))
    return out


def reach_run(
    targets: list[np.ndarray],
    settings: Any,
    max_s: float = 10.0,
    progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Closed-loop reach of every target from the ready posture."""
    from services.controller.core import ControllerCore

    safety = {"self": settings.self_collision.safety_m}
    core = ControllerCore(settings)
    monitor = SafetyMonitor()
    max_ticks = int(max_s * 1e9 / SIM_PERIOD_NS)
    times, failed, violations = [], [], 0
    worst_speed = 0.0
    min_self = np.inf
    tick = 0
    for i, p in enumerate(targets):
        # Back to the ready posture; the clock goes on (a controller never sees time go back).
        sim = KinematicSim(start_tick=tick)
        res: LoopResult = run_loop(
            core,
            sim,
            harvest_target(p, fruit_id=1),
            scene([fruit(1, p)]),
            max_ticks,
            monitor=monitor,
            safety_m=safety,
        )
        tick = sim.tick
        violations += len(res.safety.violations)
        worst_speed = max(worst_speed, res.safety.max_speed_ratio)
        min_self = min(min_self, res.safety.min_distance_m["self"])
        if res.converged_tick is None:
            last = res.statuses[-1]
            failed.append(
                {
                    "fruit_world_m": [round(float(v), 4) for v in p],
                    "abs_position_error_m": last.abs_position_error_m,
                    "rel_position_error_m": last.rel_position_error_m,
                    "rel_orientation_error_rad": last.rel_orientation_error_rad,
                    "reason": last.reason,
                }
            )
        else:
            times.append((res.converged_tick + 1) * SIM_PERIOD_NS * 1e-9)
        if progress:
            progress(i + 1)
    return {
        "reach_targets": len(targets),
        "reach_success": len(times) / len(targets) if targets else float("nan"),
        "reach_time_p50_s": _pct(times, 50),
        "reach_time_max_s": max(times) if times else float("nan"),
        "violations": violations,
        "max_speed_ratio": worst_speed,
        "min_self_distance_m": float(min_self),
        "reach_failures": failed,
    }


def run_controller_bench(
    ticks: int = 2000,
    targets: int = 100,
    seed: int = 6,
    progress: bool = True,
    sets: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Every figure of BENCHMARKS.md's controller section, as one flat dict; ``sets``:
    controller settings other than the defaults (a bad one raises SettingsError naming it)."""
    from services.controller import SERVICE
    from services.runtime.settings import load_settings

    settings = load_settings(SERVICE.settings, {}, sets or {}, service="controller")
    out: dict[str, Any] = {
        "ticks_per_case": ticks,
        "seed": seed,
        "settings": sets or {},
        "cpu_count": os.cpu_count(),
        "load_avg_1min_before": os.getloadavg()[0],
    }
    bar: Any = None
    if progress:
        from rich.progress import Progress

        bar = Progress(transient=True)
        bar.start()
    try:
        task = bar.add_task("cycle time", total=len(OBSTACLE_COUNTS) + 1) if bar else None
        gc.collect()
        for n in OBSTACLE_COUNTS:
            for key, v in cycle_times(n, ticks, seed, settings).items():
                out[f"{key}_{n}"] = v
            if bar:
                bar.advance(task)
        n_fruit, n_spheres = BRANCH_CASE
        for key, v in cycle_times(n_fruit, ticks, seed, settings, n_spheres).items():
            out[f"{key}_{n_fruit}+{n_spheres}s"] = v
        if bar:
            bar.advance(task)
        if targets:
            t_task = bar.add_task("reachable targets (IK)", total=targets) if bar else None
            pts = reachable_targets(
                targets, seed, (lambda i: bar.update(t_task, completed=i)) if bar else None
            )
            r_task = bar.add_task("closed-loop reach", total=targets) if bar else None
            out.update(
                reach_run(
                    pts,
                    settings,
                    progress=(lambda i: bar.update(r_task, completed=i)) if bar else None,
                )
            )
    finally:
        if bar:
            bar.stop()
    out["load_avg_1min_after"] = os.getloadavg()[0]
    return out


def table(r: dict[str, Any]) -> str:
    head = (
        "fruit",
        "cycle p50",
        "p99",
        "max",
        "CPU p50",
        "p99",
        "I/O p50",
        "p99",
        "solve p50",
        "near",
    )
    lines = [
        f"load average {r['load_avg_1min_before']:.1f} → {r['load_avg_1min_after']:.1f} "
        f"on {r['cpu_count']} CPUs; times in ms; near = obstacles past the broad phase",
        "  ".join(f"{h:>9s}" for h in head),
    ]
    cases = [str(n) for n in OBSTACLE_COUNTS] + ["{}+{}s".format(*BRANCH_CASE)]
    for n in cases:
        if f"cycle_p50_ms_{n}" not in r:
            continue
        keys = [
            *("cycle_p50", "cycle_p99", "cycle_max", "cycle_cpu_p50", "cycle_cpu_p99"),
            *("io_p50", "io_p99", "solve_p50"),
        ]
        vals = [r[f"{k}_ms_{n}"] for k in keys]
        cells = [f"{n:>9s}", *(f"{v:9.3f}" for v in vals), f"{r[f'obstacles_near_mean_{n}']:9.1f}"]
        lines.append("  ".join(cells))
    lines.append("(50+200s: 50 fruit and 200 occupied-space spheres along branches)")
    if "reach_success" in r:
        lines.append(
            f"reach: {100 * r['reach_success']:.0f} % of {r['reach_targets']} reachable targets, "
            f"time p50 {r['reach_time_p50_s']:.2f} s (max {r['reach_time_max_s']:.2f} s), "
            f"{r['violations']} violations, peak joint speed {100 * r['max_speed_ratio']:.0f} % "
            f"of the limit, min self distance {1e3 * r['min_self_distance_m']:.1f} mm"
        )
        for f in r["reach_failures"]:
            lines.append(f"  not reached: {f}")
    return "\n".join(lines)
