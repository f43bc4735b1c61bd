"""Helpers of the secured-profile tests: certificates, a free TCP port, a TLS router."""

from __future__ import annotations

import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from services.bus import Bus, BusError, BusSettings
from tests.helpers import wait_until

SECURE_ROUTER = Path("deploy/secure/router.json5")


def need_openssl() -> None:
    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed: cannot make the secured profile's certificates")


def free_tcp_port() -> int:
    """A port nothing listens on now (the kernel's choice; tiny race, unique per test)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_tls_router(certs: Path, endpoint: str, log: Path) -> subprocess.Popen[bytes]:
    out = open(log, "wb")  # noqa: SIM115
    return subprocess.Popen(
        [
            sys.executable, "-m", "services.router", "-l", endpoint,
            "--zenoh-config", str(SECURE_ROUTER), "--tls-dir", str(certs),
        ],
        stdout=out,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )  # fmt: skip


def tls_session(endpoint: str, certs: Path | None, identity: str, namespace: str) -> Bus | None:
    """A client of the TLS router presenting ``identity``'s certificate; None if refused."""
    try:
        return Bus(
            f"test-{identity}",
            BusSettings(
                connect=(endpoint,), namespace=namespace, tls_dir=certs, tls_identity=identity
            ),
        )
    except BusError:
        return None


def wait_router(endpoint: str, certs: Path, namespace: str, proc: subprocess.Popen[bytes]) -> Bus:
    def probe() -> Bus | None:
        assert proc.poll() is None, f"the TLS router exited with {proc.returncode}"
        return tls_session(endpoint, certs, "operator", namespace)

    return wait_until(probe, 20, "the TLS router")  # type: ignore[return-value]
