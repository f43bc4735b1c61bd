"""`harvest bench harvest --rows FILE`: a stopped bench resumes from the rows it wrote, rows of
benches run apart combine (``--from-rows``), and what cannot be trusted is not reused: rows of
other settings or code, of a dirty tree, or a line cut short."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from services.planner import bench
from services.planner.bench import BenchConfig, BenchError, from_rows, run_harvest_bench
from services.planner.bench_rows import DIRTY, code_version, read_rows
from tests.helpers import harvest


def fake_row(order: str, seed: int) -> dict[str, Any]:
    """A row as run_one gives it, with figures that tell the seeds apart."""
    return {
        "order": order,
        "seed": seed,
        "sim_s": 10.0 + seed,
        "wall_s": 100.0,
        "rtf": 0.1,
        "fruit": 5,
        "reachable": 4,
        "harvested": 3,
        "harvested_reachable": 3,
        "collisions": seed,
        "target_contacts": 0,
        "cycles_s": [3.0 + seed],
        "reachable_fates": {"harvested": 3, "blocked": 1},
        "max_velocity_ratio": 0.9,
    }


@pytest.fixture
def runs(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, int]]:
    """run_one replaced by ``fake_row``; the (order, seed) runs it was asked for."""
    asked: list[tuple[str, int]] = []

    def fake_run_one(cfg: BenchConfig, order: str, seed: int, workdir: Path) -> dict[str, Any]:
        asked.append((order, seed))
        if seed == 99:
            raise KeyboardInterrupt  # the bench stopped part-way
        return fake_row(order, seed)

    monkeypatch.setattr(bench, "run_one", fake_run_one)
    return asked


def config(rows: Path, seeds: list[int], code: str = "abc123", **kw: Any) -> BenchConfig:
    return BenchConfig("orchard", seeds, ("nearest",), rows_path=rows, code=code, **kw)


def test_a_stopped_bench_resumes_from_its_rows(tmp_path: Path, runs: list) -> None:
    rows = tmp_path / "rows.jsonl"
    with pytest.raises(KeyboardInterrupt):
        run_harvest_bench(config(rows, [0, 1, 99]))
    assert runs == [("nearest", 0), ("nearest", 1), ("nearest", 99)]
    assert [r["seed"] for _n, _k, r in read_rows(rows).lines] == [0, 1]  # on disk already
    lines: list[str] = []
    res = run_harvest_bench(config(rows, [0, 1, 2]), lines.append)
    assert runs[3:] == [("nearest", 2)]  # only the seed not yet run
    assert [r["seed"] for r in res["runs"]] == [0, 1, 2]
    assert res["policies"]["nearest"]["collisions"] == 0 + 1 + 2
    assert "nearest seed 0: the row in" in lines[0] and res["code"] == "abc123"


def test_rows_of_other_settings_or_code_are_run_again(tmp_path: Path, runs: list) -> None:
    rows = tmp_path / "rows.jsonl"
    run_harvest_bench(config(rows, [0]))
    run_harvest_bench(config(rows, [0], settings={"planner": {"branch_check": False}}))
    run_harvest_bench(config(rows, [0], code="def456"))
    run_harvest_bench(config(rows, [0], max_s=60.0))
    assert len(runs) == 4 and len(read_rows(rows).lines) == 4


def test_rows_of_uncommitted_code_are_written_and_never_reused(tmp_path: Path, runs: list) -> None:
    rows = tmp_path / "rows.jsonl"
    lines: list[str] = []
    for _ in range(2):
        run_harvest_bench(config(rows, [0], code="abc123" + DIRTY), lines.append)
    assert len(runs) == 2 and len(read_rows(rows).lines) == 2
    assert any("uncommitted changes" in line for line in lines)


def test_this_checkout_names_its_commit() -> None:
    code = code_version()
    head = code.removesuffix(DIRTY)
    assert len(head) == 40 and all(c in "0123456789abcdef" for c in head)
    assert code_version(Path("/")).endswith(DIRTY)  # no git checkout: never reused


def test_a_line_cut_short_or_malformed_is_skipped_and_named(tmp_path: Path, runs: list) -> None:
    rows = tmp_path / "rows.jsonl"
    run_harvest_bench(config(rows, [0, 1]))
    good = rows.read_text()
    rows.write_text(good + '["not a row"]\n{"key": {}, "row": {"order": "nearest"}}\n' + good[:40])
    got = read_rows(rows)
    assert [r["seed"] for _n, _k, r in got.lines] == [0, 1]
    assert len(got.skipped) == 3
    assert "line 3: no key object" in got.skipped[0]
    assert "line 4: the row names no order and seed" in got.skipped[1]
    assert "line 5: cut short" in got.skipped[2]
    lines: list[str] = []
    res = run_harvest_bench(config(rows, [0, 1]), lines.append)
    assert len(runs) == 2 and len(res["runs"]) == 2  # the good rows still count
    assert sum("skipped" in line for line in lines) == 3


def test_rows_run_apart_make_one_table(tmp_path: Path, runs: list) -> None:
    a, b = tmp_path / "a.jsonl", tmp_path / "b.jsonl"
    run_harvest_bench(config(a, [0, 2]))
    run_harvest_bench(config(b, [1]))
    res = from_rows([a, b])
    assert res["seeds"] == [0, 1, 2] and [r["seed"] for r in res["runs"]] == [0, 1, 2]
    pol = res["policies"]["nearest"]
    assert (pol["runs"], pol["harvested"], pol["collisions"]) == (3, 9, 3)
    assert pol["median_s_per_fruit"] == 4.0 and pol["reachable_fates"]["blocked"] == 3
    assert "orchard seeds 0-2" in bench.table(res)
    other = tmp_path / "other.jsonl"
    run_harvest_bench(config(other, [3], code="def456"))
    with pytest.raises(BenchError, match=r"other.jsonl line 1: its key differs .* in code"):
        from_rows([a, other])


def test_the_cli_combines_rows_and_names_a_missing_file(tmp_path: Path, runs: list) -> None:
    a = tmp_path / "a.jsonl"
    run_harvest_bench(config(a, [0, 1]))
    r = harvest("bench", "harvest", "--from-rows", str(a), "--json", timeout=120)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["policies"]["nearest"]["runs"] == 2
    r = harvest("bench", "harvest", "--from-rows", str(tmp_path / "none.jsonl"), timeout=120)
    assert r.returncode == 2 and "none.jsonl: no such rows file" in r.stderr


def test_seed_lists_print_as_ranges() -> None:
    assert bench.seed_ranges([0, 1, 2, 3, 4, 5, 6, 7, 10, 11, 13]) == "0-7,10-11,13"
    assert bench.parse_seeds(bench.seed_ranges([4, 8, 9])) == [4, 8, 9]
