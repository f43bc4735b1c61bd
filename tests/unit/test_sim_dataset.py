"""`harvest dataset synth`: the oranges_real JSON format plus depth and visibility, the same
files for the same seed, and a folder that the file camera can play."""

from __future__ import annotations

import json
from pathlib import Path

from services.camera_file import SERVICE as FILE_CAM
from services.runtime.settings import load_settings
from services.sim.dataset import synth
from services.testkit import run_source


def test_synth_writes_the_real_datasets_format_deterministically(tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    done: list[int] = []
    labels = synth(a, 3, seed=5, progress=done.append)
    synth(b, 3, seed=5)
    assert done == [1, 2, 3]
    assert json.loads((a / "labels.json").read_text()) == labels
    for e in labels:
        assert {"image", "width", "height", "boxes"} <= set(e)
        assert len(e["boxes"]) == len(e["visible_fraction"])
        for (x1, y1, x2, y2), v in zip(e["boxes"], e["visible_fraction"], strict=True):
            assert -0.5 <= x1 < x2 <= 639.5 and -0.5 <= y1 < y2 <= 479.5 and 0 < v <= 1
        for key in ("image", "depth"):
            assert (a / e[key]).read_bytes() == (b / e[key]).read_bytes()
    assert sum(len(e["boxes"]) for e in labels) > 3
    other = synth(tmp_path / "c", 1, seed=6)
    assert other[0]["boxes"] != labels[0]["boxes"]
    s = load_settings(FILE_CAM.settings, {"path": str(a), "color_glob": "images/*.png"})
    assert len(run_source(FILE_CAM, s, lambda t, m: [])) == 3
