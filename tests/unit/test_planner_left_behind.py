"""A track left where a moved fruit hung is no candidate while the fruit, under a new ID,
is estimated where it is now (paper-exp1 seed 11: a hand moved a fruit 6.7 cm, the tracker
gave it ID 37 and kept ID 6 alive on views the scene could not estimate; the tools went for
#6, stalled, and #6 was reported pending at the end)."""

from __future__ import annotations

from schemas.base import Header
from schemas.scene import Fruit, Obstacles, SceneState, Trunk
from tests.unit.test_planner_select import OK, core_with, fruit, select

S = 1_000_000_000
HUNG = (0.70, 0.00, 1.40)  # where the fruit hung (#6)
MOVED = (0.70, 0.05, 1.43)  # where a hand left it (#37): 5.8 cm away, one fruit


def view(fid: int, p: tuple[float, float, float], d_m: float, t_s: float, kept: bool) -> Fruit:
    f = fruit(fid, p, d_m).model_copy(update={"last_seen_stamp_ns": round(t_s * S)})
    return f.model_copy(update={"flags": ("depth_inconsistent", "kept")}) if kept else f


def feed(core: object, t_s: float, *fruits: Fruit) -> None:
    state = SceneState(
        header=Header(stamp_ns=round(t_s * S), seq=round(t_s * 15), source="scene"),
        fruits=fruits,
        trunk=Trunk(found=False),
        obstacles=Obstacles(),
    )
    core.book.update(state, lambda _f, resting=False: False)  # type: ignore[attr-defined]


def moved_core() -> object:
    """#6 estimated where it hung until 1 s, then only kept views there; #37 estimated where
    the fruit is now from 2 s on. #6 is the nearer of the two."""
    core = core_with("nearest", view(6, HUNG, 0.60, 0.0, kept=False))
    feed(core, 1.0, view(6, HUNG, 0.60, 1.0, kept=False))
    for k in range(6):
        t = 2.0 + k / 15
        feed(core, t, view(6, HUNG, 0.60, t, kept=True), view(37, MOVED, 0.62, t, kept=False))
    for r in core.book.records.values():
        r.reach = (OK, OK)
    return core


def test_a_track_left_where_a_moved_fruit_hung_is_not_selected() -> None:
    core = moved_core()
    assert sorted(core.book.records) == [6, 37]  # two records: 5.8 cm is beyond same_fruit_m
    assert select(core) == 37
    assert 6 not in [r.fruit_id for r in core.machine._hidden(3 * S)]  # nor waited for


def test_it_is_a_candidate_again_once_estimated_anew() -> None:
    """A fruit hidden behind leaves (kept views) next to a new track is still that fruit once
    the scene estimates it again: the rule waits for the evidence, it forgets nothing."""
    core = moved_core()
    t = 2.5
    feed(core, t, view(6, HUNG, 0.60, t, kept=False), view(37, MOVED, 0.62, t, kept=False))
    assert select(core) == 6


def test_an_old_track_alone_stays_a_candidate() -> None:
    """Only kept views since 1 s and no other fruit near: a fruit behind leaves, still to do."""
    core = core_with("nearest", view(6, HUNG, 0.60, 0.0, kept=False))
    for k in range(6):
        t = 2.0 + k / 15
        feed(core, t, view(6, HUNG, 0.60, t, kept=True), view(8, (0.7, 0.3, 1.4), 0.7, t, False))
    for r in core.book.records.values():
        r.reach = (OK, OK)
    assert select(core) == 6
