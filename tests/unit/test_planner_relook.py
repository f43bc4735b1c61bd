"""A cut that missed, the fruit still seen on its branch: the retry first looks from the ready
pose and re-plans from that view (while the tools were in front, the view was stale or cut),
then approaches again; with relook_before_retry off it cuts again from where the tools are."""

from __future__ import annotations

import numpy as np

from schemas.base import Header
from schemas.scene import Obstacles, SceneState, Trunk
from services.planner.core import PlannerCore
from tests.unit.test_planner_bench_fates import NS, TICK_NS, status
from tests.unit.test_planner_select import A, core_with, fruit

OFF = (A[0] - 0.02, A[1], A[2])  # the estimate at the cut: 2 cm nearer the camera than the fruit


def see(core: PlannerCore, p: tuple[float, float, float], t_ns: int) -> None:
    """One scene state: fruit 1 seen whole at ``p`` in the frame stamped ``t_ns``."""
    f = fruit(1, p, 0.5).model_copy(update={"last_seen_stamp_ns": t_ns})
    header = Header(stamp_ns=t_ns, seq=t_ns // TICK_NS, source="scene")
    state = SceneState(header=header, fruits=(f,), trunk=Trunk(found=False), obstacles=Obstacles())
    core.book.update(state, lambda _f, resting=False: False)


def drive(relook: bool) -> tuple[PlannerCore, list[str]]:
    """Planned at OFF; every pose is reached at once; the cut misses (the basket stays empty).
    The fruit is seen at OFF until the arms are back at the ready pose, at A from then on.
    Runs until the second attempt begins; returns the core and the phases entered."""
    core = core_with("nearest", fruit(1, OFF, 0.5))
    m, t = core.machine, 0
    m.s = m.s.model_copy(update={"relook_before_retry": relook})
    rec = core.book.records[1]
    phases: list[str] = []
    while t < 30 * NS and not (
        rec.cuts == 1 and m.phase in ("approach", "harvest") and phases[-1] != "cut"
    ):
        t += TICK_NS
        back = m.arrived_ns is not None
        see(core, A if back else OFF, t)
        before = m.phase
        m.step(t, status(m.next_seq, 0.001, t), m.next_seq + 1, 0)
        if m.phase != before or not phases:
            phases.append(m.phase)
    return core, phases


def test_a_missed_cut_is_retried_after_a_look_from_the_ready_pose() -> None:
    core, phases = drive(relook=True)
    m, rec = core.machine, core.book.records[1]
    assert phases[-3:] == ["cut", "leave", "approach"]
    assert rec.cuts == 1 and not rec.frozen and m.verify is None and not m.relook
    # re-planned from the view at the ready pose, 2 cm from the estimate the cut was aimed at
    assert np.allclose(rec.planned.centre_world_m, A)
    reasons = [e.reason for e in m.events]
    assert any("a look from afar first" in r for r in reasons)
    assert "re-planned from the view at the ready pose, 20 mm from the cut's aim" in reasons
    assert ("open", 1) in m.tools  # the shears opened before the tools backed out


def test_without_the_look_the_retry_cuts_again_on_the_same_estimate() -> None:
    core, phases = drive(relook=False)
    rec = core.book.records[1]
    assert phases[-2:] == ["cut", "harvest"]
    assert np.allclose(rec.planned.centre_world_m, OFF)


def test_no_fresh_view_at_the_ready_pose_keeps_the_estimate() -> None:
    # The fruit is hidden once the arms are back: after verify_s the retry goes on, as aimed.
    core = core_with("nearest", fruit(1, OFF, 0.5))
    m, t, rec = core.machine, 0, core.book.records[1]
    m.s = m.s.model_copy(update={"relook_before_retry": True})
    while t < 30 * NS and not (rec.cuts == 1 and m.phase == "approach"):
        t += TICK_NS
        if m.arrived_ns is None:
            see(core, OFF, t)
        m.step(t, status(m.next_seq, 0.001, t), m.next_seq + 1, 0)
    assert m.phase == "approach" and np.allclose(rec.planned.centre_world_m, OFF)
    assert m.arrived_ns is None  # reset on entering the approach
    reasons = [e.reason for e in m.events]
    assert "no fresh view at the ready pose: the estimate stays" in reasons
