"""`harvest certs make DIR`: the secured profile's CA and per-identity certificates."""

from __future__ import annotations

import argparse
from pathlib import Path

from services.cli.ui import console


def add_parsers(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "certs",
        help="certificates of the secured profile (mutual TLS + access control)",
        description="Make a private CA and one certificate per identity (common name = the "
        "service name) for deploy/secure/router.json5. See deploy/secure/README.md.",
    )
    csub = p.add_subparsers(dest="certs", metavar="WHAT")
    csub.required = True
    m = csub.add_parser(
        "make",
        help="make (or add to) a certificate folder",
        description="Writes ca.pem/ca.key (kept when they exist) and NAME.pem/NAME.key for "
        "every identity. Keys are mode 0600; keep ca.key off the robot.",
    )
    m.add_argument("dir", type=Path, help="folder, e.g. deploy/secure/certs")
    m.add_argument(
        "--names",
        help="comma-separated identities (default: every service, router, supervisor, operator)",
    )
    m.add_argument(
        "--router-host",
        action="append",
        default=[],
        metavar="HOST",
        help="a name or address clients dial to reach the router (repeatable; localhost and "
        "127.0.0.1 are always included)",
    )
    m.add_argument("--days", type=int, default=825, help="validity in days (default 825)")
    m.set_defaults(func=cmd_make)


def cmd_make(args: argparse.Namespace) -> int:
    from services.security.certs import CertError, make_certs

    names = [n.strip() for n in args.names.split(",") if n.strip()] if args.names else None
    try:
        made = make_certs(args.dir, names, args.router_host, args.days)
    except (CertError, OSError) as exc:
        print(f"harvest certs make: {exc}")
        return 1
    con = console()
    ca = "made" if made.ca_created else "kept"
    con.print(f"CA {made.dir / 'ca.pem'} ({ca}); certificates: {', '.join(made.identities)}")
    return 0
