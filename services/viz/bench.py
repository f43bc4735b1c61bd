"""Viz benchmark (`harvest bench viz`): what drawing a run costs.

* ``columns``: µs per row, ``log`` per row against buffered ``send_columns`` (joint transforms of
  both arms, and one 7-series scalar plot), into an in-memory recording;
* ``offline``: `harvest view`'s conversion of a synthetic 640×480 recording (15 Hz RGB-D, 100 Hz
  joint states and controller status): sim seconds per wall second, .rrd MB per sim minute;
* ``live``: CPU of the viz process (% of one core) drawing the same stream live at its real
  pace, with the default settings and with raw (not JPEG) images.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from schemas import ARM_ROLES, ArmJointState, ControlStatus, Header, JointState, RgbdFrame
from schemas.topics import TOPICS
from services.bus import BusSettings, bus_args
from services.bus.bench import BenchEnv, cpu_seconds, frame_msg, test_images
from services.robot.model import joint_names

TICK_NS, FRAME_NS = 10_000_000, 66_666_667  # 100 Hz control, 15 Hz camera


def stream(seconds: float) -> Iterator[tuple[str, Any]]:
    """``seconds`` of sim time: RGB-D frames, joint states and controller status."""
    rgb, depth = test_images()
    frame = 0
    for i in range(int(seconds * 100)):
        t = i * TICK_NS
        while frame * FRAME_NS <= t:
            f = frame_msg(frame, rgb, depth)
            h = f.meta.header.model_copy(update={"stamp_ns": frame * FRAME_NS})
            yield "camera/rgbd", RgbdFrame(f.meta.model_copy(update={"header": h}), rgb, depth)
            frame += 1
        arms = {
            role: ArmJointState(
                names=joint_names(role),
                position_rad=tuple(0.5 * math.sin(t * 1e-9 + j) for j in range(7)),
                velocity_rad_s=tuple(0.5 * math.cos(t * 1e-9 + j) for j in range(7)),
            )
            for role in ARM_ROLES
        }
        yield (
            "robot/joint_state",
            JointState(header=Header(stamp_ns=t, seq=i, source="b"), arms=arms),
        )
        yield (
            "control/status",
            ControlStatus(
                header=Header(stamp_ns=t, seq=i, source="b", answers_seq=i),
                abs_position_error_m=0.01,
                abs_orientation_error_rad=0.02,
                rel_position_error_m=0.01,
                rel_orientation_error_rad=0.02,
                min_distance_trunk_m=0.2,
                converged=False,
            ),
        )


def bench_columns(rows: int = 2000) -> dict[str, float]:
    """µs per row: one ``log`` call per row against buffered ``send_columns``."""
    import rerun as rr

    from services.viz import Settings
    from services.viz.out import Out
    from services.viz.robot import load_urdf

    tree = load_urdf(Settings().urdf_path)
    joints = [j for j in tree.joints() if j.joint_type == "revolute"]
    rec = rr.RecordingStream("bench", recording_id="columns")
    rec.save(str(Path(tempfile.mkdtemp(prefix="bench-viz-")) / "columns.rrd"))
    out = Out(rec, max_rows=10**9)
    values = np.random.default_rng(0).uniform(-1, 1, (rows, 7))
    res: dict[str, float] = {}
    t0 = time.perf_counter()
    for i in range(rows):
        out.at(i * TICK_NS)
        for j in joints:
            rec.log(f"/log/{j.name}", j.compute_transform(float(values[i, 0]), clamp=False))
    res["joint_transforms_log_us_per_row"] = (time.perf_counter() - t0) / rows * 1e6
    t0 = time.perf_counter()
    for i in range(rows):
        for j in joints:
            out.joint(f"/cols/{j.name}", j, i * TICK_NS, float(values[i, 0]))
    out.flush()
    res["joint_transforms_columns_us_per_row"] = (time.perf_counter() - t0) / rows * 1e6
    t0 = time.perf_counter()
    for i in range(rows):
        out.at(i * TICK_NS)
        rec.log("/log/scalars", rr.Scalars(values[i]))
    res["scalars7_log_us_per_row"] = (time.perf_counter() - t0) / rows * 1e6
    t0 = time.perf_counter()
    for i in range(rows):
        out.scalars("/cols/scalars", i * TICK_NS, values[i])
    out.flush()
    res["scalars7_columns_us_per_row"] = (time.perf_counter() - t0) / rows * 1e6
    return res


def bench_offline(seconds: float) -> dict[str, float]:
    """`harvest view`'s conversion of a synthetic recording of ``seconds`` sim seconds."""
    from services.recorder.writer import RunWriter
    from services.viz import Settings
    from services.viz.offline import convert
    from services.viz.sink import open_stream

    d = Path(tempfile.mkdtemp(prefix="bench-viz-"))
    mcap, rrd = d / "run.mcap", d / "run.rrd"
    with open(mcap, "wb") as f:
        w = RunWriter(f)
        for n, (topic, msg) in enumerate(stream(seconds)):
            codec = TOPICS[topic].codec
            w.write(topic, codec.encode(msg), codec.zenoh_encoding, n)
        w.finish()
    settings = Settings()
    rec = open_stream(settings, "bench", rrd)
    t0 = time.perf_counter()
    report = convert(mcap, rec, settings)
    rec.flush()
    rec.disconnect()
    wall = time.perf_counter() - t0
    return {
        "offline_sim_s_per_wall_s": seconds / wall,
        "offline_messages_per_s": report.messages / wall,
        "offline_rrd_mb_per_sim_min": rrd.stat().st_size / 1e6 * 60 / seconds,
        "mcap_mb_per_sim_min": mcap.stat().st_size / 1e6 * 60 / seconds,
    }


