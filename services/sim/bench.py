"""`harvest bench sim`: render time per 640×480 RGB-D frame and the sim's real-time factor.

The sim core runs in-process on one core (pinned), exactly as the service runs it, with every
output encoded by its topic's codec (publishing itself is the bus benchmark's business). A fake
controller keeps both arms moving through the view (the expensive case: arms are redrawn every
frame), then the robot holds still. Figures are measured, never asserted.
"""

from __future__ import annotations

import os
import statistics
import time
from typing import Any

import numpy as np

from schemas.base import ARM_ROLES, ArmRole, Header
from schemas.robot import ArmJointVelocity, JointVelocityCommand
from schemas.topics import TOPICS
from services.robot.model import joint_names


def _pin_one_core() -> int:
    cpus = sorted(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpus[-1]})
    return cpus[-1]


def _command(stamp: int, seq: int, t_s: float) -> JointVelocityCommand:
    """Arms sweeping up and down through the camera's view (within the velocity limits)."""
    a = 0.35 * np.sin(2 * np.pi * t_s / 6.0)
    v = {"cutter_j2": a, "cutter_j4": -a, "collector_j2": -a, "collector_j1": 0.5 * a}
    arms: dict[ArmRole, ArmJointVelocity] = {
        r: ArmJointVelocity(
            names=joint_names(r), velocity_rad_s=tuple(v.get(n, 0.0) for n in joint_names(r))
        )
        for r in ARM_ROLES
    }
    return JointVelocityCommand(header=Header(stamp_ns=stamp, seq=seq, source="bench"), arms=arms)


def _run(core: Any, seconds: float, move: bool) -> dict[str, list[float]]:
    t: dict[str, list[float]] = {"render": [], "frame": [], "tick": [], "wall": []}
    orig = core.renderer.render

    def timed_render(objs: Any) -> Any:
        t0 = time.perf_counter()
        out = orig(objs)
        t["render"].append(time.perf_counter() - t0)
        return out

    core.renderer.render = timed_render
    n = round(seconds * 1e9 / core.s.control_period_ns)
    w0 = time.perf_counter()
    for i in range(n):
        t0 = time.perf_counter()
        groups = core.emit()
        for g in groups:
            for topic, msg in g:
                TOPICS[topic].codec.encode(msg)
        if len(groups) == 2:
            t["frame"].append(time.perf_counter() - t0)
        if move:
            core.handle("robot/command", _command(core.now_ns(), i, core.now_ns() * 1e-9))
        t1 = time.perf_counter()
        core.advance()
        t["tick"].append(time.perf_counter() - t1)
    t["wall"].append(time.perf_counter() - w0)
    core.renderer.render = orig
    return t


def _ms(xs: list[float], q: float) -> float:
    return round(float(np.quantile(np.asarray(xs), q)) * 1e3, 2)


def tiny_renderer_ms(core: Any, frames: int = 5) -> float:
    """pybullet's TinyRenderer on the physics scene (robot, trunk, branches, fruit; no leaves),
    640×480 RGB + depth + segmentation, for comparison."""
    pb, cid = core.physics.pb, core.physics.cid
    T = core.T_world_camera
    eye, fwd, up = T[:3, 3], T[:3, 2], -T[:3, 1]
    view = pb.computeViewMatrix(
        eye.tolist(), (eye + fwd).tolist(), up.tolist(), physicsClientId=cid
    )
    fov = 2 * np.degrees(np.arctan(240 / core.camera.intrinsics.fy_px))
    proj = pb.computeProjectionMatrixFOV(fov, 640 / 480, 0.05, 10.0, physicsClientId=cid)
    ts = []
    for _ in range(frames):
        t0 = time.perf_counter()
        pb.getCameraImage(640, 480, view, proj, renderer=pb.ER_TINY_RENDERER, physicsClientId=cid)
        ts.append(time.perf_counter() - t0)
    return round(statistics.median(ts) * 1e3, 1)


def run_sim_bench(
    scenario: str = "paper-exp1", seconds: float = 10.0, tiny: bool = True
) -> dict[str, Any]:
    from services.sim import Settings
    from services.sim.core import SimCore
    from services.sim.render.renderer import Renderer

    cpu = _pin_one_core()
    settings = Settings(scenario=scenario)
    core = SimCore(settings)
    t0 = time.perf_counter()
    core.camera_group(0)  # the first frame draws everything (then the still objects are cached)
    first_ms = (time.perf_counter() - t0) * 1e3
    moving = _run(core, seconds, move=True)
    still = _run(core, min(seconds, 4.0), move=False)
    fresh = Renderer(core.camera, core.T_world_camera, cache=False)
    objs = core.scene_objects()
    ts = []
    for _ in range(3):
        t0 = time.perf_counter()
        fresh.render(objs)
        ts.append(time.perf_counter() - t0)
    sim_s = len(moving["tick"]) * core.dt
    out: dict[str, Any] = {
        "scenario": scenario,
        "cpu": cpu,
        "sim_seconds": round(sim_s, 3),
        "rtf": round(sim_s / moving["wall"][0], 3),
        "rtf_robot_still": round(len(still["tick"]) * core.dt / still["wall"][0], 3),
        "render_ms_p50": _ms(moving["render"], 0.5),
        "render_ms_p90": _ms(moving["render"], 0.9),
        "render_ms_p50_robot_still": _ms(still["render"], 0.5),
        "frame_ms_p50": _ms(moving["frame"], 0.5),
        "tick_ms_p50": _ms(moving["tick"], 0.5),
        "render_uncached_ms": round(statistics.median(ts) * 1e3, 1),
        "first_frame_ms": round(first_ms, 1),
        "control_hz": round(1e9 / settings.control_period_ns, 2),
        "camera_hz": round(1e9 / settings.control_period_ns / settings.camera_every_ticks, 2),
    }
    if tiny:
        out["tinyrenderer_ms_p50"] = tiny_renderer_ms(core)
    core.close()
    return out


def table(r: dict[str, Any]) -> str:
    return "\n".join(f"{k:28s} {v}" for k, v in r.items())
