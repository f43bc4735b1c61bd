"""The recorder's derived camera preview: Foxglove protobuf that other tools decode, marked as
derived so that replay never republishes it, and the raw camera channel left untouched."""

from __future__ import annotations

import io
import subprocess
from collections import Counter
from pathlib import Path

import cv2
import numpy as np
import pytest
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from mcap.reader import make_reader

from schemas import TOPICS
from services.recorder.inspect import iter_messages, read_info
from services.recorder.preview import (
    CALIBRATION_TOPIC,
    DERIVED_FROM,
    IMAGE_TOPIC,
    TF_TOPIC,
    CameraPreview,
)
from services.recorder.writer import RunWriter
from services.viz.sink import rerun_executable
from tests.fixtures.viz_recording import PATH as FIXTURE
from tests.fixtures.viz_recording import T_WORLD_CAMERA, camera_messages


def frame_payload(k: int = 0) -> bytes:
    topic, frame = camera_messages(k)[0]
    return TOPICS[topic].codec.encode(frame)


def test_raw_preview_at_full_scale_is_the_camera_image() -> None:
    payload = frame_payload()
    frame = TOPICS["camera/rgbd"].codec.decode(payload)
    image, calib, tf = CameraPreview("raw", 1.0).derive(payload)
    assert (image.topic, calib.topic, tf.topic) == (IMAGE_TOPIC, CALIBRATION_TOPIC, TF_TOPIC)
    raw = RawImage.FromString(image.data)
    assert (raw.width, raw.height, raw.encoding, raw.frame_id) == (
        160,
        120,
        "rgb8",
        "camera_optical",
    )
    assert raw.data == frame.rgb.tobytes()
    assert raw.timestamp.ToNanoseconds() == frame.meta.header.stamp_ns


def test_jpeg_preview_scales_the_image_and_the_intrinsics() -> None:
    payload = frame_payload()
    frame = TOPICS["camera/rgbd"].codec.decode(payload)
    image, calib, tf = CameraPreview("jpeg", 0.5, 90).derive(payload)
    jpeg = CompressedImage.FromString(image.data)
    decoded = cv2.imdecode(np.frombuffer(jpeg.data, np.uint8), cv2.IMREAD_COLOR)[..., ::-1]
    assert jpeg.format == "jpeg" and decoded.shape == (60, 80, 3)
    small = cv2.resize(frame.rgb, (80, 60), interpolation=cv2.INTER_AREA)
    assert np.abs(decoded.astype(int) - small.astype(int)).mean() < 4  # lossy, but close
    k = list(CameraCalibration.FromString(calib.data).K)
    intr = frame.meta.intrinsics
    assert k[0] == pytest.approx(intr.fx_px / 2) and k[4] == pytest.approx(intr.fy_px / 2)
    assert k[2] == pytest.approx((intr.cx_px + 0.5) / 2 - 0.5)
    (t,) = FrameTransforms.FromString(tf.data).transforms
    assert (t.parent_frame_id, t.child_frame_id) == ("world", "camera_optical")
    assert (t.translation.x, t.translation.y, t.translation.z) == pytest.approx(
        T_WORLD_CAMERA.position_m
    )
    q = (t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w)
    assert q == pytest.approx(T_WORLD_CAMERA.orientation_xyzw)


def test_bad_preview_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="scale"):
        CameraPreview("jpeg", 0.0)
    with pytest.raises(ValueError, match="jpeg_quality"):
        CameraPreview("jpeg", 0.5, 0)


def test_writer_marks_derived_channels_and_keeps_the_raw_frame() -> None:
    buf = io.BytesIO()
    w = RunWriter(buf, preview=CameraPreview("jpeg", 0.5))
    payload = frame_payload()
    assert w.write("camera/rgbd", payload, "application/x-harvest-rgbd", 7) == "ok"
    w.finish()
    buf.seek(0)
    reader = make_reader(buf)
    seen = {c.topic: (s, c, m) for s, c, m in reader.iter_messages()}
    assert seen["camera/rgbd"][2].data == payload
    for topic in (IMAGE_TOPIC, CALIBRATION_TOPIC, TF_TOPIC):
        schema, channel, msg = seen[topic]
        assert channel.metadata[DERIVED_FROM] == "camera/rgbd"
        assert channel.message_encoding == "protobuf" and schema.encoding == "protobuf"
        assert msg.publish_time == seen["camera/rgbd"][2].publish_time
    assert "lossy" in seen[IMAGE_TOPIC][1].metadata["content"]
    assert w.derived[IMAGE_TOPIC].messages == 1 and "/preview/tf" not in w.stats


def test_an_undecodable_frame_gets_no_preview_but_is_recorded() -> None:
    """A frame whose header decodes but whose pixels are short: recorded, counted, no preview."""
    w = RunWriter(io.BytesIO(), preview=CameraPreview("jpeg", 0.5))
    assert w.write("camera/rgbd", frame_payload()[:-10], "application/x-harvest-rgbd", 7) == "ok"
    assert w.preview_errors == 1 and not w.derived


def test_inspect_flags_derived_channels() -> None:
    derived = Counter(m.topic for m in iter_messages(FIXTURE) if m.derived)
    assert derived == {IMAGE_TOPIC: 15, CALIBRATION_TOPIC: 15, TF_TOPIC: 15}
    info = read_info(FIXTURE)
    assert {c.topic for c in info.channels if c.derived} == set(derived)


def test_rerun_own_mcap_importer_shows_the_camera(tmp_path: Path) -> None:
    """`rerun run.mcap` needs no code of ours: its importer turns the preview into an image, a
    pinhole and a transform (checked through the CLI converter, the same importer)."""
    from rerun.chunk import RrdReader

    out = tmp_path / "imported.rrd"
    r = subprocess.run(
        [rerun_executable(), "mcap", "convert", str(FIXTURE), "-o", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    columns: dict[str, set[str]] = {}
    rows: Counter[str] = Counter()
    for chunk in RrdReader(out).stream():
        names = {f.name for f in chunk.to_record_batch().schema}
        columns.setdefault(chunk.entity_path, set()).update(names)
        if "EncodedImage:blob" in names:
            rows[chunk.entity_path] += chunk.num_rows
    assert rows[IMAGE_TOPIC] == 15
    assert "Pinhole:image_from_camera" in columns[CALIBRATION_TOPIC]
    assert "Transform3D:translation" in columns[TF_TOPIC]
