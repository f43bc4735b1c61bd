"""Schemas: strict, frozen, documented, units in names; the topic map is consistent."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import BaseModel, ValidationError

from schemas import (
    TOPICS,
    CameraIntrinsics,
    Detection,
    Detections,
    Header,
    JointState,
    Pose,
    RgbdFrame,
    RgbdFrameMeta,
)
from schemas.export import all_schemas
from schemas.topics import STATUS_MODEL, UnknownTopicError, topic


def header(**kw: object) -> Header:
    base: dict[str, object] = {"stamp_ns": 10, "seq": 0, "frame_id": "world", "source": "t"}
    base.update(kw)
    return Header.model_validate(base)


def _models() -> list[type[BaseModel]]:
    out: list[type[BaseModel]] = [STATUS_MODEL, RgbdFrameMeta]
    for t in TOPICS.values():
        model = getattr(t.codec, "model", None)
        if model is not None:
            out.append(model)
    return out


def _all_model_classes() -> set[type[BaseModel]]:
    """Every model reachable from the message models (nested ones included)."""
    seen: set[type[BaseModel]] = set()
    stack = _models()
    while stack:
        m = stack.pop()
        if m in seen:
            continue
        seen.add(m)
        for f in m.model_fields.values():
            for arg in _flatten(f.annotation):
                if isinstance(arg, type) and issubclass(arg, BaseModel):
                    stack.append(arg)
    return seen


def _flatten(tp: object) -> list[object]:
    args = getattr(tp, "__args__", None)
    if not args:
        return [tp]
    return [x for a in args for x in _flatten(a)]


@pytest.mark.parametrize(
    "model", sorted(_all_model_classes(), key=lambda m: m.__name__), ids=lambda m: m.__name__
)
def test_every_model_is_documented_frozen_and_strict(model: type[BaseModel]) -> None:
    doc = (model.__doc__ or "").strip()
    assert doc and "\n" not in doc, f"{model.__name__} needs a one-line docstring"
    assert model.model_config.get("frozen") is True
    assert model.model_config.get("extra") == "forbid"
    for name, f in model.model_fields.items():
        assert f.description, f"{model.__name__}.{name} has no description"


def test_every_message_starts_with_the_header() -> None:
    for t in TOPICS.values():
        model = getattr(t.codec, "model", RgbdFrameMeta)
        assert next(iter(model.model_fields)) == "header", t.key


def test_unknown_fields_and_nan_are_rejected() -> None:
    with pytest.raises(ValidationError, match="extra"):
        Header.model_validate({"stamp_ns": 1, "seq": 0, "source": "x", "bogus": 1})
    with pytest.raises(ValidationError):
        Pose(position_m=(math.nan, 0.0, 0.0))
    with pytest.raises(ValidationError):
        Pose(position_m=(math.inf, 0.0, 0.0))


def test_models_are_frozen() -> None:
    h = header()
    with pytest.raises(ValidationError):
        h.seq = 3  # type: ignore[misc]


def test_inverted_box_is_rejected_with_the_field_named() -> None:
    with pytest.raises(ValidationError, match="inverted box"):
        Detection(xyxy_px=(10, 10, 5, 20), score=0.5)


def test_joint_state_lengths_must_agree() -> None:
    with pytest.raises(ValidationError, match="names but"):
        JointState.model_validate(
            {
                "header": header().model_dump(),
                "arms": {
                    "cutter": {
                        "names": ["a", "b"],
                        "position_rad": [0.0],
                        "velocity_rad_s": [0.0, 0.0],
                    }
                },
            }
        )


def test_arms_are_keyed_by_role() -> None:
    with pytest.raises(ValidationError):
        JointState.model_validate(
            {
                "header": header().model_dump(),
                "arms": {"left": {"names": ["a"], "position_rad": [0.0], "velocity_rad_s": [0.0]}},
            }
        )


def test_json_round_trip_is_byte_stable() -> None:
    d = Detections(
        header=header(answers_seq=3),
        image_width_px=640,
        image_height_px=480,
        detector="hsv",
        detections=(Detection(xyxy_px=(1, 2, 3, 4), score=0.9),),
    )
    codec = TOPICS["perception/detections"].codec
    payload = codec.encode(d)
    assert codec.decode(payload) == d
    assert codec.encode(codec.decode(payload)) == payload


def test_topic_map_and_schema_names() -> None:
    assert topic("camera/rgbd").schema_name == "RgbdFrame"
    with pytest.raises(UnknownTopicError, match="unknown topic 'nope'"):
        topic("nope")
    names = set(all_schemas())
    assert {t.schema_name for t in TOPICS.values()} <= names
    assert "ServiceStatus" in names


UNIT_SUFFIXES = ("_m", "_rad", "_s", "_ns", "_ms", "_px", "_m_s", "_rad_s", "_frames", "_xyzw")
PHYSICAL_WORDS = {
    "position",
    "velocity",
    "distance",
    "radius",
    "depth",
    "time",
    "stamp",
    "error",
    "speed",
    "semi",
    "center",
    "orientation",
    "duration",
}
NOT_PHYSICAL = {"depth_encoding", "stamp_ns"}


@pytest.mark.parametrize("schema_name", sorted(all_schemas()))
def test_physical_fields_carry_their_unit(schema_name: str) -> None:
    """Names carry units: a field about a physical quantity ends in a unit suffix."""
    for p in _property_names(all_schemas()[schema_name]) - NOT_PHYSICAL:
        if PHYSICAL_WORDS & set(p.split("_")):
            assert p.endswith(UNIT_SUFFIXES), f"{schema_name}.{p} does not end in a unit"


def _property_names(schema: dict) -> set[str]:
    out: set[str] = set()
    for s in [schema, *schema.get("$defs", {}).values()]:
        out |= set(s.get("properties", {}))
    return out


def test_rgbd_frame_meta_requires_a_frame_id() -> None:
    intr = CameraIntrinsics(width_px=4, height_px=2, fx_px=1, fy_px=1, cx_px=2, cy_px=1)
    with pytest.raises(ValidationError, match="frame_id"):
        RgbdFrameMeta(
            header=header(frame_id=""), intrinsics=intr, T_world_camera=Pose(position_m=(0, 0, 0))
        )


def make_frame(w: int = 8, h: int = 6, seed: int = 0) -> RgbdFrame:
    rng = np.random.default_rng(seed)
    intr = CameraIntrinsics(width_px=w, height_px=h, fx_px=5, fy_px=5, cx_px=w / 2, cy_px=h / 2)
    meta = RgbdFrameMeta(
        header=header(frame_id="camera_optical"),
        intrinsics=intr,
        T_world_camera=Pose(position_m=(0, 0, 1)),
    )
    rgb = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    depth = rng.integers(0, 65535, (h, w), dtype=np.uint16)
    return RgbdFrame(meta, rgb, depth)
