"""Derived camera channels in Foxglove protobuf, so that other tools' MCAP loaders show the camera.

Rerun's MCAP importer (``rerun run.mcap``) and Foxglove decode Foxglove schemas in protobuf but
not our JSON or raw RGB-D channels. For each ``camera/rgbd`` message the recorder can also write:

* ``/preview/camera/image``: ``foxglove.CompressedImage`` (JPEG, lossy) or ``foxglove.RawImage``
  (rgb8, lossless), at ``scale`` × the camera resolution;
* ``/preview/camera/calibration``: ``foxglove.CameraCalibration`` (intrinsics scaled alike);
* ``/preview/tf``: ``foxglove.FrameTransforms`` with the camera pose in ``world``.

These channels are *derived*: their topics start with '/', which no Zenoh key can, and their
metadata names the source topic (``derived_from``), so replay and resim skip them. The replay
source stays ``camera/rgbd``, raw and lossless.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from schemas.camera import decode_rgbd

PreviewFormat = Literal["jpeg", "raw", "none"]
DERIVED_FROM = "derived_from"
"""Channel metadata key that marks a derived channel and names the topic it derives from."""
SOURCE_TOPIC = "camera/rgbd"
IMAGE_TOPIC = "/preview/camera/image"
CALIBRATION_TOPIC = "/preview/camera/calibration"
TF_TOPIC = "/preview/tf"
WORLD_FRAME = "world"


@dataclass(frozen=True)
class DerivedMessage:
    """One message of a derived channel, ready for the MCAP writer."""

    topic: str
    schema_name: str
    data: bytes


def file_descriptor_set(message_class: Any) -> bytes:
    """The serialized FileDescriptorSet of a protobuf message class and its transitive imports
    (what an MCAP ``protobuf`` schema record carries)."""
    from google.protobuf.descriptor_pb2 import FileDescriptorSet

    fds = FileDescriptorSet()
    seen: set[str] = set()

    def add(fd: Any) -> None:
        if fd.name in seen:
            return
        seen.add(fd.name)
        for dep in fd.dependencies:
            add(dep)
        fd.CopyToProto(fds.file.add())

    add(message_class.DESCRIPTOR.file)
    return fds.SerializeToString()


class CameraPreview:
    """Turns one ``camera/rgbd`` payload into the derived Foxglove messages (pure, no I/O)."""

    def __init__(self, fmt: PreviewFormat = "jpeg", scale: float = 0.5, jpeg_quality: int = 80):
        if fmt == "none":
            raise ValueError("CameraPreview needs a format other than 'none'")
        if not 0.0 < scale <= 1.0:
            raise ValueError(f"preview scale must be in (0, 1], got {scale}")
        if not 1 <= jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be in [1, 100], got {jpeg_quality}")
        import cv2
        from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
        from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
        from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
        from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

        self._cv2 = cv2
        self.fmt, self.scale, self.jpeg_quality = fmt, scale, jpeg_quality
        self._image_cls: Any = CompressedImage if fmt == "jpeg" else RawImage
        self._calib_cls, self._tf_cls = CameraCalibration, FrameTransforms
        self.schemas: dict[str, bytes] = {
            cls.DESCRIPTOR.full_name: file_descriptor_set(cls)
            for cls in (self._image_cls, CameraCalibration, FrameTransforms)
        }

    @property
    def description(self) -> str:
        """What the image channel holds, for its metadata (lossy or not)."""
        if self.fmt == "jpeg":
            return f"JPEG quality {self.jpeg_quality} (lossy), scale {self.scale:g}"
        return f"rgb8 (lossless), scale {self.scale:g}"

    def derive(self, payload: bytes) -> list[DerivedMessage]:
        """The image, calibration and camera transform of one RGB-D payload."""
        frame = decode_rgbd(payload)
        meta = frame.meta
        intr = meta.intrinsics
        w = max(1, round(intr.width_px * self.scale))
        h = max(1, round(intr.height_px * self.scale))
        rgb = frame.rgb
        if (w, h) != (intr.width_px, intr.height_px):
            rgb = self._cv2.resize(rgb, (w, h), interpolation=self._cv2.INTER_AREA)
        stamp, frame_id = meta.header.stamp_ns, meta.header.frame_id
        sx, sy = w / intr.width_px, h / intr.height_px
        return [
            self._image(rgb, stamp, frame_id),
            self._calibration(stamp, frame_id, w, h, intr, sx, sy),
            self._transform(stamp, frame_id, meta.T_world_camera),
        ]

    def _image(self, rgb: Any, stamp_ns: int, frame_id: str) -> DerivedMessage:
        h, w = rgb.shape[:2]
        if self.fmt == "jpeg":
            bgr = self._cv2.cvtColor(rgb, self._cv2.COLOR_RGB2BGR)
            ok, buf = self._cv2.imencode(
                ".jpg", bgr, [self._cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality]
            )
            if not ok:
                raise ValueError("JPEG encoding of the preview failed")
            msg = self._image_cls(frame_id=frame_id, format="jpeg", data=buf.tobytes())
        else:
            msg = self._image_cls(
                frame_id=frame_id,
                width=w,
                height=h,
                encoding="rgb8",
                step=3 * w,
                data=rgb.tobytes(),
            )
        msg.timestamp.FromNanoseconds(stamp_ns)
        return DerivedMessage(IMAGE_TOPIC, self._image_cls.DESCRIPTOR.full_name, _ser(msg))

    def _calibration(
        self, stamp_ns: int, frame_id: str, w: int, h: int, intr: Any, sx: float, sy: float
    ) -> DerivedMessage:
        fx, fy = intr.fx_px * sx, intr.fy_px * sy
        # Pixel centres: (c + 0.5) scales, so c' = (c + 0.5) * s - 0.5.
        cx, cy = (intr.cx_px + 0.5) * sx - 0.5, (intr.cy_px + 0.5) * sy - 0.5
        msg = self._calib_cls(
            frame_id=frame_id,
            width=w,
            height=h,
            distortion_model="",
            K=[fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
            R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            P=[fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        )
        msg.timestamp.FromNanoseconds(stamp_ns)
        return DerivedMessage(CALIBRATION_TOPIC, self._calib_cls.DESCRIPTOR.full_name, _ser(msg))

    def _transform(self, stamp_ns: int, frame_id: str, pose: Any) -> DerivedMessage:
        msg = self._tf_cls()
        t = msg.transforms.add(parent_frame_id=WORLD_FRAME, child_frame_id=frame_id)
        t.timestamp.FromNanoseconds(stamp_ns)
        px, py, pz = pose.position_m
        t.translation.x, t.translation.y, t.translation.z = px, py, pz
        qx, qy, qz, qw = pose.orientation_xyzw
        t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w = qx, qy, qz, qw
        return DerivedMessage(TF_TOPIC, self._tf_cls.DESCRIPTOR.full_name, _ser(msg))


def _ser(msg: Any) -> bytes:
    data: bytes = msg.SerializeToString()
    return data
