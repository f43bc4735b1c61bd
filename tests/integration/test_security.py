"""Secured profile: mutual TLS and access control on the router (deploy/secure/router.json5).

Only the controller's certificate may publish robot/command and only the planner's robot/tool;
a certificate of our CA with an unknown name can do nothing; a client without a certificate,
or with one of another CA, cannot connect at all.
"""

from __future__ import annotations

import json
import shutil
import threading
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from services.bus import Bus, BusError, BusSettings, RawSample
from services.registry import SERVICE_MODULES
from services.security.certs import FIXED_IDENTITIES, common_name, make_certs
from tests.helpers import harvest, short_dir, wait_until, write_stack
from tests.security_helpers import (
    SECURE_ROUTER,
    free_tcp_port,
    need_openssl,
    start_tls_router,
    tls_session,
    wait_router,
)

pytestmark = pytest.mark.integration

IDENTITIES = ["router", "operator", "supervisor", "controller", "planner", "detector", "intruder"]


@pytest.fixture(scope="module")
def certs() -> Iterator[Path]:
    need_openssl()
    d = short_dir()
    make_certs(d / "certs", IDENTITIES)
    make_certs(d / "other-ca", ["controller"])  # a second CA: same name, wrong issuer
    yield d
    shutil.rmtree(d, ignore_errors=True)


@pytest.fixture
def secured(certs: Path, tmp_path: Path) -> Iterator[tuple[str, str]]:
    """A TLS router with the secured profile's ACL; yields its endpoint and a namespace."""
    endpoint, ns = f"tls/127.0.0.1:{free_tcp_port()}", f"test-{uuid.uuid4().hex[:8]}"
    proc = start_tls_router(certs / "certs", endpoint, tmp_path / "router.log")
    try:
        wait_router(endpoint, certs / "certs", ns, proc).close()
        yield endpoint, ns
    finally:
        proc.terminate()
        proc.wait(timeout=10)


class Inbox:
    """Everything an operator session receives, by key."""

    def __init__(self, bus: Bus) -> None:
        self.got: list[tuple[str, bytes]] = []
        self._lock = threading.Lock()
        bus.subscribe_raw("**", self._on)

    def _on(self, s: RawSample) -> None:
        with self._lock:
            self.got.append((s.key, s.payload))

    def has(self, key: str, payload: bytes) -> bool:
        with self._lock:
            return (key, payload) in self.got


def test_only_the_controller_commands_the_arms_and_only_the_planner_the_tool(
    certs: Path, secured: tuple[str, str]
) -> None:
    endpoint, ns = secured
    tls = certs / "certs"
    observer = tls_session(endpoint, tls, "operator", ns)
    assert observer is not None
    with observer:
        inbox = Inbox(observer)
        sessions = {n: tls_session(endpoint, tls, n, ns) for n in IDENTITIES[3:]}
        assert all(sessions.values()), "a certificate of our CA must be able to connect"
        # Subscriptions propagate asynchronously: wait until an allowed put gets through.
        ctl = sessions["controller"]
        assert ctl is not None
        wait_until(
            lambda: (
                ctl.put_raw("perception/detections", b"ping", "text/plain")
                or inbox.has("perception/detections", b"ping")
            ),
            10,
            "the observer's subscription",
        )
        for name, s in sessions.items():
            assert s is not None
            for key in ("robot/command", "robot/tool"):
                s.put_raw(key, name.encode(), "text/plain")
            s.put_raw("perception/tracks", name.encode(), "text/plain")  # after: a fence
        members = ["controller", "planner", "detector"]
        wait_until(
            lambda: all(inbox.has("perception/tracks", n.encode()) for n in members),
            10,
            "every member's allowed put",
        )
        assert inbox.has("robot/command", b"controller")
        assert inbox.has("robot/tool", b"planner")
        for denied in ("planner", "detector", "intruder"):
            assert not inbox.has("robot/command", denied.encode()), f"{denied} commanded the arms"
        for denied in ("controller", "detector", "intruder"):
            assert not inbox.has("robot/tool", denied.encode()), f"{denied} used the tool"
        # An unknown name of our CA connects but may do nothing, not even elsewhere.
        assert not inbox.has("perception/tracks", b"intruder")
        intruder = sessions["intruder"]
        assert intruder is not None and intruder.live_services(0.5) == []
        for s in sessions.values():
            if s is not None:
                s.close()


