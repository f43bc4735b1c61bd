"""Tracker core: joins frames to detections, refuses unusable input with counts, never stalls."""

from __future__ import annotations

import numpy as np

from schemas.base import Header
from schemas.camera import RgbdFrame
from schemas.perception import Detection, Detections, Tracks
from services.runtime.settings import load_settings
from services.testkit.scene2d import Scene2D
from services.tracker import SERVICE, Settings
from services.tracker.core import TrackerCore


def dets_for(frame: RgbdFrame, boxes, seq: int | None = None, problem: str = "") -> Detections:
    h = frame.header
    return Detections(
        header=Header(
            stamp_ns=h.stamp_ns,
            seq=h.seq if seq is None else seq,
            frame_id=h.frame_id,
            source="detector",
            answers_seq=h.seq,
        ),
        image_width_px=frame.rgb.shape[1],
        image_height_px=frame.rgb.shape[0],
        detector="test",
        detections=tuple(Detection(xyxy_px=tuple(b), score=0.9) for b in boxes),
        input_problem=problem,
    )


def core(**kw: object) -> TrackerCore:
    s = load_settings(Settings, {"n_init": 2, **kw}, service="tracker")
    return SERVICE.make_core(s)  # type: ignore[misc]


def run(c: TrackerCore, frame: RgbdFrame, d: Detections, send_frame: bool = True) -> Tracks:
    if send_frame:
        assert c.handle("camera/rgbd", frame) == []
    ((topic, out),) = c.handle("perception/detections", d)
    assert topic == "perception/tracks"
    return out


def truth_boxes(scene: Scene2D, k: int):
    return [v.box_xyxy_px for v in scene.frame(k).fruits if v.box_xyxy_px is not None]


def test_tracks_carry_depth_and_a_3d_position_from_the_frame() -> None:
    scene, c = Scene2D(seed=2, n_fruit=4, sweep=None), core()
    for k in range(3):
        f = scene.frame(k).frame
        out = run(c, f, dets_for(f, truth_boxes(scene, k)))
    assert [t.track_id for t in out.tracks] == [1, 2, 3, 4]
    assert all(t.confirmed and t.matched for t in out.tracks)
    depths = sorted(z for _, _, _, z in scene.fruit)  # rendered in whole millimetres
    got = sorted(t.depth_m for t in out.tracks if t.depth_m is not None)
    np.testing.assert_allclose(got, depths, atol=1e-3)
    for t in out.tracks:
        assert t.position_cam_m is not None and t.position_cam_m[2] == t.depth_m
    assert out.frame_seq == 2 and c.counters == {}


def test_boxes_outside_the_image_or_of_absurd_size_are_rejected_and_counted() -> None:
    scene, c = Scene2D(seed=1, n_fruit=2, sweep=None), core()
    f = scene.frame(0).frame
    good = truth_boxes(scene, 0)
    bad = [(600.0, 10.0, 700.0, 60.0), (5.0, 5.0, 6.0, 6.0), (0.0, 0.0, 640.0, 480.0)]
    out = run(c, f, dets_for(f, good + bad))
    assert out.rejected_detections == 3 and len(out.tracks) == 2
    assert c.counters == {"box_outside_image": 1, "box_too_small": 1, "box_too_large": 1}


def test_without_its_frame_the_tracker_runs_on_boxes_and_counts_it() -> None:
    scene, c = Scene2D(seed=1, n_fruit=2, sweep=None), core()
    f = scene.frame(0).frame
    out = run(c, f, dets_for(f, truth_boxes(scene, 0)), send_frame=False)
    assert len(out.tracks) == 2 and all(t.depth_m is None for t in out.tracks)
    assert c.counters["frame_missing"] == 1


def test_all_zero_depth_is_counted_and_not_used() -> None:
    scene, c = Scene2D(seed=1, n_fruit=2, sweep=None), core()
    f = scene.frame(0).frame
    blind = RgbdFrame(f.meta, f.rgb, np.zeros_like(f.depth))
    out = run(c, blind, dets_for(blind, truth_boxes(scene, 0)))
    assert len(out.tracks) == 2 and all(t.depth_m is None for t in out.tracks)
    assert c.counters["depth_all_zero"] == 1


def test_an_unusable_detector_input_leaves_the_tracks_unchanged_and_is_flagged() -> None:
    scene, c = Scene2D(seed=1, n_fruit=2, sweep=None), core()
    for k in range(3):
        f = scene.frame(k).frame
        before = run(c, f, dets_for(f, truth_boxes(scene, k)))
    f = scene.frame(3).frame
    out = run(c, f, dets_for(f, [], problem="blank: dead sensor"))
    assert out.tracks == before.tracks and out.input_problem == "detector: blank: dead sensor"
    assert c.counters["detector_input_problem"] == 1
    # The tentative-track rule did not fire: the same tracks go on with the next good frame.
    f = scene.frame(4).frame
    assert [t.track_id for t in run(c, f, dets_for(f, truth_boxes(scene, 4))).tracks] == [1, 2]


def test_a_frame_of_another_size_is_not_used_for_appearance() -> None:
    scene, c = Scene2D(seed=1, n_fruit=2, sweep=None), core()
    f = scene.frame(0).frame
    small = Scene2D(seed=1, n_fruit=2, sweep=None, width_px=320, height_px=240).frame(0).frame
    c.handle("camera/rgbd", small)
    out = run(c, f, dets_for(f, truth_boxes(scene, 0)), send_frame=False)
    assert len(out.tracks) == 2 and c.counters["frame_size_mismatch"] == 1


def test_detections_with_nan_or_inverted_boxes_never_reach_the_core() -> None:
    """The bus decodes with the schema: such payloads are rejected (and counted) there."""
    import pytest

    from schemas.codec import DecodeError
    from schemas.topics import TOPICS

    scene = Scene2D(seed=1, n_fruit=1, sweep=None)
    good = dets_for(scene.frame(0).frame, truth_boxes(scene, 0))
    codec = TOPICS["perception/detections"].codec
    payload = codec.encode(good).decode()
    box = ",".join(str(v) for v in good.detections[0].xyxy_px)
    assert box in payload
    for bad in ("NaN,1.0,2.0,3.0", "50.0,50.0,10.0,10.0"):
        with pytest.raises(DecodeError):
            codec.decode(payload.replace(box, bad).encode())


def test_descriptors_and_depths_of_many_boxes_equal_those_of_each_box_alone() -> None:
    from services.tracker.appearance import describe, describe_many, to_hsv
    from services.tracker.core import _median

    rng = np.random.default_rng(5)
    rgb = rng.integers(0, 256, (120, 160, 3), dtype=np.uint8)
    # HSV per pixel: converting samples gives what sampling the converted frame gives.
    ys, xs = rng.integers(0, 120, 500), rng.integers(0, 160, 500)
    assert np.array_equal(to_hsv(rgb)[ys, xs], to_hsv(rgb[ys, xs]))
    boxes = np.array([[10, 10, 60, 70], [150, 100, 200, 160], [40.5, 40.2, 41, 41], [-5, 0, 30, 9]])
    many = describe_many(rgb, boxes)
    for box, feat in zip(boxes, many, strict=True):
        alone = describe(rgb, box)
        assert (feat is None) == (alone is None)
        assert feat is None or np.array_equal(feat, alone)
    assert many[2] is None and many[0] is not None
    np.testing.assert_allclose(np.linalg.norm(many[0]), 1.0)  # Hellinger: unit length
    for n in (1, 2, 7, 8, 101):
        v = rng.integers(0, 5000, n).astype(np.uint16)
        assert _median(v) == float(np.median(v))
