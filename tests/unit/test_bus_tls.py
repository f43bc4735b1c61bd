"""Bus TLS settings: which certificate each mode presents, and a clear error for a missing file."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from services.bus import BusSettings
from services.bus.config import TlsError, make_zenoh_config, tls_config


def fake_certs(d: Path, *names: str) -> Path:
    (d / "ca.pem").write_text("ca")
    for n in names:
        (d / f"{n}.pem").write_text(n)
        (d / f"{n}.key").write_text(n)
    return d


def test_a_client_presents_its_own_certificate_and_checks_the_router_against_the_ca(
    tmp_path: Path,
) -> None:
    d = fake_certs(tmp_path, "controller")
    tls = tls_config(BusSettings(tls_dir=d), "controller")
    assert tls == {
        "root_ca_certificate": str(d / "ca.pem"),
        "enable_mtls": True,
        "connect_certificate": str(d / "controller.pem"),
        "connect_private_key": str(d / "controller.key"),
    }


def test_a_router_presents_its_certificate_on_listen(tmp_path: Path) -> None:
    d = fake_certs(tmp_path, "router")
    tls = tls_config(BusSettings(mode="router", connect=(), tls_dir=d), "router")
    assert tls["listen_certificate"] == str(d / "router.pem")
    assert "connect_certificate" not in tls


def test_tls_identity_overrides_the_bus_name(tmp_path: Path) -> None:
    d = fake_certs(tmp_path, "operator")
    s = BusSettings(tls_dir=d, tls_identity="operator")
    conf = make_zenoh_config(s, identity="cli-status")
    got = json.loads(conf.get_json("transport/link/tls/connect_certificate"))
    assert got == str(d / "operator.pem")


def test_tls_keys_of_the_json5_file_are_kept(tmp_path: Path) -> None:
    d = fake_certs(tmp_path, "router")
    s = BusSettings(
        mode="router", connect=(), tls_dir=d, config_file=Path("deploy/secure/router.json5")
    )
    conf = make_zenoh_config(s, identity="router")
    assert json.loads(conf.get_json("transport/link/tls/close_link_on_expiration")) is True
    assert json.loads(conf.get_json("access_control/enabled")) is True


def test_a_missing_certificate_names_the_file_and_the_command(tmp_path: Path) -> None:
    d = fake_certs(tmp_path, "sim")
    with pytest.raises(TlsError, match=r"no key file .*planner\.key.*harvest certs make"):
        (d / "planner.pem").write_text("x")
        tls_config(BusSettings(tls_dir=d), "planner")
