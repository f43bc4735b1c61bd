"""The supervisor's health judgement: hung = process alive, liveliness gone for longer than the
grace; a loss while the router is away is judged only after the link is back."""

from __future__ import annotations

from pathlib import Path

from services.supervisor.health import Child, Health
from services.supervisor.process import LogSink, ManagedProcess
from services.supervisor.stack import RestartPolicy


def child(policy: RestartPolicy | None = None) -> Child:
    return Child(ManagedProcess("x", ["true"], LogSink()), policy or RestartPolicy())


def test_lost_liveliness_is_hung_after_the_grace() -> None:
    h = Health(hung_grace_s=0.3)
    c = child()
    h.children["x"] = c
    h.started("x", c)
    h.on_health("x", True)
    assert h.is_alive("x") and not h.hung(c, c.lost_at or 0.0)
    h.on_health("x", False)
    assert c.lost_at is not None
    assert not h.hung(c, c.lost_at + 0.2)
    assert h.hung(c, c.lost_at + 0.4)


def test_a_child_never_live_is_not_hung() -> None:
    h = Health(hung_grace_s=0.3)
    c = child()
    h.children["x"] = c
    h.started("x", c)
    h.on_health("x", False)
    assert not h.hung(c, 1e9)


def test_a_loss_during_a_router_outage_waits_for_the_reconnect_grace() -> None:
    h = Health(hung_grace_s=0.3, reconnect_grace_s=3.0)
    c = child()
    h.children["x"] = c
    h.started("x", c)
    h.on_health("x", True)
    h.on_health("router", False)  # the router went away: every token vanishes
    h.on_health("x", False)
    assert not h.hung(c, c.lost_at + 10)  # type: ignore[operator]
    h.link(True)
    h.link(True)
    assert [ln.split(":")[0] for ln in h.take_lines()] == ["lost the router", "the router is back"]
    back = h.link_up_since
    assert not h.hung(c, back + 3.0)
    assert h.hung(c, back + 3.4)


def test_restart_time_is_timed_from_process_start_to_liveliness() -> None:
    h = Health(hung_grace_s=0.3)
    c = child()
    h.children["x"] = c
    c.restarts = 1
    h.started("x", c)
    h.on_health("x", True)
    assert len(c.restart_s) == 1 and c.restart_s[0] >= 0


def test_backoff_doubles_and_gives_up() -> None:
    c = child(RestartPolicy(policy="on-failure", max_restarts=2, backoff_s=0.1))
    assert c.backoff_s() == 0.1
    c.restarts = 1
    assert c.backoff_s() == 0.2
    c.restarts = 2
    assert c.backoff_s() is None
    assert child().backoff_s() is None  # policy never


def test_log_sink_without_a_file(tmp_path: Path) -> None:
    LogSink(quiet=True).line("x", "no file, no error")


class _FakeBus:
    def __init__(self, pids: list[int]) -> None:
        self.pids = pids

    def query_status(self, name: str, timeout_s: float) -> list[object]:
        from types import SimpleNamespace

        return [SimpleNamespace(pid=p) for p in self.pids]


def test_lost_liveliness_with_a_status_answer_is_not_hung(tmp_path: Path) -> None:
    """A link that flapped (a lease missed under load) is told from a hang by a status query
    that only the running process can answer."""
    from services.supervisor.stack import load_stack
    from services.supervisor.supervisor import Supervisor

    (tmp_path / "s.yaml").write_text(
        "name: t\nmode: lockstep\nmaster: demo_clock\n"
        f"recording: {{dir: {tmp_path}}}\n"
        "services:\n  demo_worker: {}\n  demo_clock: {main: true}\n"
    )
    sup = Supervisor(load_stack(tmp_path / "s.yaml"), tmp_path / "s.yaml", "r", quiet=True)
    c = child()
    c.proc.proc = type("P", (), {"pid": 4242})()  # type: ignore[assignment]
    sup.bus = _FakeBus([4242])  # type: ignore[assignment]
    assert sup._answers("demo_worker", c)
    sup.bus = _FakeBus([1])  # type: ignore[assignment]
    assert not sup._answers("demo_worker", c)  # another process answers: not ours
    sup.bus = _FakeBus([])  # type: ignore[assignment]
    assert not sup._answers("demo_worker", c)
    sup.sink.close()


def test_a_service_that_exits_after_dropping_its_liveliness_is_not_killed(tmp_path: Path) -> None:
    """A finished service's token and status go before its process ends (teardown is slow under
    load): the supervisor must see the normal exit, not kill a 'hung' process."""
    import time

    from services.supervisor.stack import load_stack
    from services.supervisor.supervisor import Supervisor

    (tmp_path / "s.yaml").write_text(
        "name: t\nmode: lockstep\nmaster: demo_clock\n"
        f"recording: {{dir: {tmp_path}}}\n"
        "services:\n  demo_worker: {}\n  demo_clock: {main: true}\n"
    )
    sup = Supervisor(load_stack(tmp_path / "s.yaml"), tmp_path / "s.yaml", "r", quiet=True)
    sup.bus = _FakeBus([])  # type: ignore[assignment]  # nobody answers the status query
    c = Child(ManagedProcess("x", ["sleep", "0.3"], LogSink()), RestartPolicy())
    c.proc.start()
    c.was_alive, c.lost_at = True, time.monotonic() - 10.0  # its token went long ago
    assert sup._check_child("demo_worker", c) is None
    assert c.proc.exit_codes == [0] and c.done and not c.failed
    sup.sink.close()
