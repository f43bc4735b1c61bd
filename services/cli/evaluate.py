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
    """'0-4' (inclusive), '0,3,7', '3' or a mix → seeds (the benchmarks' parser); an argparse
    error naming the argument otherwise."""
    from services.planner.bench import BenchError
    from services.planner.bench import parse_seeds as parse

    try:
        return parse(text)  # never empty, never negative: '' and '-1' do not parse
    except BenchError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
