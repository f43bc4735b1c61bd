"""Tracks from the sim's truth: which fruit become tracks, their IDs and boxes, seeded noise."""

from __future__ import annotations

from schemas.base import Header
from schemas.sim import FruitTruth, GroundTruth, TrunkTruth
from services.scene.truth_tracks import TruthTracks


def truth(frame_seq: int) -> GroundTruth:
    def fruit(i: int, vf: float, state: str = "attached") -> FruitTruth:
        box = (100.0 + 50 * i, 100.0, 140.0 + 50 * i, 138.0) if vf > 0 else None
        return FruitTruth(
            fruit_id=i,
            position_world_m=(0.6, 0.0, 1.3),
            orientation_xyzw=(0, 0, 0, 1),
            semi_axes_m=(0.04, 0.04, 0.038),
            peduncle_world_m=(0.6, 0.0, 1.34),
            visible_fraction=vf,
            box_xyxy_px=box,
            state=state,  # type: ignore[arg-type]
        )

    return GroundTruth(
        header=Header(stamp_ns=frame_seq * 10, seq=frame_seq, source="sim"),
        frame_seq=frame_seq,
        fruits=(fruit(0, 0.9), fruit(1, 0.3), fruit(2, 0.0), fruit(3, 1.0, "falling")),
        trunk=TrunkTruth(axis_point_world_m=(1.2, 0.0, 0.0), radius_m=0.06),
    )


def test_visible_attached_fruit_become_confirmed_tracks_with_id_plus_one() -> None:
    t = TruthTracks(min_visible=0.5)(truth(3))
    assert [tr.track_id for tr in t.tracks] == [1]
    tr = t.tracks[0]
    assert tr.xyxy_px == (100.0, 100.0, 140.0, 138.0) and tr.confirmed and tr.matched
    assert t.frame_seq == 3 and t.header.stamp_ns == 30 and t.header.answers_seq == 3
    assert [x.track_id for x in TruthTracks(min_visible=0.25)(truth(3)).tracks] == [1, 2]


def test_box_noise_is_seeded_per_frame() -> None:
    a, b = TruthTracks(box_noise_px=2.0, seed=1), TruthTracks(box_noise_px=2.0, seed=1)
    boxes_a = [a(truth(k)).tracks[0].xyxy_px for k in range(3)]
    boxes_b = [b(truth(k)).tracks[0].xyxy_px for k in range(3)]
    assert boxes_a == boxes_b
    assert len(set(boxes_a)) == 3 and boxes_a[0] != (100.0, 100.0, 140.0, 138.0)
