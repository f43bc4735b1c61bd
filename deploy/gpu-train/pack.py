"""Pack detection data sets into one small folder for a GPU machine that cannot render.

    python deploy/gpu-train/pack.py OUT NAME=SET [NAME=SET ...] [--scale 0.8] [--quality 80]

SET is a data set in the shared JSON format or ``synth:N:SEED`` (rendered here once, into
runs/synth, as `harvest train detector` does). Each is written to OUT/NAME/labels.json with its
images: JPEG files are copied as they are; other images (the sim's PNG renders) are resized by
``--scale`` and stored as JPEG of ``--quality``, their boxes scaled to match. Training sees a
640x480 image at most at 0.8 of its size (the letterbox's 0.5 times the largest augmentation
scale, 1.6), so 0.8 loses nothing but the resampling.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import cv2


def pack_set(src_json: Path, out: Path, scale: float, quality: int) -> int:
    """Write one data set into ``out``; returns the number of images."""
    from services.detector.data import load_dataset

    samples = load_dataset(src_json)  # checks every entry and names the bad ones
    (out / "images").mkdir(parents=True, exist_ok=True)
    entries = []
    for i, s in enumerate(samples):
        if s.path.suffix.lower() in (".jpg", ".jpeg"):
            name = f"images/{i:06d}_{s.path.name}"
            shutil.copyfile(s.path, out / name)
            w, h, k = s.width_px, s.height_px, 1.0
        else:
            bgr = cv2.cvtColor(s.load_rgb(), cv2.COLOR_RGB2BGR)  # checks it reads, and its size
            w, h, k = round(s.width_px * scale), round(s.height_px * scale), scale
            name = f"images/{i:06d}_{s.path.stem}.jpg"
            small = cv2.resize(bgr, (w, h), interpolation=cv2.INTER_AREA)
            cv2.imwrite(str(out / name), small, [cv2.IMWRITE_JPEG_QUALITY, quality])
        boxes = [[round(float(v) * k, 2) for v in b] for b in s.boxes_xyxy_px]
        entries.append({"image": name, "width": w, "height": h, "boxes": boxes})
    (out / "labels.json").write_text(json.dumps(entries) + "\n")
    return len(entries)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("out", type=Path)
    p.add_argument("sets", nargs="+", metavar="NAME=SET")
    p.add_argument("--scale", type=float, default=0.8)
    p.add_argument("--quality", type=int, default=80)
    p.add_argument("--synth-cache", type=Path, default=Path("runs/synth"))
    a = p.parse_args(argv)
    from services.detector.data import DatasetError
    from services.detector.train import DataSpec, resolve

    for arg in a.sets:
        name, sep, spec = arg.partition("=")
        if not sep or not name or "/" in name:
            p.error(f"{arg!r}: expected NAME=SET, NAME a plain folder name")
        # As training reads it: synth:N:SEED rendered once into the cache, else a JSON file.
        try:
            src = Path(resolve([DataSpec(spec)], None, a.synth_cache, print)[0].json_path)
            n_img = pack_set(src, a.out / name, a.scale, a.quality)
        except DatasetError as exc:
            print(f"pack.py: {name}: {exc}", file=sys.stderr)
            return 1
        print(f"{name}: {n_img} images from {src}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
