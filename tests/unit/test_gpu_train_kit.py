"""deploy/gpu-train: packing data sets for a machine that cannot render, and training there
without the stack's runtime (no zenoh, no pydantic-settings)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

from services.detector.data import load_dataset
from tests.unit.test_detector import write_dataset

KIT = Path(__file__).resolve().parents[2] / "deploy" / "gpu-train"


def test_pack_scales_renders_to_jpeg_and_copies_photos(tmp_path: Path) -> None:
    sys.path.insert(0, str(KIT))
    try:
        import pack
    finally:
        sys.path.remove(str(KIT))
    renders = write_dataset(tmp_path, 2, 10)  # PNG
    photo = tmp_path / "photo.jpg"
    cv2.imwrite(str(photo), np.full((50, 60, 3), 90, np.uint8))
    photos = tmp_path / "photos.json"
    photos.write_text(
        json.dumps([{"image": "photo.jpg", "width": 60, "height": 50, "boxes": [[10, 10, 20, 30]]}])
    )
    assert pack.main([str(tmp_path / "out"), f"r={renders}", f"p={photos}", "--scale", "0.5"]) == 0
    src, got = load_dataset(renders), load_dataset(tmp_path / "out" / "r" / "labels.json")
    assert [s.path.suffix for s in got] == [".jpg", ".jpg"]
    assert (got[0].width_px, got[0].height_px) == (80, 60)
    assert got[0].load_rgb().shape == (60, 80, 3)
    assert np.allclose(got[0].boxes_xyxy_px, src[0].boxes_xyxy_px * 0.5, atol=0.01)
    kept = load_dataset(tmp_path / "out" / "p" / "labels.json")[0]
    assert kept.path.read_bytes() == photo.read_bytes()
    assert kept.boxes_xyxy_px.tolist() == [[10, 10, 20, 30]]
    assert pack.main([str(tmp_path / "out"), "bad=synth:x"]) == 1  # named, no traceback


def test_training_runs_without_the_runtime_packages(tmp_path: Path) -> None:
    data = write_dataset(tmp_path, 2, 10)
    args = ["--data", str(data), "--val", str(data), "--out-dir", str(tmp_path / "run")]
    args += ["--weights", str(tmp_path / "w.pt"), "--epochs", "1", "--iters-per-epoch", "1"]
    args += ["--batch", "1", "--eval-every", "1"]
    # None in sys.modules makes `import zenoh` fail, as on a machine without it.
    code = (
        "import sys, runpy\n"
        "sys.modules.update(dict.fromkeys(['zenoh', 'pydantic_settings', 'mcap', 'rerun']))\n"
        f"sys.argv = ['train_bare.py', *{args!r}]\n"
        f"runpy.run_path({str(KIT / 'train_bare.py')!r}, run_name='__main__')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.splitlines()  # the weights' meta is printed last, indented
    start = len(lines) - 1 - lines[::-1].index("{")
    meta = json.loads("\n".join(lines[start:]))
    assert meta["command"].startswith("harvest train detector --data")
    assert (tmp_path / "w.pt").is_file()
