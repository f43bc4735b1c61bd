"""Make the secured profile's certificates with openssl: a CA and one certificate per identity.

Each identity (a service, the router, the supervisor, an operator) gets ``<name>.pem`` and
``<name>.key`` whose common name is the identity: the router's access control matches it
(deploy/secure/router.json5). The router's certificate also names the addresses clients dial
(subjectAltName), because clients check it (Zenoh's verify_name_on_connect).
"""

from __future__ import annotations

import ipaddress
import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

FIXED_IDENTITIES = ("router", "supervisor", "operator")
"""Identities besides the services: the router, the supervisor, and people's CLI tools."""

ROUTER_HOSTS = ("localhost", "127.0.0.1")
_NAME_RE = re.compile(r"^[A-Za-z0-9_\-]+$")
_EC = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]


class CertError(RuntimeError):
    """openssl is missing or failed; the message says which step and why."""


@dataclass(frozen=True)
class MadeCerts:
    dir: Path
    ca_created: bool
    identities: tuple[str, ...]


def default_identities() -> list[str]:
    """Every registered service plus the router, the supervisor and the operator."""
    from services.registry import SERVICE_MODULES

    return sorted(set(SERVICE_MODULES) | set(FIXED_IDENTITIES))


def _openssl(*args: str, what: str) -> None:
    exe = shutil.which("openssl")
    if exe is None:
        raise CertError("openssl is not installed (Debian: apt-get install openssl)")
    r = subprocess.run([exe, *args], capture_output=True, text=True)
    if r.returncode != 0:
        raise CertError(f"openssl failed to {what}: {r.stderr.strip()[-500:]}")


def _san(hosts: list[str]) -> str:
    out = []
    for h in hosts:
        try:
            ipaddress.ip_address(h)
            out.append(f"IP:{h}")
        except ValueError:
            out.append(f"DNS:{h}")
    return ",".join(out)


def make_ca(d: Path, days: int) -> None:
    _openssl(
        "req", "-x509", *_EC,
        "-keyout", str(d / "ca.key"), "-out", str(d / "ca.pem"), "-days", str(days),
        "-subj", "/CN=harvest-ca",
        "-addext", "basicConstraints=critical,CA:TRUE",
        "-addext", "keyUsage=critical,keyCertSign,cRLSign",
        what="make the CA",
    )  # fmt: skip
    os.chmod(d / "ca.key", 0o600)


def make_identity(d: Path, name: str, hosts: list[str], days: int) -> None:
    """``<name>.pem`` signed by the CA in ``d`` and ``<name>.key`` (mode 0600)."""
    if not _NAME_RE.match(name):
        raise CertError(f"identity {name!r}: use letters, digits, '_' and '-' only")
    with tempfile.TemporaryDirectory() as tmp:
        csr, ext = Path(tmp) / "req.csr", Path(tmp) / "ext.cnf"
        _openssl(
            "req", *_EC, "-keyout", str(d / f"{name}.key"), "-out", str(csr),
            "-subj", f"/CN={name}", what=f"make the key of {name!r}",
        )  # fmt: skip
        ext.write_text(
            "basicConstraints=critical,CA:FALSE\n"
            "keyUsage=critical,digitalSignature,keyEncipherment\n"
            "extendedKeyUsage=serverAuth,clientAuth\n"
            f"subjectAltName={_san(hosts or [name])}\n"
        )
        _openssl(
            "x509", "-req", "-in", str(csr), "-CA", str(d / "ca.pem"),
            "-CAkey", str(d / "ca.key"), "-CAcreateserial", "-days", str(days),
            "-extfile", str(ext), "-out", str(d / f"{name}.pem"),
            what=f"sign the certificate of {name!r}",
        )  # fmt: skip
    os.chmod(d / f"{name}.key", 0o600)


def make_certs(
    d: Path,
    names: list[str] | None = None,
    router_hosts: list[str] | None = None,
    days: int = 825,
) -> MadeCerts:
    """A CA in ``d`` (kept if it exists, so identities can be added later) and a certificate
    per identity (default: every service, router, supervisor, operator). ``router_hosts`` are
    the names and addresses clients use to reach the router (localhost and 127.0.0.1 always)."""
    d.mkdir(parents=True, exist_ok=True)
    ca_created = not (d / "ca.pem").exists()
    if ca_created:
        make_ca(d, days)
    elif not (d / "ca.key").exists():
        raise CertError(f"{d / 'ca.pem'} exists but {d / 'ca.key'} does not: cannot sign")
    ids = names or default_identities()
    for name in ids:
        hosts = [*ROUTER_HOSTS, *(router_hosts or [])] if name == "router" else [name]
        make_identity(d, name, hosts, days)
    return MadeCerts(d, ca_created, tuple(ids))


def common_name(cert: Path) -> str:
    """The subject common name of a PEM certificate (for `harvest certs show` and tests)."""
    exe = shutil.which("openssl")
    if exe is None:
        raise CertError("openssl is not installed (Debian: apt-get install openssl)")
    r = subprocess.run(
        [exe, "x509", "-in", str(cert), "-noout", "-subject", "-nameopt", "multiline"],
        capture_output=True,
        text=True,
    )
    if r.returncode != 0:
        raise CertError(f"{cert}: not a PEM certificate ({r.stderr.strip()[-200:]})")
    m = re.search(r"commonName\s*=\s*(\S+)", r.stdout)
    if m is None:
        raise CertError(f"{cert}: no common name")
    return m.group(1)
