"""Zenoh session configuration: Zenoh's own json5 files plus the standard transport flags."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
RECONNECT = {"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2}
"""How clients re-dial a lost router (Zenoh's connect/retry)."""
BLOCK_CLOSE_US = 500_000
"""The router closes a link it could not write to for this long (a hung subscriber), µs."""
_NS_RE = re.compile(r"^[A-Za-z0-9_\-]+(/[A-Za-z0-9_\-]+)*$")


class BusSettings(BaseModel):
    """How a process joins the bus. Multicast scouting is off unless asked for."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    mode: Literal["client", "peer", "router"] = Field(
        default="client",
        description="Zenoh mode. Services are clients of the run's router: one star, so "
        "messages keep their causal order (what lock-step relies on).",
    )
    connect: tuple[str, ...] = Field(default=(DEFAULT_ENDPOINT,), description="Endpoints.")
    listen: tuple[str, ...] = Field(default=(), description="Endpoints to listen on.")
    namespace: str | None = Field(default=None, description="Key prefix of the run.")
    config_file: Path | None = Field(default=None, description="Zenoh json5 config file.")
    multicast_scouting: bool = Field(default=False, description="Zenoh multicast discovery.")
    lease_ms: int = Field(
        default=600,
        gt=0,
        description="Link lease: a hung peer is dropped after this, ms (a SIGSTOPped service "
        "loses its liveliness within it: 1000 ms measured 0.88-1.0 s, too close to 1 s).",
    )
    tls_dir: Path | None = Field(
        default=None,
        description="Certificates of the secured profile (`harvest certs make DIR`): ca.pem and "
        "<identity>.pem/.key. Set: every link is TLS with mutual authentication.",
    )
    tls_identity: str | None = Field(
        default=None,
        description="Which certificate of tls_dir this process presents (its common name is "
        "what the router's access control matches); default: the process's bus name.",
    )

    @field_validator("namespace")
    @classmethod
    def _ns(cls, v: str | None) -> str | None:
        if v is not None and not _NS_RE.match(v):
            raise ValueError(f"namespace {v!r} must be key chunks of [A-Za-z0-9_-] joined by '/'")
        return v


class TlsError(ValueError):
    """A certificate or key of the secured profile is missing; the message names the file."""


def tls_files(tls_dir: Path, identity: str) -> dict[str, Path]:
    """The CA certificate and this identity's certificate and key, checked to exist."""
    files = {
        "ca": tls_dir / "ca.pem",
        "cert": tls_dir / f"{identity}.pem",
        "key": tls_dir / f"{identity}.key",
    }
    for what, path in files.items():
        if not path.is_file():
            raise TlsError(
                f"TLS: no {what} file {path} for identity {identity!r} "
                f"(make the certificates with `harvest certs make {tls_dir}`)"
            )
    return files


def tls_config(s: BusSettings, identity: str) -> dict[str, object]:
    """Zenoh's ``transport/link/tls`` block: mutual TLS with this identity's certificate.

    A router presents its certificate when clients connect (listen_*); clients and peers
    present theirs when they connect (connect_*); both check the other side against the CA.
    """
    assert s.tls_dir is not None
    f = tls_files(s.tls_dir, s.tls_identity or identity)
    out: dict[str, object] = {"root_ca_certificate": str(f["ca"]), "enable_mtls": True}
    if s.mode in ("router", "peer"):
        out |= {"listen_certificate": str(f["cert"]), "listen_private_key": str(f["key"])}
    if s.mode in ("client", "peer") or s.connect:
        out |= {"connect_certificate": str(f["cert"]), "connect_private_key": str(f["key"])}
    return out


def make_zenoh_config(s: BusSettings, identity: str = ""):
    """A zenoh.Config: the json5 file first (if any), then our settings on top.

    ``identity`` names the certificate to present when ``s.tls_dir`` is set (the process's
    bus name unless ``s.tls_identity`` says otherwise).
    """
    import zenoh

    conf = zenoh.Config.from_file(str(s.config_file)) if s.config_file else zenoh.Config()
    conf.insert_json5("mode", json.dumps(s.mode))
    if s.connect and s.mode != "router":
        conf.insert_json5("connect/endpoints", json.dumps(list(s.connect)))
    if s.listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(s.listen)))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(s.multicast_scouting))
    if s.mode == "peer" and not s.multicast_scouting:
        # Peers would otherwise gossip and open direct links, breaking the single-star order.
        conf.insert_json5("scouting/gossip/enabled", "false")
    if s.mode != "router":
        # After a router restart a client re-dials on this schedule and re-declares its
        # subscriptions and liveliness: measured 0.25 s back, against 2.1 s with Zenoh's
        # default (1 s first wait, doubling to 4 s). Start-up is unchanged: a client still fails
        # at once when the router is not there (connect/timeout_ms 0).
        conf.insert_json5("connect/retry", json.dumps(RECONNECT))
    if s.mode == "router":
        # A client that stops reading (SIGSTOP) fills its queue in the router; with BLOCK
        # congestion control the router then stalls every link until the stuck one is closed,
        # and the other clients' leases run out too. Closing a link blocked for 0.5 s (less
        # than a lease) keeps the fault on the hung client (Zenoh's default waits 5 s).
        conf.insert_json5(
            "transport/link/tx/queue/congestion_control/block/wait_before_close",
            str(BLOCK_CLOSE_US),
        )
    conf.insert_json5("transport/link/tx/lease", str(s.lease_ms))
    conf.insert_json5("transport/link/tx/keep_alive", "4")
    if s.namespace:
        conf.insert_json5("namespace", json.dumps(s.namespace))
    if s.tls_dir is not None:
        # Key by key, so that other TLS keys of the json5 file (if any) are kept.
        for key, value in tls_config(s, identity).items():
            conf.insert_json5(f"transport/link/tls/{key}", json.dumps(value))
    return conf


