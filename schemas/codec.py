"""Codecs between messages and wire bytes: pydantic JSON for models, raw layout for RGB-D."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Generic, Protocol, TypeVar

from pydantic import BaseModel, ValidationError

from schemas.base import Header, Message
from schemas.camera import (
    RGBD_ENCODING,
    FrameError,
    RgbdFrame,
    RgbdFrameMeta,
    decode_rgbd,
    decode_rgbd_meta,
    encode_rgbd,
)

T = TypeVar("T")
M = TypeVar("M", bound=Message)


class DecodeError(ValueError):
    """A payload that does not decode or validate; ``reason`` is short enough to log once."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class Codec(Protocol[T]):
    """Turns one message type into bytes and back."""

    @property
    def schema_name(self) -> str: ...
    @property
    def zenoh_encoding(self) -> str: ...
    @property
    def mcap_message_encoding(self) -> str: ...

    def encode(self, msg: T) -> bytes: ...
    def decode(self, payload: bytes) -> T: ...
    def header(self, payload: bytes) -> Header: ...
    def json_schema(self) -> dict[str, Any]: ...


def _short(exc: ValidationError) -> str:
    """First error of a pydantic ValidationError as 'field.path: message'."""
    err = exc.errors(include_url=False)[0]
    loc = ".".join(str(p) for p in err["loc"]) or "<root>"
    more = f" (+{exc.error_count() - 1} more)" if exc.error_count() > 1 else ""
    return f"{loc}: {err['msg']}{more}"


@dataclass(frozen=True)
class JsonCodec(Generic[M]):
    """pydantic JSON: the cheapest codec for small messages (Rust encoder and parser)."""

    model: type[M]

    @property
    def schema_name(self) -> str:
        return self.model.__name__

    @property
    def zenoh_encoding(self) -> str:
        return f"application/json;{self.model.__name__}"

    mcap_message_encoding: str = "json"

    def encode(self, msg: M) -> bytes:
        if not isinstance(msg, self.model):
            raise TypeError(f"expected {self.model.__name__}, got {type(msg).__name__}")
        return msg.model_dump_json().encode()

    def decode(self, payload: bytes) -> M:
        try:
            return self.model.model_validate_json(payload)
        except ValidationError as exc:
            raise DecodeError(f"{self.model.__name__} invalid: {_short(exc)}") from None
        except (UnicodeDecodeError, ValueError) as exc:
            raise DecodeError(f"{self.model.__name__} undecodable: {exc}") from None

    def header(self, payload: bytes) -> Header:
        return self.decode(payload).header

    def json_schema(self) -> dict[str, Any]:
        return self.model.model_json_schema()


@dataclass(frozen=True)
class RgbdCodec:
    """Raw RGB u8 + depth u16 after a length-prefixed JSON header (see schemas.camera)."""

    schema_name: str = "RgbdFrame"
    zenoh_encoding: str = RGBD_ENCODING
    mcap_message_encoding: str = "x-harvest-rgbd"

    def encode(self, msg: RgbdFrame) -> bytes:
        return encode_rgbd(msg)

    def decode(self, payload: bytes) -> RgbdFrame:
        try:
            return decode_rgbd(payload)
        except FrameError as exc:
            raise DecodeError(str(exc)) from None

    def header(self, payload: bytes) -> Header:
        try:
            return decode_rgbd_meta(payload)[0].header
        except FrameError as exc:
            raise DecodeError(str(exc)) from None

    def json_schema(self) -> dict[str, Any]:
        schema = RgbdFrameMeta.model_json_schema()
        schema["title"] = "RgbdFrame"
        schema["description"] = (
            "RGB-D frame. Binary layout: b'RGBD' | u32 LE n | n bytes of this JSON object | "
            "rgb (H*W*3 u8, RGB) | depth (H*W u16 LE, depth_unit_m per count, 0 = invalid)."
        )
        return schema


def canonical_json(obj: Any) -> str:
    """Stable JSON text (sorted keys) for hashing settings and golden files."""
    if isinstance(obj, BaseModel):
        obj = obj.model_dump(mode="json")
    return json.dumps(obj, sort_keys=True, indent=2) + "\n"
