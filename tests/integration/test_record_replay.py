"""The recording chain: record, SIGKILL the recorder, recover, replay, resim: 100 % identical."""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

import pytest

from schemas import TOPICS
from services.recorder.inspect import RecordingError, iter_messages, read_info
from tests.helpers import BusEnv, harvest, payloads_by_topic, wait_until

pytestmark = pytest.mark.integration

PLAN = json.dumps(
    {"wait": {"demo/tick": ["demo/answer"]}, "consumers": ["recorder", "demo_worker"]}
)


def record_and_kill(env: BusEnv, out: Path) -> int:
    """Run clock + worker in lock-step, SIGKILL the recorder mid-run; returns how many messages
    the recorder had received 0.7 s before the kill (all of them must be recoverable)."""
    rec = env.service("services.recorder", "--out", str(out), log="recorder.log")
    me = env.client("tester")
    wait_until(lambda: "recorder" in me.live_services(0.3), 20, "recorder")
    env.service(
        "services.demo_worker",
        "--time-mode",
        "lockstep",
        "--set",
        "max_delay_ms=1",
        log="worker.log",
    )
    wait_until(lambda: "demo_worker" in me.live_services(0.3), 20, "worker")
    clock = env.service(
        "services.demo_clock",
        "--time-mode",
        "lockstep",
        "--lockstep-plan",
        PLAN,
        "--set",
        "ticks=4000",
        log="clock.log",
    )

    def received() -> int:
        st = me.query_status("recorder", 1.0)
        return sum(c.received for c in st[0].topics.values()) if st else 0

    wait_until(lambda: received() > 400, 30, "400 recorded messages")
    before = received()
    time.sleep(0.7)  # deliberately: the flush interval (0.5 s) must elapse
    os.kill(rec.pid, signal.SIGKILL)
    rec.wait()
    assert clock.wait(timeout=120) == 0, env.log("clock.log")
    return before


def test_record_kill_recover_replay_resim(bus_env: BusEnv) -> None:
    out = bus_env.dir / "run.mcap"
    before_kill = record_and_kill(bus_env, out)

    with pytest.raises(RecordingError, match="harvest recover"):
        read_info(out)
    r = harvest("info", str(out))
    assert r.returncode == 1 and "harvest recover" in r.stderr

    fixed = bus_env.dir / "fixed.mcap"
    r = harvest("recover", str(out), "-o", str(fixed))
    assert r.returncode == 0, r.stderr
    info = read_info(fixed)
    assert info.message_count >= before_kill, "lost more than the last 0.5 s"
    recorded = payloads_by_topic(fixed)
    n_ticks = len(recorded["demo/tick"])
    assert n_ticks > 200

    # Replay the ticks in lock-step into a fresh worker: its answers equal the recorded ones.
    replay_ns = bus_env.namespace + "-replay"
    bus_env.spawn(
        "-m",
        "services.demo_worker",
        "-e",
        bus_env.endpoint,
        "--namespace",
        replay_ns,
        "--set",
        "max_delay_ms=0",
        log="worker2.log",
    )
    me = bus_env.client("watch", namespace=replay_ns)
    answers: dict[int, bytes] = {}
    me.subscribe_raw(
        "demo/answer",
        lambda s: answers.setdefault(TOPICS["demo/answer"].codec.header(s.payload).seq, s.payload),
    )
    wait_until(lambda: "demo_worker" in me.live_services(0.3), 20, "replay worker")
    r = harvest(
        "replay",
        str(fixed),
        "--lockstep",
        "--include",
        "demo/tick",
        "-e",
        bus_env.endpoint,
        "--namespace",
        replay_ns,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    wait_until(lambda: len(answers) >= len(recorded["demo/answer"]), 10, "all answers")
    assert [answers[s] for s, _ in recorded["demo/answer"]] == [
        p for _, p in recorded["demo/answer"]
    ]

    # Resim: the worker alone, and the clock with the worker, are 100 % identical.
    # (This recording was made without the supervisor, so it has no settings metadata.)
    sets = ["--set", "demo_clock.ticks=4000", "--set", "demo_worker.max_delay_ms=0"]
    for services in ("demo_worker", "demo_clock,demo_worker"):
        extra = sets if "clock" in services else sets[2:]
        r = harvest("resim", str(fixed), "--services", services, "--json", *extra)
        assert r.returncode == 0, r.stdout + r.stderr
        rep = json.loads(r.stdout)
        assert rep["identical_ratio"] == 1.0 and rep["ok"]
        for t in rep["topics"]:
            assert t["identical"] == t["recorded"] > 200


def test_resim_reports_differences(bus_env: BusEnv, tmp_path: Path) -> None:
    """A changed service shows up as 'different' (the resim can fail)."""
    out = bus_env.dir / "run.mcap"
    record_and_kill(bus_env, out)
    fixed = bus_env.dir / "fixed.mcap"
    assert harvest("recover", str(out), "-o", str(fixed)).returncode == 0
    r = harvest(
        "resim",
        str(fixed),
        "--services",
        "demo_worker",
        "--json",
        "--set",
        "demo_worker.modulus=999",
    )
    rep = json.loads(r.stdout)
    assert r.returncode == 1 and not rep["ok"]
    (answer,) = rep["topics"]
    assert answer["different"] > 0 and answer["first_difference_seq"] is not None
    assert sum(1 for _ in iter_messages(fixed)) == read_info(fixed).message_count