def test_a_client_without_a_certificate_or_with_another_ca_cannot_connect(
    certs: Path, secured: tuple[str, str]
) -> None:
    endpoint, ns = secured
    with pytest.raises(BusError, match="cannot connect"):
        Bus("no-cert", BusSettings(connect=(endpoint,), namespace=ns))
    # TLS with our CA to check the router, but no certificate of its own to present.
    conf_only_ca = _client_with_ca_only(endpoint, certs / "certs" / "ca.pem")
    with pytest.raises(zenoh.ZError):
        zenoh.open(conf_only_ca)
    assert tls_session(endpoint, certs / "other-ca", "controller", ns) is None
    # Plain TCP to the TLS port is not Zenoh's TLS handshake either.
    with pytest.raises(BusError):
        Bus("plain", BusSettings(connect=(endpoint.replace("tls/", "tcp/"),), namespace=ns))


def test_the_acl_admits_every_service_and_gives_the_actuators_to_one_each() -> None:
    acl = json.loads(zenoh.Config.from_file(str(SECURE_ROUTER)).get_json("access_control"))
    subjects = {s["id"]: set(s["cert_common_names"]) for s in acl["subjects"]}
    needed = set(SERVICE_MODULES) | set(FIXED_IDENTITIES)
    assert needed <= subjects["members"], f"not admitted: {needed - subjects['members']}"
    assert subjects["members"] - subjects["all_but_controller"] == {"controller"}
    assert subjects["members"] - subjects["all_but_planner"] == {"planner"}
    assert acl["default_permission"] == "deny"


def test_certs_make_writes_one_certificate_per_identity_named_by_its_common_name(
    tmp_path: Path,
) -> None:
    need_openssl()
    r = harvest("certs", "make", str(tmp_path / "c"), "--router-host", "10.9.8.7")
    assert r.returncode == 0, r.stdout + r.stderr
    for name in set(SERVICE_MODULES) | set(FIXED_IDENTITIES):
        assert common_name(tmp_path / "c" / f"{name}.pem") == name
        assert (tmp_path / "c" / f"{name}.key").stat().st_mode & 0o077 == 0
    r = harvest("certs", "make", str(tmp_path / "c"), "--names", "bad name")
    assert r.returncode == 1 and "identity 'bad name'" in r.stdout


def test_a_secured_run_finishes_and_a_missing_certificate_refuses_start(
    certs: Path, tmp_path: Path
) -> None:
    d = short_dir()
    try:
        stack = write_stack(d / "s.yaml", d / "rec", ticks=60)
        port = free_tcp_port()
        secure = json.dumps(
            {
                "router": {"listen": [f"tls/127.0.0.1:{port}"], "zenoh_config": str(SECURE_ROUTER)},
                "security": {"tls_dir": str(certs / "certs")},
            }
        )
        text = stack.read_text() + f"profiles:\n  secure: {secure}\n"
        stack.write_text(text)
        # The demo's services have no certificate in this folder yet: refused, file named.
        r = harvest("run", "--stack", str(stack), "--profile", "secure", "--run-id", "s1")
        assert r.returncode == 2, r.stdout
        out = " ".join(r.stdout.split())
        assert "no certificate for recorder, demo_worker, demo_clock" in out, out
        assert "--names recorder,demo_worker,demo_clock" in out
        make_certs(certs / "certs", ["recorder", "demo_clock", "demo_worker"])
        r = harvest("run", "--stack", str(stack), "--profile", "secure", "--run-id", "s2")
        assert r.returncode == 0, r.stdout + r.stderr
        assert "run finished" in r.stdout
        # An unencrypted endpoint with a TLS folder is refused before anything starts.
        stack.write_text(text.replace("tls/127.0.0.1", "tcp/127.0.0.1"))
        r = harvest("run", "--stack", str(stack), "--profile", "secure")
        assert r.returncode == 2 and "unencrypted endpoints" in r.stdout
    finally:
        shutil.rmtree(d, ignore_errors=True)


def _client_with_ca_only(endpoint: str, ca: Path) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(ca)))
    return conf
