"""`harvest`: run stacks, inspect the live bus, and work with recordings. `--help` everywhere."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from services.cli import bench, certs, dataset, evaluate, files, live, replay, run, train, view


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="harvest", description=__doc__)
    sub = ap.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    run.add_parser(sub)
    live.add_parsers(sub)
    files.add_parsers(sub)
    replay.add_parsers(sub)
    view.add_parser(sub)
    bench.add_parser(sub)
    dataset.add_parsers(sub)
    certs.add_parsers(sub)
    train.add_parsers(sub)
    evaluate.add_parsers(sub)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # `harvest echo ... | head`
        return 0


if __name__ == "__main__":
    sys.exit(main())
