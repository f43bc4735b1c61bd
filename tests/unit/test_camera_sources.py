"""The other camera sources: a PNG folder (and its bad inputs), the RealSense without its
package or device."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from services.camera_file import SERVICE as FILE_CAM
from services.runtime import ConfigError
from services.runtime.settings import load_settings
from services.testkit import check_declared_topics, check_schema_valid, run_source

INTR = {"width_px": 64, "height_px": 48, "fx_px": 60.0, "fy_px": 60.0, "cx_px": 32, "cy_px": 24}


def folder(tmp: Path, n: int = 3, bad: int | None = None) -> Path:
    (tmp / "color").mkdir()
    (tmp / "depth").mkdir()
    (tmp / "intrinsics.json").write_text(json.dumps(INTR))
    rng = np.random.default_rng(0)
    for i in range(n):
        rgb = rng.integers(0, 255, (48, 64 if i != bad else 50, 3), dtype=np.uint8)
        depth = rng.integers(0, 3000, (48, 64), dtype=np.uint16)
        cv2.imwrite(str(tmp / "color" / f"{i:06d}.png"), rgb[:, :, ::-1])
        cv2.imwrite(str(tmp / "depth" / f"{i:06d}.png"), depth)
    return tmp


def play(path: Path, **kw: object) -> list:
    s = load_settings(FILE_CAM.settings, {"path": str(path), **kw})
    return run_source(FILE_CAM, s, lambda t, m: [])


def test_a_png_folder_plays_as_camera_frames(tmp_path: Path) -> None:
    outs = play(folder(tmp_path), rate_hz=10.0)
    check_declared_topics(FILE_CAM, outs)
    check_schema_valid(outs)
    assert [o.msg.header.stamp_ns for o in outs] == [0, 100_000_000, 200_000_000]
    f = outs[1].msg
    rgb = cv2.imread(str(tmp_path / "color" / "000001.png"))[:, :, ::-1]
    depth = cv2.imread(str(tmp_path / "depth" / "000001.png"), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(f.rgb, rgb) and np.array_equal(f.depth, depth)
    assert f.meta.intrinsics.fx_px == 60.0 and f.header.frame_id == "camera_optical"
    assert len(play(tmp_path, repeat=2)) == 6


def test_a_bad_frame_is_skipped_and_counted(tmp_path: Path) -> None:
    s = load_settings(FILE_CAM.settings, {"path": str(folder(tmp_path, 3, bad=1))})
    assert FILE_CAM.make_core is not None
    core = FILE_CAM.make_core(s)
    n = 0
    while not core.done():
        core.emit()
        core.advance()
        n += 1
    assert n == 2 and core.skipped == 1


@pytest.mark.parametrize(
    ("setup", "message"),
    [
        (lambda p: p / "nowhere", "no such file or folder"),
        (lambda p: (folder(p), (p / "intrinsics.json").unlink())[0], "intrinsics file not found"),
        (lambda p: (folder(p), (p / "depth" / "000002.png").unlink())[0], "3 colour images"),
        (
            lambda p: (folder(p), (p / "intrinsics.json").write_text('{"fx_px": 1}'))[0],
            "invalid intrinsics",
        ),
    ],
)
def test_unusable_inputs_refuse_to_start_with_the_problem_named(
    tmp_path: Path, setup, message: str
) -> None:
    with pytest.raises(ConfigError, match=message):
        play(setup(tmp_path))


def test_realsense_without_package_or_device_exits_with_a_clear_message() -> None:
    r = subprocess.run(
        [sys.executable, "-m", "services.realsense", "--no-multicast-scouting"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2
    if importlib.util.find_spec("pyrealsense2") is None:
        assert "pyrealsense2 package is missing" in r.stderr and "[realsense]" in r.stderr
    else:
        assert "no RealSense device" in r.stderr
