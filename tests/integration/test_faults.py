"""Faults survived under the supervisor, one test per service type of the running stack: a
SIGKILLed service is restarted; a SIGSTOPped (hung) one is found through its lost liveliness,
killed and restarted; either way the lock-step run completes with every tick recorded and
answered. A SIGKILLed recorder restarts into the next part file and `harvest recover` makes the
killed part valid. (Figures: `harvest bench faults`, BENCHMARKS.md.)"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from schemas import TOPICS
from services.bus import Bus, BusSettings
from services.recorder.inspect import iter_messages, read_info
from tests.helpers import harvest, payloads_by_topic, short_dir, start_harvest, wait_until

pytestmark = pytest.mark.integration

SIM_S = 5.0  # sim seconds of the run: 121 joint states a second
FAST = "{policy: on-failure, max_restarts: 3, backoff_s: 0.05}"


@pytest.fixture
def d() -> Iterator[Path]:
    p = short_dir()
    yield p
    shutil.rmtree(p, ignore_errors=True)


def fault_stack(d: Path, sim_s: float = SIM_S) -> Path:
    """The services this branch runs, each restarted on failure, the sim (clock master) main."""
    path = d / "faults.yaml"
    path.write_text(f"""
name: faults
mode: lockstep
master: sim
scenario: paper-exp1
recording: {{enabled: true, dir: {d / "rec"}, restart: {FAST}}}
services:
  controller: {{restart: {FAST}}}
  viz: {{restart: {FAST}, settings: {{viewer: none, save_path: {d / "viz.rrd"}}}}}
  sim:
    main: true
    settings: {{scenario: paper-exp1, duration_s: {sim_s}}}
