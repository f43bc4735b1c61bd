"""Lock-step: two runs of the same stack, one under heavy CPU load, give byte-identical payloads
on every topic, although the worker sleeps a random wall-clock time on every tick."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import harvest, payloads_by_topic, short_dir, write_stack

pytestmark = pytest.mark.integration


def run_demo(d: Path, name: str, ticks: int) -> Path:
    stack = write_stack(d / f"{name}.yaml", d / "rec", ticks=ticks, max_delay_ms=3.0)
    r = harvest(
        "run",
        "--stack",
        str(stack),
        "--run-id",
        name,
        "--quiet",
        "--listen",
        f"unixsock-stream/{d}/{name}.sock",
    )
    assert r.returncode == 0, r.stdout + r.stderr
    return d / "rec" / f"{name}.mcap"


def test_two_runs_under_different_load_are_byte_identical() -> None:
    d = short_dir()
    burners: list[subprocess.Popen[bytes]] = []
    try:
        quiet = run_demo(d, "quiet", ticks=300)
        burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(3)]
        loaded = run_demo(d, "loaded", ticks=300)
    finally:
        for b in burners:
            b.kill()
            b.wait()
    a, b = payloads_by_topic(quiet), payloads_by_topic(loaded)
    assert set(a) == {"demo/tick", "demo/answer"}
    assert len(a["demo/tick"]) == len(a["demo/answer"]) == 300
    for topic in a:
        assert a[topic] == b[topic], f"{topic} differs between the two runs"
    shutil.rmtree(d, ignore_errors=True)


def test_live_mode_is_paced_by_the_wall_clock_and_does_not_wait() -> None:
    """Control for the test above: in live mode the clock is paced by the wall clock and does
    not wait for answers, so the feedback loop sees late answers and the ticks differ from the
    lock-step run of the same stack."""
    d = short_dir()
    runs = {}
    for mode in ("live", "lockstep"):
        stack = write_stack(
            d / f"{mode}.yaml", d / "rec", ticks=100, mode=mode, max_delay_ms=3.0, period_ms=1.0
        )
        r = harvest(
            "run",
            "--stack",
            str(stack),
            "--run-id",
            mode,
            "--quiet",
            "--listen",
            f"unixsock-stream/{d}/{mode}.sock",
        )
        assert r.returncode == 0, r.stdout + r.stderr
        runs[mode] = d / "rec" / f"{mode}.mcap"
    from services.recorder.inspect import iter_messages

    ticks = [m for m in iter_messages(runs["live"]) if m.topic == "demo/tick"]
    span_s = (ticks[-1].log_time_ns - ticks[0].log_time_ns) * 1e-9
    assert span_s >= 0.099 * 0.9  # 99 ticks of 1 ms, paced by the wall clock
    live, lock = payloads_by_topic(runs["live"]), payloads_by_topic(runs["lockstep"])
    assert live["demo/tick"] != lock["demo/tick"]
    shutil.rmtree(d, ignore_errors=True)
