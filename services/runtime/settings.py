"""Service settings: pydantic-settings with YAML (profile) < environment < command-line flags.

A bad value stops start-up with the offending field named (SettingsError).
"""

from __future__ import annotations

import contextvars
import hashlib
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError
from pydantic.fields import FieldInfo
from pydantic_settings import BaseSettings, PydanticBaseSettingsSource, SettingsConfigDict

from schemas.codec import canonical_json

_YAML_LAYER: contextvars.ContextVar[dict[str, Any]] = contextvars.ContextVar("yaml")


class SettingsError(ValueError):
    """Settings that do not validate; the message names the service, the field and the reason."""


class _YamlLayer(PydanticBaseSettingsSource):
    """The lowest-priority source: the service's block of the stack/profile YAML."""

    def get_field_value(self, field: FieldInfo, field_name: str) -> tuple[Any, str, bool]:
        return _YAML_LAYER.get({}).get(field_name), field_name, False

    def __call__(self) -> dict[str, Any]:
        return dict(_YAML_LAYER.get({}))


class ServiceSettings(BaseSettings):
    """Base of every service's settings. Subclasses set ``env_prefix`` (HARVEST_<NAME>_)."""

    model_config = SettingsConfigDict(extra="forbid", frozen=True, env_nested_delimiter="__")

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        # First wins: flags (init kwargs) > environment > YAML.
        return (init_settings, env_settings, _YamlLayer(settings_cls))


def parse_overrides(items: list[str] | None) -> dict[str, Any]:
    """``["a.b=1", "c=[1, 2]"]`` → ``{"a": {"b": 1}, "c": [1, 2]}`` (values parsed as YAML)."""
    out: dict[str, Any] = {}
    for item in items or []:
        if "=" not in item:
            raise SettingsError(f"--set {item!r}: expected KEY=VALUE")
        key, raw = item.split("=", 1)
        node = out
        *parents, leaf = key.strip().split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = yaml.safe_load(raw)
    return out


def load_settings(
    cls: type[ServiceSettings],
    yaml_layer: dict[str, Any] | None = None,
    overrides: dict[str, Any] | None = None,
    service: str = "",
) -> ServiceSettings:
    """Validate settings from the three layers; raise SettingsError naming the bad field."""
    token = _YAML_LAYER.set(dict(yaml_layer or {}))
    try:
        return cls(**(overrides or {}))
    except ValidationError as exc:
        raise SettingsError(
            format_validation_error(exc, f"settings of {service or cls.__name__}")
        ) from None
    finally:
        _YAML_LAYER.reset(token)


def format_validation_error(exc: ValidationError, what: str) -> str:
    lines = [f"invalid {what}:"]
    for err in exc.errors(include_url=False):
        loc = ".".join(str(p) for p in err["loc"]) or "<root>"
        got = err.get("input")
        got_s = "" if isinstance(got, dict) else f" (got {got!r})"
        lines.append(f"  field '{loc}': {err['msg']}{got_s}")
    return "\n".join(lines)


def read_yaml(path: Path) -> dict[str, Any]:
    """A YAML mapping from ``path``; a clear SettingsError when missing or not a mapping."""
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except FileNotFoundError:
        raise SettingsError(f"settings file not found: {path}") from None
    except yaml.YAMLError as exc:
        raise SettingsError(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise SettingsError(f"{path}: expected a mapping at the top level")
    return data


def config_hash(settings: ServiceSettings) -> str:
    """First 16 hex digits of the SHA-256 of the resolved settings' canonical JSON."""
    return hashlib.sha256(canonical_json(settings).encode()).hexdigest()[:16]
