"""`harvest eval detector` and `harvest eval tracker`: measured figures, a table, or --json."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
from collections.abc import Iterator
from pathlib import Path

from rich.progress import Progress
from rich.table import Table

from services.cli.ui import console


def add_parser(esub: argparse._SubParsersAction) -> None:
    d = esub.add_parser(
        "detector",
        help="AP50, AP50:95, precision, recall and ms per frame on a data set",
        description="Run the detector on every image of a data set in the shared JSON format "
        "(a list of {image, width, height, boxes}) and score it with pycocotools.",
    )
    d.add_argument("--data", type=Path, required=True, help="the data set JSON file")
    d.add_argument(
        "--images-root", type=Path, help="image paths are relative to this (default: the JSON's)"
    )
    _detector_args(d)
    d.add_argument("--json", action="store_true", help="print one JSON object")
    d.set_defaults(func=cmd_eval_detector)

    t = esub.add_parser(
        "tracker",
        help="correct-ID share (paper), HOTA, IDF1, MOTA, ID switches on occlusion scenarios",
        description="Run scenario sequences (occluder sweeps, moved fruit, swaying leaves) "
        "through the detector and tracker cores and score the tracks against the truth.",
    )
    t.add_argument(
        "--scenario",
        required=True,
        help="a sim scenario (deploy/scenarios/*.yaml, e.g. paper-exp1) or a scripted 2D one "
        "(scripted-sweep, scripted-moved, scripted-leaves, scripted-occlusion-suite)",
    )
    t.add_argument(
        "--duration-s",
        type=float,
        help="sim time per sequence (default: until the last event ends, plus 1 s)",
    )
    t.add_argument("--seeds", type=_seeds, default=[0, 1, 2, 3, 4], help="A-B or A,B,C (0-4)")
    t.add_argument("--fruit", type=int, default=8, help="fruit per scripted scene")
    _detector_args(t, truth=True)
    t.add_argument("--set", action="append", metavar="KEY=VALUE", help="tracker setting")
    t.add_argument("--json", action="store_true", help="print one JSON object")
    t.set_defaults(func=cmd_eval_tracker)


def _seeds(text: str) -> list[int]:
    from services.cli.evaluate import parse_seeds

    return parse_seeds(text)


def _detector_args(p: argparse.ArgumentParser, truth: bool = False) -> None:
    p.add_argument(
        "--backend",
        choices=["net", "hsv", "truth"] if truth else ["net", "hsv"],
        default="net",
        help="detector backend"
        + ("; truth: the true visible boxes, to score the tracker alone" if truth else ""),
    )
    p.add_argument("--weights", type=Path, help="OrangeNet weights (default: the committed ones)")
    p.add_argument(
        "--threshold", type=float, help="operating score threshold (default: the weights')"
    )
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads")


def _json(result: dict) -> str:
    """JSON with NaN (a metric with nothing to measure, e.g. no occluded frame) as null."""
    clean = {k: (None if isinstance(v, float) and v != v else v) for k, v in result.items()}
    return json.dumps(clean, indent=2)


@contextlib.contextmanager
def _stdout_to_stderr(active: bool) -> Iterator[None]:
    """Send file descriptor 1 to stderr while active: C libraries (pybullet prints its build
    time) must not spoil the one JSON object on stdout."""
    if not active:
        yield
        return
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def _fmt(v: float) -> str:
    return "n/a" if v != v else f"{v:.3f}"


def _detector_settings(args: argparse.Namespace, **extra: object):
    from services.detector import Settings
    from services.runtime.settings import load_settings

    layer: dict[str, object] = {"backend": args.backend, "torch_threads": args.threads, **extra}
    if args.weights:
        layer["weights_path"] = str(args.weights.resolve())
    if args.threshold is not None:
        layer["score_threshold"] = args.threshold
    return load_settings(Settings, layer, service="detector")


def cmd_eval_detector(args: argparse.Namespace) -> int:
    from services.detector.core import DetectorCore
    from services.detector.data import DatasetError, load_dataset
    from services.detector.evaluate import evaluate
    from services.runtime import ConfigError
    from services.runtime.settings import SettingsError

    try:
        samples = load_dataset(args.data, args.images_root)
        settings = _detector_settings(args)
        # AP needs the whole ranking: score every box above 0.01, then apply the operating
        # threshold for precision and recall.
        low = DetectorCore(_detector_settings(args, score_threshold=0.01, max_detections=100))
        threshold = DetectorCore(settings).threshold
    except (DatasetError, ConfigError, SettingsError) as exc:
        print(f"harvest eval detector: {exc}", file=sys.stderr)
        return 1
    with Progress(transient=True, disable=args.json) as bar:
        task = bar.add_task(f"eval {low.name}", total=len(samples))
        try:
            m = evaluate(samples, low.detect, threshold, lambda i: bar.update(task, completed=i))
        except DatasetError as exc:
            print(f"harvest eval detector: {exc}", file=sys.stderr)
            return 1
    result = {"data": str(args.data), "detector": low.name, **m.to_json()}
    if args.json:
        print(_json(result))
        return 0
    t = Table(title=f"{low.name} on {args.data} ({m.images} images, {m.boxes} boxes)")
    cols = ("AP50", "AP50:95", "AP30", "box w/h", "precision", "recall", "threshold")
    for col in (*cols, "ms/frame", "p90 ms"):
        t.add_column(col, justify="right")
    t.add_row(
        f"{m.ap50:.3f}",
        f"{m.ap50_95:.3f}",
        f"{m.ap30:.3f}",
        f"{m.box_width_ratio:.2f}/{m.box_height_ratio:.2f}",
        f"{m.precision:.3f}",
        f"{m.recall:.3f}",
        f"{m.score_threshold:.2f}",
        f"{m.ms_per_frame:.1f}",
        f"{m.ms_per_frame_p90:.1f}",
    )
    console().print(t)
    return 0


def cmd_eval_tracker(args: argparse.Namespace) -> int:
    from services.detector.core import DetectorCore
    from services.runtime import ConfigError
    from services.runtime.settings import SettingsError, load_settings, parse_overrides
    from services.tracker import Settings as TrackerSettings
    from services.tracker.core import TrackerCore
    from services.tracker.run_eval import RunStats, TruthDetector, run_sequence, summarize
    from services.tracker.scenarios import make_sequence

    try:
        seeds = args.seeds
        seqs = [make_sequence(args.scenario, s, args.fruit, args.duration_s) for s in seeds]
        truth = args.backend == "truth"
        dsettings = None if truth else _detector_settings(args, expected_size_px=None)
        tsettings = load_settings(TrackerSettings, overrides=parse_overrides(args.set))
        if dsettings is not None:
            DetectorCore(dsettings)  # refuse bad weights before the long run
    except (KeyError, ValueError, ConfigError, SettingsError) as exc:
        msg = exc.args[0] if isinstance(exc, KeyError) else exc
        print(f"harvest eval tracker: {msg}", file=sys.stderr)
        return 1
    stats = RunStats()
    records = []
    with _stdout_to_stderr(args.json), Progress(transient=True, disable=args.json) as bar:
        task = bar.add_task(f"eval tracker on {args.scenario}", total=None)
        for seq in seqs:
            records.append(
                run_sequence(
                    seq,
                    TruthDetector() if dsettings is None else DetectorCore(dsettings),
                    TrackerCore(tsettings),  # type: ignore[arg-type]
                    stats,
                    lambda: bar.advance(task),
                )
            )
    result = {"scenario": args.scenario, "seeds": seeds, **summarize(records, stats)}
    if args.json:
        print(_json(result))
        return 0
    seed_list = ",".join(map(str, seeds))
    t = Table(title=f"tracker on {args.scenario}, seeds {seed_list} ({stats.frames} frames)")
    cols = {
        "ID ok (occl.)": f"{_fmt(result['id_correct_occluded'])} ({result['frames_occluded']})",
        "ID ok (clear)": f"{_fmt(result['id_correct_clear'])} ({result['frames_clear']})",
        "HOTA": f"{result['hota']:.3f}",
        "IDF1": f"{result['idf1']:.3f}",
        "MOTA": f"{result['mota']:.3f}",
        "IDSW": str(result["id_switches"]),
        "tracker ms": f"{result['tracker_ms_per_frame']:.2f}",
        "detector ms": f"{result['detector_ms_per_frame']:.1f}",
    }
    for c in cols:
        t.add_column(c, justify="right")
    t.add_row(*cols.values())
    console().print(t)
    return 0
