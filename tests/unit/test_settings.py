"""Settings: YAML < environment < flags; a bad value names the field."""

from __future__ import annotations

from pathlib import Path

import pytest

from services.demo_clock import Settings as ClockSettings
from services.runtime.settings import (
    SettingsError,
    config_hash,
    load_settings,
    parse_overrides,
    read_yaml,
)


def test_layers_yaml_then_env_then_flags(monkeypatch: pytest.MonkeyPatch) -> None:
    yaml_layer = {"ticks": 5, "seed": 1, "gain": 0.1}
    s = load_settings(ClockSettings, yaml_layer)
    assert (s.ticks, s.seed, s.gain) == (5, 1, 0.1)
    monkeypatch.setenv("HARVEST_DEMO_CLOCK_SEED", "2")
    monkeypatch.setenv("HARVEST_DEMO_CLOCK_TICKS", "6")
    s = load_settings(ClockSettings, yaml_layer)
    assert (s.ticks, s.seed) == (6, 2)
    s = load_settings(ClockSettings, yaml_layer, parse_overrides(["ticks=7"]))
    assert (s.ticks, s.seed, s.gain) == (7, 2, 0.1)


def test_bad_value_names_the_field() -> None:
    with pytest.raises(SettingsError, match=r"field 'ticks'.*greater than or equal to 1"):
        load_settings(ClockSettings, {"ticks": 0}, service="demo_clock")


def test_unknown_field_is_refused_with_its_name() -> None:
    with pytest.raises(SettingsError, match="field 'tiks'"):
        load_settings(ClockSettings, {"tiks": 3})


def test_overrides_parse_dotted_keys_and_yaml_values() -> None:
    assert parse_overrides(["a.b=1", "c=[1, 2]", "d=x"]) == {"a": {"b": 1}, "c": [1, 2], "d": "x"}
    with pytest.raises(SettingsError, match="KEY=VALUE"):
        parse_overrides(["novalue"])


def test_config_hash_is_stable_and_sensitive() -> None:
    a = load_settings(ClockSettings, {"ticks": 3})
    assert config_hash(a) == config_hash(load_settings(ClockSettings, {"ticks": 3}))
    assert config_hash(a) != config_hash(load_settings(ClockSettings, {"ticks": 4}))


def test_read_yaml_errors(tmp_path: Path) -> None:
    with pytest.raises(SettingsError, match="not found"):
        read_yaml(tmp_path / "nope.yaml")
    (tmp_path / "list.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(SettingsError, match="mapping"):
        read_yaml(tmp_path / "list.yaml")
    (tmp_path / "bad.yaml").write_text("a: [\n")
    with pytest.raises(SettingsError, match="not valid YAML"):
        read_yaml(tmp_path / "bad.yaml")


def test_zenoh_json5_files_load_and_flags_go_on_top() -> None:
    import json

    from services.bus.config import BusSettings, make_zenoh_config

    s = BusSettings(
        config_file=Path("deploy/zenoh/client-local.json5"),
        namespace="ns1",
        connect=("tcp/127.0.0.1:9999",),
    )
    conf = make_zenoh_config(s)
    assert json.loads(conf.get_json("transport/shared_memory/enabled")) is True
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/127.0.0.1:9999"]
    assert json.loads(conf.get_json("namespace")) == "ns1"
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    make_zenoh_config(
        BusSettings(
            mode="router",
            config_file=Path("deploy/zenoh/router-local.json5"),
            listen=("tcp/127.0.0.1:9998",),
        )
    )
