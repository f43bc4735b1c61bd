"""Bus benchmark: our bus against raw zenoh-python, measured in the same run, same topology.

It lives in the bus package because its baseline is raw zenoh. Two processes on loopback
through the Python router (TCP), both clients with the same Zenoh settings. One-way latency =
CLOCK_MONOTONIC in the subscriber after decode minus CLOCK_MONOTONIC in the publisher before
encode (one host, one clock).

    python -m services.bus.bench sub --mode ours|raw|node --kind small|frame --out F ...

is the subscriber side; `harvest bench bus` runs everything.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from schemas import CameraIntrinsics, Detection, Detections, Header, Pose, RgbdFrame, RgbdFrameMeta
from schemas.topics import TOPICS
from services.bus import Bus, BusSettings, bus_args

SMALL_KEY, FRAME_KEY = "perception/detections", "camera/rgbd"
W, H = 640, 480
_STAMP = struct.Struct("<q")


# ---- messages ---------------------------------------------------------------------------------
def small_msg(seq: int) -> Detections:
    """A ~200-byte JSON message (one detection), stamped with the monotonic clock."""
    h = Header(stamp_ns=time.monotonic_ns(), seq=seq, source="b")
    box = Detection(xyxy_px=(100, 120, 180, 200), score=0.93)
    return Detections(
        header=h, image_width_px=W, image_height_px=H, detector="n", detections=(box,)
    )


def frame_msg(seq: int, rgb: np.ndarray, depth: np.ndarray) -> RgbdFrame:
    h = Header(stamp_ns=time.monotonic_ns(), seq=seq, frame_id="camera_optical", source="bench")
    intr = CameraIntrinsics(
        width_px=W, height_px=H, fx_px=615.0, fy_px=615.0, cx_px=320.0, cy_px=240.0
    )
    meta = RgbdFrameMeta(header=h, intrinsics=intr, T_world_camera=Pose(position_m=(0, 0, 1.5)))
    return RgbdFrame(meta, rgb, depth)


def test_images() -> tuple[np.ndarray, np.ndarray]:
    """A camera-like RGB-D frame (sky, foliage texture, fruit discs, a trunk, sensor noise), so
    that compression costs what it costs on real frames (random bytes compress trivially)."""
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    rgb = np.empty((H, W, 3), np.float32)
    rgb[..., 0] = 120 + 60 * yy / H
    rgb[..., 1] = 160 + 40 * yy / H
    rgb[..., 2] = 230 - 30 * yy / H
    leaves = (np.sin(xx / 7.0) * np.cos(yy / 5.0) + rng.normal(0, 0.6, (H, W))) > 0.2
    rgb[leaves] = (40, 110, 35)
    rgb[:, 300:340] = (110, 80, 55)  # trunk
    for cx, cy, r in rng.uniform((60, 60, 18), (W - 60, H - 60, 40), (12, 3)):
        rgb[(xx - cx) ** 2 + (yy - cy) ** 2 < r * r] = (235, 140, 25)
    rgb += rng.normal(0, 3, rgb.shape)
    depth = 900 + 0.8 * yy + 200 * leaves + rng.normal(0, 4, (H, W))
    depth[rng.random((H, W)) < 0.02] = 0  # invalid pixels
    return np.clip(rgb, 0, 255).astype(np.uint8), np.clip(depth, 0, 65535).astype(np.uint16)


# ---- subscriber process ----------------------------------------------------------------------
def sub_main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--mode", choices=["ours", "raw", "node"], required=True)
    ap.add_argument("--kind", choices=["small", "frame"], required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--endpoint", required=True)
    ap.add_argument("--namespace", required=True)
    args = ap.parse_args(argv)
    key = SMALL_KEY if args.kind == "small" else FRAME_KEY
    lat_ns: list[int] = []
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    settings = BusSettings(connect=(args.endpoint,), namespace=args.namespace)
    bus = Bus(f"bench-sub-{args.mode}", settings)
    if args.mode == "raw":

        def on_raw(s: Any) -> None:
            data = s.payload.to_bytes()
            lat_ns.append(time.monotonic_ns() - _STAMP.unpack_from(data)[0])

        bus._handles.append(bus.session.declare_subscriber(key, on_raw))  # raw zenoh path
    elif args.mode == "ours":
        bus.subscribe(key, lambda _k, m: lat_ns.append(time.monotonic_ns() - m.header.stamp_ns))
    else:
        _node_sub(bus, key, lat_ns, stop)
    bus.declare_health()
    stop.wait()
    bus.close()
    args.out.write_text(json.dumps(lat_ns))
    return 0


def _node_sub(bus: Bus, key: str, lat_ns: list[int], stop: threading.Event) -> None:
    """The Node's path: decode on the Zenoh thread, queue, hand over to one worker thread."""
    from collections import deque

    q: deque[Any] = deque()
    cv = threading.Condition()

    def on_msg(_k: str, m: Any) -> None:
        with cv:
            q.append(m)
            cv.notify()

    def worker() -> None:
        while not stop.is_set():
            with cv:
                if not q:
                    cv.wait(0.1)
                items = list(q)
                q.clear()
            now = time.monotonic_ns()
            lat_ns.extend(now - m.header.stamp_ns for m in items)

    bus.subscribe(key, on_msg)
    threading.Thread(target=worker, daemon=True).start()


