"""The camera in Rerun: pose and frustum, colour and depth images, the trunk mask, and the
detector's and tracker's boxes on the image."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from schemas.camera import RgbdFrame
from schemas.perception import Detections, Track, Tracks
from schemas.sim import GroundTruth
from services.vision.trunk_mask import trunk_mask
from services.viz import paths
from services.viz.out import Out

MASK_CLASS = 1


@dataclass
class RateLimit:
    """Passes at most ``rate_hz`` events per second of message time (0: pass all)."""

    rate_hz: float
    last_ns: int | None = None

    def __call__(self, stamp_ns: int) -> bool:
        if self.rate_hz <= 0:
            return True
        if self.last_ns is not None and stamp_ns - self.last_ns < 1e9 / self.rate_hz - 1e3:
            return False  # (1 µs of slack: 15 Hz stamps are rounded to the nanosecond)
        self.last_ns = stamp_ns
        return True


@dataclass
class CameraView:
    """Draws camera frames; image rates are limited by message time, so live = replay."""

    image_rate_hz: float
    depth_rate_hz: float
    jpeg_quality: int
    trunk_max_depth_m: float
    frames: int = 0
    images: int = 0
    _image_gate: RateLimit = field(init=False)
    _depth_gate: RateLimit = field(init=False)

    def __post_init__(self) -> None:
        self._image_gate = RateLimit(self.image_rate_hz)
        self._depth_gate = RateLimit(self.depth_rate_hz)

    def log_static(self, out: Out) -> None:
        rr = out.rr
        out.log(
            paths.TRUNK_MASK,
            rr.AnnotationContext(
                [
                    rr.AnnotationInfo(id=0, label="background", color=(0, 0, 0, 0)),
                    rr.AnnotationInfo(
                        id=MASK_CLASS, label="trunk (HSV ∩ depth)", color=paths.MASK_COLOUR
                    ),
                ]
            ),
            static=True,
        )
        out.log(
            paths.DETECTIONS,
            rr.AnnotationContext([rr.AnnotationInfo(id=0, label="orange", color=(255, 200, 0))]),
            static=True,
        )

    def log_frame(self, out: Out, frame: RgbdFrame) -> None:
        """Camera pose and intrinsics on every frame; images when the rate limits allow."""
        rr = out.rr
        meta = frame.meta
        intr = meta.intrinsics
        pose = meta.T_world_camera
        self.frames += 1
        out.log(
            paths.CAMERA,
            rr.Transform3D(
                translation=pose.position_m, quaternion=rr.Quaternion(xyzw=pose.orientation_xyzw)
            ),
        )
        out.log(
            paths.IMAGE,
            rr.Pinhole(
                image_from_camera=[
                    [intr.fx_px, 0, intr.cx_px],
                    [0, intr.fy_px, intr.cy_px],
                    [0, 0, 1],
                ],
                resolution=[intr.width_px, intr.height_px],
                camera_xyz=rr.ViewCoordinates.RDF,
                image_plane_distance=0.3,
            ),
        )
        stamp = meta.header.stamp_ns
        if self._image_gate(stamp):
            self.images += 1
            out.log(paths.RGB, self._colour(out, frame.rgb))
        if self.depth_rate_hz > 0 and self._depth_gate(stamp):
            out.log(paths.DEPTH, rr.DepthImage(frame.depth, meter=1.0 / meta.depth_unit_m))
            mask = trunk_mask(frame, self.trunk_max_depth_m).astype(np.uint8) * MASK_CLASS
            out.log(paths.TRUNK_MASK, rr.SegmentationImage(mask))

    def _colour(self, out: Out, rgb: np.ndarray) -> object:
        rr = out.rr
        if self.jpeg_quality <= 0:
            return rr.Image(rgb, color_model="RGB")
        import cv2

        ok, buf = cv2.imencode(
            ".jpg",
            cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR),
            [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality],
        )
        if not ok:
            return rr.Image(rgb, color_model="RGB")
        return rr.EncodedImage(contents=buf.tobytes(), media_type="image/jpeg")


def log_detections(out: Out, msg: Detections) -> None:
    """Boxes with class and score (colour by class)."""
    rr = out.rr
    dets = msg.detections
    out.log(
        paths.DETECTIONS,
        rr.Boxes2D(
            array=np.array([d.xyxy_px for d in dets], np.float32).reshape(-1, 4),
            array_format=rr.Box2DFormat.XYXY,
            class_ids=[d.class_id for d in dets],
            labels=[f"{d.class_name} {d.score:.2f}" for d in dets],
            show_labels=False,
        ),
    )


def log_tracks(out: Out, msg: Tracks) -> None:
    """Boxes labelled with the track ID and score, one stable colour per ID; tentative tracks
    carry a '?', coasting (unmatched) ones a '~'."""
    rr = out.rr
    tracks = msg.tracks

    def label(t: Track) -> str:
        mark = ("" if t.confirmed else "?") + ("" if t.matched else "~")
        return f"#{t.track_id}{mark} {t.score:.2f}"

    out.log(
        paths.TRACKS,
        rr.Boxes2D(
            array=np.array([t.xyxy_px for t in tracks], np.float32).reshape(-1, 4),
            array_format=rr.Box2DFormat.XYXY,
            colors=[paths.track_colour(t.track_id) for t in tracks],
            labels=[label(t) for t in tracks],
            radii=[1.5 if t.matched else 0.75 for t in tracks],
        ),
        rr.AnyValues(track_id=np.array([t.track_id for t in tracks], np.int64)),
    )


def log_truth_boxes(out: Out, msg: GroundTruth) -> None:
    """The ground-truth boxes of the visible fruit (evaluation only), grey."""
    rr = out.rr
    boxes = [f for f in msg.fruits if f.box_xyxy_px is not None]
    out.log(
        paths.TRUTH_BOXES,
        rr.Boxes2D(
            array=np.array([f.box_xyxy_px for f in boxes], np.float32).reshape(-1, 4),
            array_format=rr.Box2DFormat.XYXY,
            colors=[paths.TRUTH_COLOUR] * len(boxes),
            labels=[f"truth {f.fruit_id}" for f in boxes],
            show_labels=False,
            radii=0.5,
        ),
    )
