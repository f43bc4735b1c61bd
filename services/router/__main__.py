"""python -m services.router -l tcp/127.0.0.1:7447 [--zenoh-config FILE]

Routes every client and peer of a run. Exits 2 when the endpoint cannot be bound (for example
when it is already in use), 0 on SIGTERM/SIGINT.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from services.bus import DEFAULT_ENDPOINT, Bus, BusError, add_bus_args, bus_settings_from_args
from services.runtime.service import setup_logging


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m services.router",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_bus_args(ap)
    args = ap.parse_args(argv)
    setup_logging("router")
    if not args.listen:
        args.listen = [DEFAULT_ENDPOINT]
    args.mode = "router"
    settings = bus_settings_from_args(args, connect=())
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    try:
        bus = Bus("router", settings)
    except BusError as exc:
        print(f"router: {exc}", file=sys.stderr)
        return 2
    bus.declare_health()
    print(f"router: listening on {', '.join(settings.listen)}", file=sys.stderr, flush=True)
    stop.wait()
    bus.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
