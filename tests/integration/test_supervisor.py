"""`harvest run`: start, finish, restart on failure, detect a hung service, fail for good, stop
in order on Ctrl-C, and refuse bad stacks and busy endpoints."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from services.bus import Bus, BusSettings
from services.recorder.inspect import read_info
from tests.helpers import (
    harvest,
    payloads_by_topic,
    short_dir,
    start_harvest,
    wait_until,
    write_stack,
)

pytestmark = pytest.mark.integration


@pytest.fixture
def d() -> Iterator[Path]:
    import shutil

    p = short_dir()
    yield p
    shutil.rmtree(p, ignore_errors=True)


def endpoint(d: Path) -> str:
    return f"unixsock-stream/{d}/router.sock"


def run_args(stack: Path, d: Path, run_id: str) -> list[str]:
    return ["run", "--stack", str(stack), "--run-id", run_id, "--listen", endpoint(d)]


def observer(d: Path, run_id: str) -> Bus:
    return wait_until(lambda: _try_bus(d, run_id), 30, "the run's router")  # type: ignore[return-value]


def _try_bus(d: Path, run_id: str) -> Bus | None:
    try:
        return Bus(
            "test-observer", BusSettings(connect=(endpoint(d),), namespace=f"harvest/{run_id}")
        )
    except Exception:
        return None


def pid_of(bus: Bus, name: str) -> int:
    st = wait_until(lambda: bus.query_status(name, 1.0), 30, f"status of {name}")
    return st[0].pid  # type: ignore[index]


def worker_ticks(bus: Bus) -> int:
    st = bus.query_status("demo_worker", 1.0)
    return st[0].topics["demo/tick"].received if st and "demo/tick" in st[0].topics else 0


def test_run_finishes_and_records_with_metadata(d: Path) -> None:
    stack = write_stack(d / "s.yaml", d / "rec", ticks=50)
    r = harvest(*run_args(stack, d, "ok"))
    assert r.returncode == 0, r.stdout + r.stderr
    assert "run finished" in r.stdout
    info = read_info(d / "rec" / "ok.mcap")
    assert {c.topic: c.count for c in info.channels} == {"demo/answer": 50, "demo/tick": 50}
    run = info.run
    assert run["run_id"] == "ok" and run["mode"] == "lockstep" and run["master"] == "demo_clock"
    services = json.loads(run["services"])
    assert services["demo_clock"]["ticks"] == 50 and "recorder" in services
    assert json.loads(run["versions"])["eclipse-zenoh"] == "1.10.2"
    assert run["git_revision"]
    assert (d / "rec" / "ok.log").read_text().count("demo_clock") > 0


def test_killed_service_is_restarted_and_the_run_completes(d: Path) -> None:
    stack = write_stack(d / "s.yaml", d / "rec", ticks=3000, max_delay_ms=1.0)
    p = start_harvest(*run_args(stack, d, "kill"), log=d / "out.log")
    with observer(d, "kill") as bus:
        pid = pid_of(bus, "demo_worker")
        wait_until(lambda: worker_ticks(bus) > 200, 30, "worker progress")
        os.kill(pid, signal.SIGKILL)
        assert p.wait(timeout=120) == 0, (d / "out.log").read_text()
    out = (d / "out.log").read_text()
    assert "restarting demo_worker (restart 1/3)" in out
    got = payloads_by_topic(d / "rec" / "kill.mcap")
    assert len(got["demo/tick"]) == 3000


def test_hung_service_is_detected_by_liveliness_and_restarted(d: Path) -> None:
    stack = write_stack(d / "s.yaml", d / "rec", ticks=3000, max_delay_ms=1.0)
    p = start_harvest(*run_args(stack, d, "hung"), log=d / "out.log")
    with observer(d, "hung") as bus:
        pid = pid_of(bus, "demo_worker")
        lost: list[float] = []
        bus.watch_health(
            lambda n, up: lost.append(time.monotonic()) if (n == "demo_worker" and not up) else None
        )
        wait_until(lambda: worker_ticks(bus) > 200, 30, "worker progress")
        os.kill(pid, signal.SIGSTOP)
        wait_until(lambda: lost, 5, "liveliness loss of the stopped worker")
        assert p.wait(timeout=120) == 0, (d / "out.log").read_text()
    out = (d / "out.log").read_text()
    assert "hung, killing it" in out and "restarting demo_worker" in out


def test_service_that_fails_for_good_stops_the_run_with_a_valid_recording(d: Path) -> None:
    stack = write_stack(
        d / "s.yaml", d / "rec", ticks=100000, worker_restart="never", max_delay_ms=1.0
    )
    p = start_harvest(*run_args(stack, d, "fail"), log=d / "out.log")
    with observer(d, "fail") as bus:
        pid = pid_of(bus, "demo_worker")
        wait_until(lambda: worker_ticks(bus) > 50, 30, "worker progress")
        os.kill(pid, signal.SIGKILL)
        assert p.wait(timeout=60) == 1
    out = (d / "out.log").read_text()
    assert "demo_worker failed for good" in out
    assert read_info(d / "rec" / "fail.mcap").message_count > 0


def test_ctrl_c_stops_in_order_and_finishes_the_recording(d: Path) -> None:
    stack = write_stack(d / "s.yaml", d / "rec", ticks=100000, max_delay_ms=1.0)
    p = start_harvest(*run_args(stack, d, "int"), log=d / "out.log")
    with observer(d, "int") as bus:
        wait_until(lambda: worker_ticks(bus) > 50, 30, "worker progress")
    p.send_signal(signal.SIGINT)
    assert p.wait(timeout=60) == 130
    out = (d / "out.log").read_text()
    assert "stopping in order" in out and "recording finished cleanly" in out
    lines = [ln for ln in out.splitlines() if ln.startswith("recorder") and "finished" in ln]
    assert lines, "the recorder did not finish its file"
    assert read_info(d / "rec" / "int.mcap").message_count > 100


def test_bad_stack_is_refused_with_the_field_named(d: Path) -> None:
    bad = d / "bad.yaml"
    bad.write_text("name: x\nservices:\n  detectr: {}\n")
    r = harvest("run", "--stack", str(bad), "--listen", endpoint(d))
    assert r.returncode == 2 and "unknown service 'detectr'" in r.stdout
    stack = write_stack(d / "s.yaml", d / "rec", ticks=5)
    r = harvest("run", "--stack", str(stack), "--set", "demo_clock.ticks=-1")
    assert r.returncode == 2 and "field 'ticks'" in r.stdout


def test_endpoint_in_use_is_a_clear_error(d: Path) -> None:
    router = subprocess.Popen(
        [sys.executable, "-m", "services.router", "-l", endpoint(d)], stderr=subprocess.DEVNULL
    )
    try:
        wait_until(lambda: (d / "router.sock").exists(), 20, "first router")
        stack = write_stack(d / "s.yaml", d / "rec", ticks=5)
        r = harvest(*run_args(stack, d, "busy"))
        assert r.returncode == 1
        assert "address already in use" in r.stdout
    finally:
        router.terminate()
        router.wait()
