"""`harvest bench detector` and `harvest bench tracker`: per-frame times on this machine."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def add_parsers(bsub: argparse._SubParsersAction) -> None:
    b = bsub.add_parser(
        "detector",
        help="detector ms per 640x480 frame (torch threads fixed)",
        description="Time the detector core on scripted 640x480 RGB-D frames: median and p90 "
        "ms per frame, after a warm-up.",
    )
    b.add_argument("--backend", choices=["net", "hsv"], default="net")
    b.add_argument("--weights", type=Path, help="OrangeNet weights (default: the committed ones)")
    b.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    b.add_argument("--frames", type=int, default=200)
    b.add_argument("--json", action="store_true")
    b.set_defaults(func=cmd_bench_detector)
    b = bsub.add_parser(
        "tracker",
        help="tracker ms per frame with N tracks",
        description="Time the tracker core (descriptors, depth, Kalman, matching) on a "
        "scripted scene with N fruit, fed their true boxes as detections.",
    )
    b.add_argument("--tracks", type=int, default=30)
    b.add_argument("--frames", type=int, default=300)
    b.add_argument("--json", action="store_true")
    b.set_defaults(func=cmd_bench_tracker)


def _stats(ms: list[float]) -> dict[str, float]:
    return {
        "ms_median": float(np.median(ms)),
        "ms_p90": float(np.percentile(ms, 90)),
        "ms_mean": float(np.mean(ms)),
    }


def cmd_bench_detector(args: argparse.Namespace) -> int:
    from services.detector import Settings
    from services.detector.core import DetectorCore
    from services.runtime.settings import load_settings
    from services.testkit.scene2d import Scene2D

    layer: dict[str, object] = {"backend": args.backend, "torch_threads": args.threads}
    if args.weights:
        layer["weights_path"] = str(args.weights.resolve())
    settings = load_settings(Settings, layer)
    core = DetectorCore(settings)  # type: ignore[arg-type]
    scene = Scene2D(seed=0, n_fruit=12, sweep=(0, 60), sway=True)
    frames = [scene.frame(k).frame for k in range(20)]
    for f in frames[:5]:
        core.handle("camera/rgbd", f)
    ms = []
    for k in range(args.frames):
        t0 = time.perf_counter()
        core.handle("camera/rgbd", frames[k % len(frames)])
        ms.append((time.perf_counter() - t0) * 1e3)
    out = {
        "detector": core.name,
        "threads": args.threads,
        # The vector instructions torch's CPU kernels use (AVX2, AVX512...): the same network
        # ran at 15-19 ms on an AVX512 CPU and 25-28 ms on an AVX2 one (BENCHMARKS.md).
        "cpu": torch_cpu_capability(),
        "frames": args.frames,
        **_stats(ms),
    }
    print(json.dumps(out, indent=2) if args.json else _line(f"detector {core.name}", out))
    return 0


def cmd_bench_tracker(args: argparse.Namespace) -> int:
    from schemas.base import Header
    from schemas.perception import Detection, Detections
    from services.runtime.settings import load_settings
    from services.testkit.scene2d import Scene2D
    from services.tracker import Settings
    from services.tracker.core import TrackerCore

    scene = Scene2D(seed=0, n_fruit=args.tracks, sweep=None, sway=False, move=(0, args.frames))
    core = TrackerCore(load_settings(Settings, {}))  # type: ignore[arg-type]
    ms, n_tracks = [], []
    for k in range(args.frames):
        sf = scene.frame(k)
        h = sf.frame.header
        dets = Detections(
            header=Header(
                stamp_ns=h.stamp_ns, seq=k, frame_id=h.frame_id, source="bench", answers_seq=h.seq
            ),
            image_width_px=scene.w,
            image_height_px=scene.h,
            detector="truth",
            detections=tuple(
                Detection(xyxy_px=v.box_xyxy_px, score=1.0) for v in sf.fruits if v.box_xyxy_px
            ),
        )
        core.handle("camera/rgbd", sf.frame)
        t0 = time.perf_counter()
        ((_, tracks),) = core.handle("perception/detections", dets)
        ms.append((time.perf_counter() - t0) * 1e3)
        n_tracks.append(len(tracks.tracks))
    out = {
        "fruit": args.tracks,
        "frames": args.frames,
        "tracks_median": float(np.median(n_tracks)),
        **_stats(ms[10:]),
    }
    print(json.dumps(out, indent=2) if args.json else _line("tracker", out))
    return 0


def torch_cpu_capability() -> str:
    import torch

    return str(torch.backends.cpu.get_cpu_capability())


def _line(what: str, out: dict) -> str:
    return f"{what}: " + ", ".join(
        f"{k} {v:.2f}" if isinstance(v, float) else f"{k} {v}" for k, v in out.items()
    )
