"""Codecs: garbage and schema-violating payloads give a DecodeError with a reason; frames are
bit-exact."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from schemas import TOPICS, DecodeError
from schemas.camera import RgbdFrame
from tests.unit.test_schemas import header, make_frame

JSON_TOPICS = [k for k in TOPICS if k != "camera/rgbd"]


@pytest.mark.parametrize("key", sorted(TOPICS))
@given(garbage=st.binary(max_size=256))
@settings(max_examples=30, deadline=None)
def test_garbage_bytes_raise_decode_error(key: str, garbage: bytes) -> None:
    with pytest.raises(DecodeError) as e:
        TOPICS[key].codec.decode(garbage)
    assert e.value.reason


@pytest.mark.parametrize("key", JSON_TOPICS)
def test_schema_violating_json_names_the_field(key: str) -> None:
    with pytest.raises(DecodeError, match="header"):
        TOPICS[key].codec.decode(b'{"header": {"stamp_ns": -1, "seq": 0, "source": "x"}}')


def test_rgbd_round_trip_is_bit_exact() -> None:
    f = make_frame()
    codec = TOPICS["camera/rgbd"].codec
    payload = codec.encode(f)
    back = codec.decode(payload)
    assert isinstance(back, RgbdFrame)
    assert back.meta == f.meta
    np.testing.assert_array_equal(back.rgb, f.rgb)
    np.testing.assert_array_equal(back.depth, f.depth)
    assert codec.encode(back) == payload
    assert codec.header(payload) == f.meta.header


def test_rgbd_wrong_size_and_truncation_are_rejected() -> None:
    codec = TOPICS["camera/rgbd"].codec
    payload = codec.encode(make_frame())
    with pytest.raises(DecodeError, match="size"):
        codec.decode(payload[:-1])
    with pytest.raises(DecodeError, match="truncated RGB-D header"):
        codec.decode(payload[:12])
    with pytest.raises(DecodeError, match="magic"):
        codec.decode(b"XXXX" + payload[4:])


def test_rgbd_encode_refuses_arrays_that_do_not_match_the_intrinsics() -> None:
    f = make_frame()
    bad = RgbdFrame(f.meta, f.rgb[:, :4].copy(), f.depth)
    with pytest.raises(ValueError, match="rgb must be"):
        TOPICS["camera/rgbd"].codec.encode(bad)


def test_json_codec_refuses_the_wrong_type() -> None:
    with pytest.raises(TypeError, match="expected JointState"):
        TOPICS["robot/joint_state"].codec.encode(header())
