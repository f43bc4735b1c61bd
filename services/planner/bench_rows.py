"""`harvest bench harvest --rows FILE`: each finished run's row kept as one JSON line, so that a
bench stopped part-way resumes where it was, and benches run apart (other processes, other
days) combine into one table (``--from-rows``).

A line is ``{"key": …, "row": …}``. The key is what decides a row besides its order and seed:
the scenario, mode, fruit count, sim-time cap, ``--set`` overrides and the code (the git commit;
``+dirty`` with uncommitted changes to tracked files). A row is reused only under the same key,
and never one of a dirty tree: two dirty trees cannot be told apart. A line that does not parse
(the last one of a bench killed while writing it) is skipped and named, never fatal.
"""

from __future__ import annotations

import json
import os
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROWS_VERSION = 1
DIRTY = "+dirty"
REPO = Path(__file__).resolve().parents[2]


class RowsError(ValueError):
    """Rows that cannot be combined (different keys), with the file and line."""


def code_version(repo: Path = REPO) -> str:
    """The commit of ``repo`` (``+dirty`` when tracked files differ from it); ``unknown`` when
    it is no git checkout (an installed copy): such rows are never reused either."""
    try:
        top = _git(repo, "rev-parse", "--show-toplevel")
        head = _git(repo, "rev-parse", "HEAD")
        dirty = _git(repo, "status", "--porcelain", "--untracked-files=no")
    except (OSError, subprocess.CalledProcessError, subprocess.TimeoutExpired):
        return "unknown" + DIRTY
    if Path(top).resolve() != repo.resolve():  # an installed copy inside some other checkout
        return "unknown" + DIRTY
    return head + (DIRTY if dirty else "")


def _git(repo: Path, *args: str) -> str:
    out = subprocess.run(
        ["git", "-C", str(repo), *args], capture_output=True, text=True, check=True, timeout=30
    )
    return out.stdout.strip()


def run_key(
    scenario: str,
    mode: str,
    fruit_count: int | None,
    max_s: float,
    settings: dict[str, dict[str, Any]],
    code: str,
) -> dict[str, Any]:
    # Through JSON, so a key read back from a file compares equal (tuples become lists).
    key = {
        "version": ROWS_VERSION,
        "scenario": scenario,
        "mode": mode,
        "fruit_count": fruit_count,
        "max_s": max_s,
        "settings": settings,
        "code": code,
    }
    return json.loads(json.dumps(key, sort_keys=True))


@dataclass
class Rows:
    """The rows of one file, in file order, and the lines skipped (``"FILE line N: why"``)."""

    path: Path
    lines: list[tuple[int, dict[str, Any], dict[str, Any]]] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)


def read_rows(path: Path) -> Rows:
    """The rows in ``path`` (none when it does not exist yet)."""
    got = Rows(path)
    if not path.exists():
        return got
    text = path.read_text()
    lines = text.split("\n")
    for n, line in enumerate(lines, 1):
        if not line.strip():
            continue
        d, why = _parse(line)
        if d is not None:
            got.lines.append((n, d["key"], d["row"]))
            continue
        if n == len(lines) and not text.endswith("\n"):
            why = "cut short (the bench writing it was stopped)"
        got.skipped.append(f"{path} line {n}: {why}, skipped")
    return got


def _parse(line: str) -> tuple[dict[str, Any] | None, str]:
    """The line's ``{"key", "row"}`` object, or None and why it is no row."""
    try:
        d = json.loads(line)
    except json.JSONDecodeError as exc:
        return None, f"not JSON ({exc.msg})"
    if not isinstance(d, dict) or not isinstance(d.get("key"), dict):
        return None, "no key object"
    row = d.get("row")
    if not isinstance(row, dict):
        return None, "no row object"
    if not isinstance(row.get("order"), str) or type(row.get("seed")) is not int:
        return None, "the row names no order and seed"
    if d["key"].get("version") != ROWS_VERSION:
        return None, f"rows version {d['key'].get('version')!r}, expected {ROWS_VERSION}"
    return d, ""


def reusable(rows: Rows, key: dict[str, Any]) -> dict[tuple[str, int], dict[str, Any]]:
    """The rows made under ``key``, by (order, seed), a later line over an earlier one; none
    when the code is dirty or unknown."""
    if str(key["code"]).endswith(DIRTY):
        return {}
    return {(r["order"], r["seed"]): r for _n, k, r in rows.lines if k == key}


def append_row(path: Path, key: dict[str, Any], row: dict[str, Any]) -> None:
    """One more line, on disk before the next run starts (a stopped bench keeps it)."""
    with path.open("a") as f:
        f.write(json.dumps({"key": key, "row": row}, sort_keys=True) + "\n")
        f.flush()
        os.fsync(f.fileno())


def combined(paths: list[Path]) -> tuple[dict[str, Any], list[dict[str, Any]], list[str]]:
    """The common key, the rows (by order then seed; a later line over an earlier one for the
    same run) and the skipped lines of ``paths``. Rows under different keys do not add up:
    ``RowsError`` names the first line whose key differs and the fields that do."""
    key: dict[str, Any] | None = None
    first = ""
    runs: dict[tuple[str, int], dict[str, Any]] = {}
    skipped: list[str] = []
    for path in paths:
        if not path.is_file():
            raise RowsError(f"{path}: no such rows file")
        rows = read_rows(path)
        skipped += rows.skipped
        for n, k, r in rows.lines:
            if key is None:
                key, first = k, f"{path} line {n}"
            elif k != key:
                diff = sorted(f for f in set(k) | set(key) if k.get(f) != key.get(f))
                raise RowsError(
                    f"{path} line {n}: its key differs from {first}'s in {', '.join(diff)}: "
                    "rows of different runs do not add up"
                )
            runs[(r["order"], r["seed"])] = r
    if key is None:
        raise RowsError(f"no rows in {', '.join(map(str, paths))}")
    return key, [runs[k] for k in sorted(runs)], skipped
