"""`harvest eval ...`: measured figures of the perception chain against ground truth.

Each evaluation lives in its own module with ``add_parser(esub)``; this one only makes the
group: ``eval detector`` and ``eval tracker`` (eval_perception), ``eval scene`` (eval_scene).
"""

from __future__ import annotations

import argparse

from services.cli import eval_perception, eval_scene

EVAL_MODULES = (eval_perception, eval_scene)


def add_parsers(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "eval",
        help="evaluations against ground truth (see BENCHMARKS.md)",
        description=__doc__,
    )
    esub = p.add_subparsers(dest="what", metavar="WHAT")
    esub.required = True
    for module in EVAL_MODULES:
        module.add_parser(esub)


def parse_seeds(text: str) -> list[int]:
    """'0-4' (inclusive) or '0,3,7' → seeds; a clear error otherwise."""
    try:
        if "-" in text:
            a, b = text.split("-", 1)
            seeds = list(range(int(a), int(b) + 1))
        else:
            seeds = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"seeds {text!r}: expected A-B or A,B,C") from None
    if not seeds or min(seeds) < 0:
        raise argparse.ArgumentTypeError(f"seeds {text!r}: need at least one seed, none < 0")
    return seeds
