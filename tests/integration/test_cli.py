"""CLI conveniences against a live run, and clear errors on bad recordings."""

from __future__ import annotations

import json
import shutil
import signal
from collections.abc import Iterator
from pathlib import Path

import pytest

from services.cli.main import build_parser
from tests.helpers import harvest, short_dir, start_harvest, wait_until, write_stack

pytestmark = pytest.mark.integration


def _subcommands() -> list[list[str]]:
    ap = build_parser()
    sub = next(a for a in ap._actions if a.dest == "command")
    out = [[name] for name in sub.choices]  # type: ignore[union-attr]
    out += [["bench", "bus"], ["bench", "viz"], ["bench", "sim"], ["dataset", "synth"]]
    return out


@pytest.mark.parametrize("cmd", _subcommands(), ids=" ".join)
def test_every_command_has_help(cmd: list[str]) -> None:
    r = harvest(*cmd, "--help")
    assert r.returncode == 0 and "usage: harvest" in r.stdout


@pytest.fixture(scope="module")
def live_run() -> Iterator[tuple[Path, str]]:
    d = short_dir()
    stack = write_stack(
        d / "s.yaml", d / "rec", ticks=100000, mode="live", period_ms=10.0, max_delay_ms=0
    )
    ep = f"unixsock-stream/{d}/router.sock"
    p = start_harvest(
        "run", "--stack", str(stack), "--run-id", "cli", "--listen", ep, log=d / "out.log"
    )
    wait_until(lambda: "demo_clock is live" in (d / "out.log").read_text(), 60, "the run")
    yield d, ep
    p.send_signal(signal.SIGINT)
    p.wait(timeout=60)
    shutil.rmtree(d, ignore_errors=True)


def test_topics_lists_keys_with_rates(live_run: tuple[Path, str]) -> None:
    _, ep = live_run
    r = harvest("topics", "-e", ep, "--duration", "1.5", "--json")  # namespace discovered
    assert r.returncode == 0, r.stderr
    data = json.loads(r.stdout)
    assert data["namespace"] == "harvest/cli"
    rates = {t["key"]: t["rate_hz"] for t in data["topics"]}
    assert 50 < rates["demo/tick"] < 150  # 100 Hz in live mode
    assert {t["key"]: t["schema"] for t in data["topics"]}["demo/answer"] == "DemoAnswer"


def test_echo_prints_decoded_messages(live_run: tuple[Path, str]) -> None:
    _, ep = live_run
    r = harvest("echo", "demo/tick", "-n", "3", "-e", ep, "--run", "cli", "--timeout", "10")
    lines = [json.loads(x) for x in r.stdout.splitlines()]
    assert len(lines) == 3 and all(x["key"] == "demo/tick" and "tick" in x for x in lines)
    assert lines[1]["header"]["seq"] == lines[0]["header"]["seq"] + 1


def test_status_lists_every_service(live_run: tuple[Path, str]) -> None:
    _, ep = live_run
    r = harvest("status", "-e", ep, "--json")
    assert r.returncode == 0, r.stderr
    names = {s["name"]: s for s in json.loads(r.stdout)}
    assert set(names) == {"recorder", "demo_worker", "demo_clock"}
    assert names["demo_worker"]["state"] == "running"
    assert names["demo_worker"]["mode"] == "live"
    r = harvest("status", "-e", ep)
    assert "demo_worker" in r.stdout


def test_live_tools_without_a_run_say_so(tmp_path: Path) -> None:
    r = harvest("status", "-e", "unixsock-stream//tmp/no-such-router.sock")
    assert r.returncode == 1 and "is the router running" in r.stderr


def test_a_bad_controller_bench_setting_is_named_without_a_traceback() -> None:
    r = harvest("bench", "controller", "--targets", "0", "--set", "limit_margin_rad=-1")
    assert r.returncode == 2 and "limit_margin_rad" in r.stderr
    assert "Traceback" not in r.stderr


def test_info_on_bad_files(tmp_path: Path) -> None:
    (tmp_path / "empty.mcap").write_bytes(b"")
    (tmp_path / "text.mcap").write_text("not an mcap at all")
    for name, why in (
        ("empty.mcap", "empty"),
        ("text.mcap", "not an MCAP"),
        ("missing.mcap", "no such file"),
    ):
        r = harvest("info", str(tmp_path / name))
        assert r.returncode == 1 and why in r.stderr, r.stderr
    r = harvest("recover", str(tmp_path / "text.mcap"))
    assert r.returncode == 1 and "not an MCAP" in r.stderr
    r = harvest("resim", str(tmp_path / "empty.mcap"), "--services", "demo_worker")
    assert r.returncode == 1 and "empty" in r.stderr
    r = harvest("resim", str(tmp_path / "empty.mcap"), "--services", "nope")
    assert r.returncode == 1


def test_info_of_a_recording_from_another_tool(tmp_path: Path) -> None:
    from mcap.writer import Writer

    with open(tmp_path / "other.mcap", "wb") as f:
        w = Writer(f)
        w.start()
        cid = w.register_channel("/foo", "json", 0)
        w.add_message(cid, log_time=1, data=b"{}", publish_time=1)
        w.finish()
    r = harvest("info", str(tmp_path / "other.mcap"))
    assert r.returncode == 0 and "/foo" in r.stdout and "no run metadata" in r.stdout