def add_bus_args(ap: argparse.ArgumentParser) -> None:
    """The transport flags every program takes (as in the zenoh-python examples)."""
    g = ap.add_argument_group("bus (Zenoh)")
    g.add_argument(
        "-e",
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help=f"endpoint to connect to (repeatable; default {DEFAULT_ENDPOINT})",
    )
    g.add_argument(
        "-l",
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help="endpoint to listen on (repeatable)",
    )
    g.add_argument("-m", "--mode", choices=["client", "peer", "router"], help="Zenoh mode")
    g.add_argument("--namespace", help="the run's key prefix")
    g.add_argument("--zenoh-config", type=Path, metavar="FILE", help="Zenoh json5 config file")
    g.add_argument(
        "--tls-dir",
        type=Path,
        metavar="DIR",
        help="secured profile: mutual TLS with the certificates in DIR (`harvest certs make`)",
    )
    g.add_argument(
        "--tls-identity",
        metavar="NAME",
        help="which certificate of --tls-dir to present (default: this program's name)",
    )
    g.add_argument(
        "--no-multicast-scouting",
        action="store_true",
        help="disable multicast scouting (the default; kept for compatibility)",
    )
    g.add_argument(
        "--multicast-scouting",
        action="store_true",
        help="enable multicast scouting (never in tests)",
    )


def bus_settings_from_args(args: argparse.Namespace, **defaults: object) -> BusSettings:
    """BusSettings from parsed flags; ``defaults`` fill what the flags leave unset."""
    values: dict[str, object] = dict(defaults)
    if args.mode:
        values["mode"] = args.mode
    if args.connect:
        values["connect"] = tuple(args.connect)
    if args.listen:
        values["listen"] = tuple(args.listen)
    if args.namespace:
        values["namespace"] = args.namespace
    if args.zenoh_config:
        values["config_file"] = args.zenoh_config
    if args.multicast_scouting and not args.no_multicast_scouting:
        values["multicast_scouting"] = True
    if getattr(args, "tls_dir", None):
        values["tls_dir"] = args.tls_dir
    if getattr(args, "tls_identity", None):
        values["tls_identity"] = args.tls_identity
    return BusSettings.model_validate(values)


def bus_args(s: BusSettings) -> list[str]:
    """The command-line flags that reproduce ``s`` (used by the supervisor to start services)."""
    out: list[str] = ["-m", s.mode]
    for e in s.connect:
        out += ["-e", e]
    for e in s.listen:
        out += ["-l", e]
    if s.namespace:
        out += ["--namespace", s.namespace]
    if s.config_file:
        out += ["--zenoh-config", str(s.config_file)]
    if s.multicast_scouting:
        out += ["--multicast-scouting"]
    if s.tls_dir:
        out += ["--tls-dir", str(s.tls_dir)]
    if s.tls_identity:
        out += ["--tls-identity", s.tls_identity]
    return out
