"""Contract tests of the detector and the tracker with the foundation's kit."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from schemas.base import Header
from schemas.camera import RgbdFrame, RgbdFrameMeta
from services.detector import SERVICE as DETECTOR
from services.runtime import ConfigError
from services.runtime.settings import load_settings
from services.testkit import ContractCase, Emitted, FakeNode, assert_contract
from services.testkit.scene2d import Scene2D
from services.tracker import SERVICE as TRACKER


def frames(n: int, seed: int = 0, **kw: Any) -> list[tuple[str, RgbdFrame]]:
    scene = Scene2D(seed=seed, n_fruit=6, sweep=(2, 6), **kw)
    return [("camera/rgbd", scene.frame(k).frame) for k in range(n)]


def blank(k: int, w: int = 640, h: int = 480) -> tuple[str, RgbdFrame]:
    _, f = frames(1)[0]
    meta = RgbdFrameMeta(
        header=Header(stamp_ns=k, seq=k, frame_id="camera", source="sim"),
        intrinsics=f.meta.intrinsics.model_copy(update={"width_px": w, "height_px": h}),
        T_world_camera=f.meta.T_world_camera,
    )
    return (
        "camera/rgbd",
        RgbdFrame(meta, np.zeros((h, w, 3), np.uint8), np.zeros((h, w), np.uint16)),
    )


def no_detections(outs: list[Emitted]) -> None:
    assert len(outs) == 2
    for o in outs:
        assert o.msg.detections == () and o.msg.input_problem


@pytest.mark.parametrize("backend", ["net", "hsv"])
def test_detector_contract(backend: str) -> None:
    settings = load_settings(DETECTOR.settings, {"backend": backend})
    outs = assert_contract(
        ContractCase(
            DETECTOR,
            settings,
            inputs=frames(8),
            empty_inputs=[blank(0), blank(1, 320, 240)],
            empty_check=no_detections,
        )
    )
    assert len(outs) == 8
    assert sum(len(o.msg.detections) for o in outs) >= 8 * 3  # finds most of the 6 fruit
    assert all(o.msg.detector.startswith(backend) for o in outs)


def test_detector_counts_wrong_size_blank_and_depthless_frames() -> None:
    node = FakeNode(DETECTOR, load_settings(DETECTOR.settings, {"backend": "hsv"}))
    _, f = frames(1)[0]
    depthless = ("camera/rgbd", RgbdFrame(f.meta, f.rgb, np.zeros_like(f.depth)))
    small = frames(1, width_px=320, height_px=240)[0][1]
    small = RgbdFrame(
        small.meta.model_copy(
            update={"header": small.meta.header.model_copy(update={"seq": 2, "stamp_ns": 2})}
        ),
        small.rgb,
        small.depth,
    )
    outs = node.feed([depthless, blank(1), ("camera/rgbd", small)])
    problems = [o.msg.input_problem.split(":")[0] for o in outs]
    assert problems == ["", "blank", "wrong_size"]
    assert outs[0].msg.detections  # no depth does not stop a colour detector
    assert dict(node.core.counters) == {"depth_all_zero": 1, "blank": 1, "wrong_size": 1}


def test_detector_refuses_to_start_with_bad_weights(tmp_path) -> None:
    missing = tmp_path / "missing.pt"
    with pytest.raises(ConfigError, match=str(missing)):
        FakeNode(DETECTOR, load_settings(DETECTOR.settings, {"weights_path": str(missing)}))


def tracker_script(n: int) -> list[tuple[str, Any]]:
    """Frames and the detector's answers, interleaved as on the bus."""
    det = FakeNode(DETECTOR, load_settings(DETECTOR.settings, {"backend": "hsv"}))
    script: list[tuple[str, Any]] = []
    for item in frames(n, seed=4):
        script.append(item)
        script += [(o.topic, o.msg) for o in det.feed([item])]
    return script


def test_tracker_contract() -> None:
    settings = load_settings(TRACKER.settings, {"n_init": 3})
    script = tracker_script(12)

    def empty_check(outs: list[Emitted]) -> None:
        assert [o.msg.tracks for o in outs] == [(), ()]

    dets_only = [item for item in script if item[0] == "perception/detections"]
    empty = [(t, m.model_copy(update={"detections": ()})) for t, m in dets_only[:2]]
    outs = assert_contract(
        ContractCase(TRACKER, settings, inputs=script, empty_inputs=empty, empty_check=empty_check)
    )
    assert len(outs) == 12
    last = outs[-1].msg
    assert last.frame_seq == 11 and len(last.tracks) >= 4
    assert all(t.confirmed for t in last.tracks)
    assert [t.track_id for t in last.tracks] == sorted(t.track_id for t in last.tracks)


def test_tracker_drops_duplicated_and_out_of_order_detections() -> None:
    script = tracker_script(4)
    node = FakeNode(TRACKER, load_settings(TRACKER.settings, {"n_init": 2}))
    d = [i for i, (t, _) in enumerate(script) if t == "perception/detections"]
    replayed = [*script[: d[2] + 1], script[d[1]], script[d[2]], *script[d[2] + 1 :]]
    outs = node.feed(replayed)
    assert len(outs) == 4 and len(node.dropped) == 2
    clean = FakeNode(TRACKER, load_settings(TRACKER.settings, {"n_init": 2})).feed(script)
    assert [o.msg for o in outs] == [o.msg for o in clean]  # state not corrupted