""")
    return path


def endpoint(d: Path) -> str:
    return f"unixsock-stream/{d}/router.sock"


def observer(d: Path, run_id: str) -> Bus:
    def try_bus() -> Bus | None:
        try:
            s = BusSettings(connect=(endpoint(d),), namespace=f"harvest/{run_id}")
            return Bus("test-observer", s)
        except Exception:
            return None

    return wait_until(try_bus, 60, "the run's router")  # type: ignore[return-value]


def received(bus: Bus, name: str, run: subprocess.Popen[bytes] | None = None) -> int:
    """Messages ``name`` has received (fails at once when the run ended meanwhile)."""
    assert run is None or run.poll() is None, "the run ended early"
    st = bus.query_status(name, 1.0)
    return sum(c.received for c in st[0].topics.values()) if st else 0


def pid_of(bus: Bus, name: str) -> int:
    st = wait_until(lambda: bus.query_status(name, 1.0), 60, f"status of {name}")
    return st[0].pid  # type: ignore[index]


def start_and_fault(d: Path, run_id: str, name: str, sig: int) -> tuple[str, list[str]]:
    """Start the stack, wait for progress, send ``sig`` to ``name``; returns the run's output and
    the liveliness changes of ``name`` the observer saw ("up" / "down")."""
    stack = fault_stack(d)
    argv = ["run", "--stack", str(stack), "--run-id", run_id, "--listen", endpoint(d)]
    p = start_harvest(*argv, log=d / "out.log")
    seen: list[str] = []
    with observer(d, run_id) as bus:
        bus.watch_health(lambda n, up: seen.append("up" if up else "down") if n == name else None)
        pid = pid_of(bus, name)
        wait_until(lambda: received(bus, name, p) > 100, 120, f"{name} progress")
        os.kill(pid, sig)
        wait_until(lambda: "down" in seen, 30, f"{name}'s liveliness to go")
        assert p.wait(timeout=300) == 0, (d / "out.log").read_text()
    return (d / "out.log").read_text(), seen


def assert_every_tick_answered(mcap: Path) -> None:
    """Lock-step: every joint state from tick 0 to the end, each answered by one command."""
    got = payloads_by_topic(mcap)
    states = [s for s, _ in got["robot/joint_state"]]
    assert states == list(range(int(SIM_S * 120) + 1)), "a tick is missing"
    codec = TOPICS["robot/command"].codec
    answered = {codec.decode(p).header.answers_seq for _, p in got["robot/command"]}
    assert set(states) <= answered, f"ticks without a command: {sorted(set(states) - answered)}"


@pytest.mark.parametrize(
    ("name", "sig"),
    [
        ("controller", signal.SIGKILL),
        ("controller", signal.SIGSTOP),
        ("viz", signal.SIGKILL),
        ("viz", signal.SIGSTOP),
    ],
    ids=["controller-kill", "controller-hung", "viz-kill", "viz-hung"],
)
def test_faulty_service_is_restarted_and_the_run_completes(d: Path, name: str, sig: int) -> None:
    out, seen = start_and_fault(d, f"f-{name}-{sig}", name, sig)
    if sig == signal.SIGSTOP:
        assert f"{name} lost its liveliness while its process runs: hung, killing it" in out
    assert f"restarting {name} (restart 1/3)" in out
    assert "up" in seen[seen.index("down") :], f"{name} did not come back: {seen}"
    assert_every_tick_answered(d / "rec" / f"f-{name}-{sig}.mcap")


def test_killed_recorder_restarts_into_a_part_file_and_the_killed_part_recovers(d: Path) -> None:
    run_id = "f-rec"
    stack = fault_stack(d)
    argv = ["run", "--stack", str(stack), "--run-id", run_id, "--listen", endpoint(d)]
    p = start_harvest(*argv, log=d / "out.log")
    first, part1 = d / "rec" / f"{run_id}.mcap", d / "rec" / f"{run_id}.1.mcap"
    with observer(d, run_id) as bus:
        pid = pid_of(bus, "recorder")
        wait_until(lambda: received(bus, "recorder", p) > 300, 120, "recorder progress")
        before = received(bus, "recorder")
        time.sleep(0.7)  # deliberately: one flush interval (0.5 s) must pass before the kill
        os.kill(pid, signal.SIGKILL)
        assert p.wait(timeout=300) == 0, (d / "out.log").read_text()
    out = (d / "out.log").read_text()
    assert "restarting recorder (restart 1/3)" in out and f"goes on in {part1}" in out
    r = harvest("recover", str(first), "-o", str(d / "fixed.mcap"))
    assert r.returncode == 0 and "truncated" in r.stdout, r.stdout + r.stderr
    fixed = read_info(d / "fixed.mcap")  # a valid file: summary and index
    raw = sum(1 for m in iter_messages(d / "fixed.mcap") if not m.topic.startswith("/preview"))
    assert raw >= before, f"recovered {raw} messages, {before} were received 0.7 s before the kill"
    assert fixed.run["run_id"] == run_id  # the run metadata survives the kill
    second = payloads_by_topic(part1)
    last = int(SIM_S * 120)
    assert second["robot/joint_state"][-1][0] == last, "the second part does not reach the end"
    assert read_info(part1).run["run_id"] == run_id


@contextlib.contextmanager
def tmpfs(path: Path, size: str) -> Iterator[Path]:
    """A small tmpfs at ``path`` (a real full disk); skipped where mounting is not allowed."""
    path.mkdir(parents=True, exist_ok=True)
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)])
    if r.returncode != 0:
        pytest.skip("cannot mount a tmpfs here (needs root): no real full disk to test with")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], check=False)


def run_on(d: Path, run_id: str, sim_s: float) -> subprocess.Popen[bytes]:
    stack = fault_stack(d, sim_s)
    argv = ["run", "--stack", str(stack), "--run-id", run_id, "--listen", endpoint(d)]
    return start_harvest(*argv, log=d / "out.log")


def test_full_disk_stops_the_recording_with_the_path_named_and_the_run_goes_on(d: Path) -> None:
    with tmpfs(d / "rec", "3m"):
        p = run_on(d, "full", 3.0)
        assert p.wait(timeout=300) == 0, (d / "out.log").read_text()
        out = (d / "out.log").read_text()
    mcap = d / "rec" / "full.mcap"
    assert f"cannot write {mcap}: No space left on device" in out
    assert "recorder failed for good (exit code 3)" in out and "the run goes on without it" in out
    assert "restarting recorder" not in out  # a full disk stays full
    assert "sim finished: stopping the run" in out and "run finished" in out
    assert "restarting controller" not in out and "restarting viz" not in out


def test_read_only_recording_folder_is_refused_before_anything_starts(d: Path) -> None:
    rec = d / "rec"
    rec.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(rec)])
    if r.returncode != 0:
        pytest.skip("cannot mount a tmpfs here (needs root)")
    try:
        r2 = harvest(
            "run", "--stack", str(fault_stack(d)), "--run-id", "x", "--listen", endpoint(d)
        )
    finally:
        subprocess.run(["umount", "-l", str(rec)], check=False)
    assert r2.returncode == 2, r2.stdout + r2.stderr
    assert f"refused to start: cannot write the run log in {rec}" in r2.stdout
    assert "Read-only file system" in r2.stdout


def test_recording_file_that_cannot_be_made_fails_the_start_with_the_path_named(d: Path) -> None:
    (d / "rec" / "nf.mcap").mkdir(parents=True)  # a folder where the file should go
    r = harvest("run", "--stack", str(fault_stack(d)), "--run-id", "nf", "--listen", endpoint(d))
    assert r.returncode == 1, r.stdout + r.stderr
    mcap = d / "rec" / "nf.mcap"
    assert f"recorder exited with code 2 during start-up: recorder: cannot write {mcap}" in r.stdout