# ---- orchestration ---------------------------------------------------------------------------
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class BenchEnv:
    """A private router on a free TCP port and a publisher session (also used by the viz bench)."""

    def __init__(self) -> None:
        self.dir = Path(tempfile.mkdtemp(prefix="bench-bus-"))
        self.endpoint = f"tcp/127.0.0.1:{_free_port()}"
        self.ns = "bench"
        self.router = subprocess.Popen(
            [sys.executable, "-m", "services.router", "-l", self.endpoint],
            stderr=subprocess.DEVNULL,
        )
        self.bus = self._connect()

    def _connect(self) -> Bus:
        deadline = time.monotonic() + 20
        while True:
            try:
                return Bus("bench-pub", BusSettings(connect=(self.endpoint,), namespace=self.ns))
            except Exception:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)

    def wait_live(self, name: str) -> None:
        deadline = time.monotonic() + 30
        while name not in self.bus.live_services(0.3):
            if time.monotonic() > deadline:
                raise RuntimeError(f"{name} did not come up")

    def close(self) -> None:
        self.bus.close()
        self.router.terminate()
        self.router.wait()


def _measure(env: BenchEnv, mode: str, kind: str, rate_hz: float, seconds: float) -> list[int]:
    out = env.dir / f"{mode}-{kind}.json"
    sub = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "services.bus.bench",
            "sub",
            "--mode",
            mode,
            "--kind",
            kind,
            "--out",
            str(out),
            "--endpoint",
            env.endpoint,
            "--namespace",
            env.ns,
        ]
    )
    env.wait_live(f"bench-sub-{mode}")
    key = SMALL_KEY if kind == "small" else FRAME_KEY
    n = int(rate_hz * seconds) + 20
    rgb, depth = test_images()
    if mode == "raw":
        import zenoh

        pub = env.bus.session.declare_publisher(
            key, congestion_control=zenoh.CongestionControl.BLOCK, express=True
        )
        size = len(
            TOPICS[key].codec.encode(small_msg(0) if kind == "small" else frame_msg(0, rgb, depth))
        )
        filler = bytes(size - 8)

        def send(i: int) -> None:
            pub.put(_STAMP.pack(time.monotonic_ns()) + filler)
    else:
        typed = env.bus.publisher(key)

        def send(i: int) -> None:
            typed.put(small_msg(i) if kind == "small" else frame_msg(i, rgb, depth))

    period = 1.0 / rate_hz
    t_next = time.monotonic()
    for i in range(n):
        send(i)
        t_next += period
        delay = t_next - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    time.sleep(0.3)
    sub.send_signal(signal.SIGTERM)
    sub.wait(timeout=30)
    lat = json.loads(out.read_text())
    return lat[20:]  # warm-up


def _recorder_cpu(env: BenchEnv, seconds: float, settings_json: str = "{}") -> dict[str, float]:
    out = env.dir / "rec.mcap"
    rec = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "services.recorder",
            "--out",
            str(out),
            "--settings-json",
            settings_json,
            *bus_args(BusSettings(connect=(env.endpoint,), namespace=env.ns)),
        ],
        stderr=subprocess.DEVNULL,
    )
    env.wait_live("recorder")
    pub = env.bus.publisher(FRAME_KEY)
    rgb, depth = test_images()
    period = 1 / 15.0
    for i in range(15):  # warm-up
        pub.put(frame_msg(i, rgb, depth))
        time.sleep(period)
    cpu0, t0 = cpu_seconds(rec.pid), time.monotonic()
    t_next = t0
    for i in range(15, 15 + int(15 * seconds)):
        pub.put(frame_msg(i, rgb, depth))
        t_next += period
        time.sleep(max(0.0, t_next - time.monotonic()))
    time.sleep(0.6)  # let the last flush happen inside the window
    cpu1, t1 = cpu_seconds(rec.pid), time.monotonic()
    rec.send_signal(signal.SIGTERM)
    rec.wait(timeout=30)
    return {
        "recorder_cpu_pct_15hz": 100.0 * (cpu1 - cpu0) / (t1 - t0),
        "recorder_mb_written": out.stat().st_size / 1e6,
    }


RECORDER_VARIANTS = {
    "": "{}",
    "_no_preview": '{"preview": "none"}',
    "_raw_preview": '{"preview": "raw"}',
    "_full_jpeg_preview": '{"preview_scale": 1.0}',
}
"""Default settings (JPEG camera preview at half resolution), no preview, a lossless rgb8 preview
at half resolution, a JPEG preview at full resolution."""


