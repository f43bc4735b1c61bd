"""Stack files: unknown services and bad fields are refused with the field named."""

from __future__ import annotations

from pathlib import Path

import pytest

from services.supervisor.stack import StackError, load_stack, resolve_service_settings
from services.supervisor.supervisor import Supervisor

GOOD = """
name: t
mode: lockstep
master: demo_clock
services:
  demo_worker: {}
  demo_clock: {main: true, settings: {ticks: 5}}
profiles:
  longer: {services: {demo_clock: {settings: {ticks: 50}}}}
"""


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "stack.yaml"
    p.write_text(text)
    return p


def test_default_stack_file_is_valid() -> None:
    stack = load_stack(Path("deploy/stack.yaml"))
    resolve_service_settings(stack)
    for profile in stack.profiles:
        resolve_service_settings(load_stack(Path("deploy/stack.yaml"), profile))


def test_profile_and_overrides_are_merged(tmp_path: Path) -> None:
    p = write(tmp_path, GOOD)
    assert load_stack(p).services["demo_clock"].settings == {"ticks": 5}
    assert load_stack(p, "longer").services["demo_clock"].settings == {"ticks": 50}
    s = load_stack(p, "longer", {"demo_clock": {"seed": 3}})
    assert s.services["demo_clock"].settings == {"ticks": 50, "seed": 3}


def test_unknown_service_is_refused(tmp_path: Path) -> None:
    p = write(tmp_path, GOOD.replace("demo_worker: {}", "detectorr: {}"))
    with pytest.raises(StackError, match="unknown service 'detectorr'"):
        load_stack(p)


def test_bad_field_is_named(tmp_path: Path) -> None:
    p = write(tmp_path, GOOD.replace("mode: lockstep", "mode: fast"))
    with pytest.raises(StackError, match="field 'mode'"):
        load_stack(p)
    p = write(tmp_path, GOOD.replace("demo_worker: {}", "demo_worker: {restrat: never}"))
    with pytest.raises(StackError, match=r"services\.demo_worker\.restrat"):
        load_stack(p)


def test_bad_service_setting_is_named(tmp_path: Path) -> None:
    p = write(tmp_path, GOOD.replace("ticks: 5", "ticks: -5"))
    with pytest.raises(StackError, match=r"(?s)services.demo_clock.settings.*field 'ticks'"):
        resolve_service_settings(load_stack(p))


def test_unknown_profile_and_missing_file(tmp_path: Path) -> None:
    with pytest.raises(StackError, match="no profile 'fast'"):
        load_stack(write(tmp_path, GOOD), "fast")
    with pytest.raises(StackError, match="not found"):
        load_stack(tmp_path / "missing.yaml")


def test_master_must_be_a_service(tmp_path: Path) -> None:
    with pytest.raises(StackError, match="master 'sim'"):
        load_stack(write(tmp_path, GOOD.replace("master: demo_clock", "master: sim")))


def test_lockstep_plan_and_orders(tmp_path: Path) -> None:
    stack = load_stack(write(tmp_path, GOOD))
    sup = Supervisor(
        stack.model_copy(
            update={"recording": stack.recording.model_copy(update={"dir": tmp_path})}
        ),
        Path("x"),
        "run-test",
        quiet=True,
    )
    sup._build_children()
    plan = sup.lockstep_plan()
    assert plan.wait == {"demo/tick": ("demo/answer",)}
    assert plan.consumers == ("recorder", "demo_worker")
    assert sup.start_order() == ["recorder", "demo_worker", "demo_clock"]
    assert sup.stop_order() == ["demo_clock", "demo_worker", "recorder"]