def bench_live(seconds: float, settings_json: str) -> dict[str, float]:
    """CPU of a viz process drawing ``seconds`` of the stream at its real pace."""
    env = BenchEnv()
    rrd = env.dir / "live.rrd"
    settings = {**json.loads(settings_json), "save_path": str(rrd)}
    bus = bus_args(BusSettings(connect=(env.endpoint,), namespace=env.ns))
    viz = subprocess.Popen(
        [sys.executable, "-m", "services.viz", "--settings-json", json.dumps(settings), *bus],
        stderr=subprocess.DEVNULL,
    )
    try:
        env.wait_live("viz")
        keys = ("camera/rgbd", "robot/joint_state", "control/status")
        pubs = {k: env.bus.publisher(k) for k in keys}
        cpu0, t0 = cpu_seconds(viz.pid), time.monotonic()
        for topic, msg in stream(seconds):
            lag = msg.header.stamp_ns * 1e-9 - (time.monotonic() - t0)
            if lag > 0:
                time.sleep(lag)
            pubs[topic].put(msg)
        time.sleep(0.5)  # let the last flush happen inside the window
        cpu1, t1 = cpu_seconds(viz.pid), time.monotonic()
        viz.send_signal(signal.SIGTERM)
        viz.wait(timeout=60)
    finally:
        if viz.poll() is None:
            viz.kill()
        env.close()
    return {
        "live_cpu_pct": 100.0 * (cpu1 - cpu0) / (t1 - t0),
        "live_rrd_mb_per_sim_min": rrd.stat().st_size / 1e6 * 60 / seconds,
    }


def run_viz_bench(seconds: float = 10.0, rounds: int = 3, progress: bool = True) -> dict[str, Any]:
    """Medians over ``rounds``; the live variants are interleaved."""

    def say(text: str) -> None:
        if progress:
            print(f"  {text}", file=sys.stderr, flush=True)

    res: dict[str, Any] = {"seconds": seconds, "rounds": rounds}
    per: dict[str, list[float]] = {}
    variants = {"": "{}", "_raw_images": '{"image_jpeg_quality": 0}'}
    for r in range(rounds):
        say(f"round {r + 1}/{rounds}: log vs send_columns")
        for k, v in bench_columns().items():
            per.setdefault(k, []).append(v)
        say(f"round {r + 1}/{rounds}: offline conversion of {seconds:.0f} sim s")
        for k, v in bench_offline(seconds).items():
            per.setdefault(k, []).append(v)
        for suffix, settings_json in variants.items():
            say(f"round {r + 1}/{rounds}: live viz {settings_json}")
            for k, v in bench_live(seconds, settings_json).items():
                per.setdefault(k + suffix, []).append(v)
    for k, values in per.items():
        res[k] = float(np.median(values))
        res[f"{k}_rounds"] = values
    return res