def _recorder_rounds(seconds: float, rounds: int, progress: bool) -> dict[str, Any]:
    """Recorder CPU and file size, with and without the camera preview, interleaved; medians."""
    per: dict[str, list[dict[str, float]]] = {k: [] for k in RECORDER_VARIANTS}
    for r in range(rounds):
        for suffix, settings_json in RECORDER_VARIANTS.items():
            if progress:
                print(
                    f"  round {r + 1}/{rounds}: recorder at 15 Hz RGB-D {settings_json}",
                    file=sys.stderr,
                    flush=True,
                )
            env = BenchEnv()
            try:
                per[suffix].append(_recorder_cpu(env, max(seconds, 5.0), settings_json))
            finally:
                env.close()
    out: dict[str, Any] = {}
    for suffix, results in per.items():
        for key in results[0]:
            values = [x[key] for x in results]
            out[f"{key}{suffix}"] = float(np.median(values))
            out[f"{key}{suffix}_rounds"] = values
    return out


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _pct(lat_ns: list[int], q: float) -> float:
    return float(np.percentile(np.asarray(lat_ns, dtype=np.float64), q))


def run_bus_bench(seconds: float = 3.0, rounds: int = 3, progress: bool = True) -> dict[str, Any]:
    """Each case runs ``rounds`` times, ours and raw interleaved, each on a fresh router and
    sessions; figures are medians over rounds (this VM's latency is bimodal from run to run),
    ratios are the median of the paired per-round ratios."""
    cases = [("small", 1000.0), ("frame", 30.0)]
    per: dict[tuple[str, str], list[tuple[float, float]]] = {}
    res: dict[str, Any] = {
        "seconds_per_case": seconds,
        "rounds": rounds,
        "cpu_count": os.cpu_count(),
    }
    for r in range(rounds):
        for kind, rate in cases:
            for mode in ("ours", "raw", "node") if kind == "small" else ("ours", "raw"):
                if progress:
                    print(
                        f"  round {r + 1}/{rounds}: {kind} messages at {rate:.0f} Hz "
                        f"through {mode}",
                        file=sys.stderr,
                        flush=True,
                    )
                env = BenchEnv()
                try:
                    lat = _measure(env, mode, kind, rate, seconds)
                finally:
                    env.close()
                per.setdefault((mode, kind), []).append((_pct(lat, 50), _pct(lat, 99)))
    for (mode, kind), vals in per.items():
        prefix = {"ours": "", "raw": "raw_", "node": "node_"}[mode]
        scale, unit = (1e3, "us") if kind == "small" else (1e6, "ms")
        p50s = [v[0] / scale for v in vals]
        res[f"{prefix}{kind}_p50_{unit}"] = float(np.median(p50s))
        res[f"{prefix}{kind}_p99_{unit}"] = float(np.median([v[1] / scale for v in vals]))
        res[f"{prefix}{kind}_p50_{unit}_rounds"] = p50s
    for kind in ("small", "frame"):
        pairs = zip(per[("ours", kind)], per[("raw", kind)], strict=True)
        res[f"{kind}_ratio_p50"] = float(np.median([o[0] / w[0] for o, w in pairs]))
    res.update(_recorder_rounds(seconds, rounds, progress))
    res["small_bytes"] = len(TOPICS[SMALL_KEY].codec.encode(small_msg(0)))
    res["frame_bytes"] = len(TOPICS[FRAME_KEY].codec.encode(frame_msg(0, *test_images())))
    return res


def table(r: dict[str, Any]) -> str:
    rows = [
        (
            f"small {r['small_bytes']} B @1 kHz p50/p99 µs",
            f"{r['small_p50_us']:.0f} / {r['small_p99_us']:.0f}",
            f"{r['raw_small_p50_us']:.0f} / {r['raw_small_p99_us']:.0f}",
            f"{r['small_ratio_p50']:.2f}",
        ),
        (
            "  via the Node worker thread",
            f"{r['node_small_p50_us']:.0f} / {r['node_small_p99_us']:.0f}",
            "",
            "",
        ),
        (
            "RGB-D 640x480 @30 Hz p50/p99 ms",
            f"{r['frame_p50_ms']:.2f} / {r['frame_p99_ms']:.2f}",
            f"{r['raw_frame_p50_ms']:.2f} / {r['raw_frame_p99_ms']:.2f}",
            f"{r['frame_ratio_p50']:.2f}",
        ),
    ]
    lines = [f"{'case':36} {'ours':>16} {'raw zenoh':>16} {'ratio':>6}"]
    lines += [f"{a:36} {b:>16} {c:>16} {d:>6}" for a, b, c, d in rows]
    lines.append(
        f"recorder CPU at 15 Hz RGB-D: {r['recorder_cpu_pct_15hz']:.1f} % of one core with the "
        f"camera preview, {r['recorder_cpu_pct_15hz_no_preview']:.1f} % without; file "
        f"{r['recorder_mb_written']:.1f} MB vs {r['recorder_mb_written_no_preview']:.1f} MB"
    )
    return "\n".join(lines)


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "sub":
        sys.exit(sub_main(sys.argv[2:]))
    print(json.dumps(run_bus_bench(), indent=2))
