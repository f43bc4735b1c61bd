"""Tracker: Kalman gating, life cycle, per-instance IDs, occlusion handling, cascade order."""

from __future__ import annotations

import numpy as np

from services.tracker.kalman_filter import CHI2INV95, KalmanFilter, xyah_to_xyxy, xyxy_to_xyah
from services.tracker.linear_assignment import matching_cascade, min_cost_matching
from services.tracker.track import Measurement
from services.tracker.tracker import Tracker, TrackerParams

BOX_A = np.array([100.0, 100.0, 140.0, 140.0])
BOX_B = np.array([300.0, 200.0, 350.0, 250.0])


def m(box: np.ndarray, depth: float | None = None, feature: np.ndarray | None = None):
    return Measurement(np.asarray(box, float), 0.9, feature, depth)


def step(tr: Tracker, boxes: list[np.ndarray], depths: list[float | None] | None = None):
    tr.predict()
    depths = depths or [None] * len(boxes)
    return tr.update([m(b, d) for b, d in zip(boxes, depths, strict=True)])


def test_box_conversions_round_trip() -> None:
    np.testing.assert_allclose(xyah_to_xyxy(xyxy_to_xyah(BOX_B)), BOX_B)


def test_gate_accepts_the_predicted_box_and_rejects_a_far_one() -> None:
    kf = KalmanFilter()
    mean, cov = kf.initiate(xyxy_to_xyah(BOX_A))
    mean, cov = kf.predict(mean, cov)
    d = kf.gating_distance(mean, cov, xyxy_to_xyah(np.stack([BOX_A, BOX_B])))
    assert d[0] < 1.0 < CHI2INV95[4] < d[1]


def test_track_is_confirmed_after_n_init_hits_and_ids_are_per_instance() -> None:
    a, b = Tracker(TrackerParams(n_init=3)), Tracker(TrackerParams(n_init=3))
    for k in range(3):
        ids = step(a, [BOX_A, BOX_B])
        assert [t.confirmed for t in a.tracks] == [k == 2] * 2
    assert ids == {0: 1, 1: 2}
    assert step(b, [BOX_B]) == {0: 1}  # a second tracker counts from 1 on its own


def test_tentative_track_is_deleted_after_one_miss() -> None:
    tr = Tracker(TrackerParams(n_init=3))
    step(tr, [BOX_A])
    step(tr, [])
    assert tr.tracks == []
    assert step(tr, [BOX_A]) == {0: 2}  # a new track, a new ID


def test_track_id_survives_full_occlusion() -> None:
    tr = Tracker(TrackerParams(n_init=3))
    for _ in range(5):
        step(tr, [BOX_A, BOX_B])
    for _ in range(100):  # fully hidden for 100 frames (6.7 s at 15 Hz)
        step(tr, [BOX_B])
    assert step(tr, [BOX_A, BOX_B]) == {0: 1, 1: 2}


def test_confirmed_track_is_deleted_after_max_age() -> None:
    tr = Tracker(TrackerParams(n_init=2, max_age=5))
    for _ in range(3):
        step(tr, [BOX_A])
    for _ in range(6):
        step(tr, [])
    assert tr.tracks == []


def test_fruit_growing_back_out_of_a_partial_occlusion_keeps_its_id() -> None:
    tr = Tracker(TrackerParams(n_init=2))
    full = np.array([100.0, 100.0, 160.0, 160.0])
    for _ in range(5):
        step(tr, [full], [0.7])
    sliver = np.array([110.0, 150.0, 140.0, 160.0])  # a hand covers all but the bottom
    for _ in range(8):
        step(tr, [sliver], [0.7])
    assert step(tr, [full], [0.7]) == {0: 1}


def test_depth_gate_refuses_a_fruit_at_another_depth() -> None:
    tr = Tracker(TrackerParams(n_init=2))
    for _ in range(5):
        step(tr, [BOX_A], [0.6])
    for _ in range(3):
        step(tr, [], [])
    # Same place in the image, 0.5 m further back: another fruit, not the hidden one.
    assert step(tr, [BOX_A], [1.1]) == {0: 2}


def test_a_hand_in_front_of_a_fruit_neither_takes_nor_moves_its_depth() -> None:
    # The sim's occlusion suite: the box of a fruit 0.81 m deep reads the hand's 0.47 m for the
    # frames the hand enters it. That view is the fruit's (same box) but not its depth; a track
    # whose depth had followed the hand refused the fruit's own box after it (a new ID).
    tr = Tracker(TrackerParams(n_init=2))
    for _ in range(5):
        step(tr, [BOX_A], [0.81])
    for _ in range(3):
        assert step(tr, [BOX_A], [0.47]) == {0: 1}
    assert tr.tracks[0].depth_m is not None and abs(tr.tracks[0].depth_m - 0.81) < 1e-9
    assert step(tr, [BOX_A], [0.815]) == {0: 1}


def test_a_fruit_shrunk_behind_a_passing_hand_keeps_its_id_when_it_shows_on_the_other_side() -> (
    None
):
    # The sim's occlusion suite: a hand passes right to left over a fruit. Its visible part
    # shrinks towards the left edge (the Kalman filter learns a shrinking box and, coasting,
    # shrinks it to a few pixels), then the fruit shows again from the right, outside that
    # shrunk prediction. Its last whole view still contains the new box: the same fruit.
    tr = Tracker(TrackerParams(n_init=3))
    whole = np.array([500.0, 150.0, 572.0, 214.0])
    for _ in range(5):
        assert step(tr, [whole]) == {0: 1}
    for right in (560.0, 545.0, 530.0, 518.0):  # the hand covers it from the right
        assert step(tr, [np.array([500.0, 155.0, right, 205.0])]) == {0: 1}
    for _ in range(5):
        step(tr, [])
    assert step(tr, [np.array([520.0, 150.0, 572.0, 212.0])]) == {0: 1}


def test_a_box_much_larger_than_the_fruit_ever_was_is_not_the_fruit_in_any_stage() -> None:
    # A hand sweeping over a fruit: its box (1.9x the fruit's area, about the same centre) is
    # inside the Kalman gate of the fruit's track; the fruit does not grow, so it is not it.
    tr = Tracker(TrackerParams(n_init=3))
    for _ in range(5):
        step(tr, [BOX_A])
    hand = np.array([92.0, 92.0, 147.0, 147.0])
    assert step(tr, [hand]) == {0: 2}
    assert step(tr, [BOX_A]) == {0: 1}


def test_a_fruit_showing_again_is_not_taken_by_the_long_lost_track_of_the_hand_beside_it() -> None:
    # A hand (its own confirmed track) passed the fruit and was lost beside it 20 frames ago.
    # The fruit, hidden for 4 frames, shows again with the hand still half over it: its box
    # looks like the hand (its own appearance gate refuses it), and the hand's long-lost track
    # would take it in the cascade. The fruit's whole view contains the box: the fruit's.
    from services.tracker.appearance import DESCRIPTOR_DIM

    fruit_f, hand_f = np.zeros(DESCRIPTOR_DIM), np.zeros(DESCRIPTOR_DIM)
    fruit_f[0] = hand_f[1] = 1.0
    hand = np.array([130.0, 60.0, 210.0, 140.0])
    tr = Tracker(TrackerParams(n_init=3))
    for _ in range(5):
        tr.predict()
        tr.update([m(BOX_A, feature=fruit_f), m(hand, feature=hand_f)])
    for _ in range(20):
        tr.predict()
        tr.update([m(BOX_A, feature=fruit_f)])
    for _ in range(4):
        tr.predict()
        tr.update([])
    tr.predict()
    assert tr.update([m(BOX_A, feature=hand_f)]) == {0: 1}


def test_a_fruit_moved_while_partly_hidden_is_still_claimed_where_it_went() -> None:
    # The sim's occlusion suite: a hand pushes a fruit 4 cm; where it goes a leaf hides a
    # quarter of it, so no box of it is a whole view again. Later the hand passes over it and
    # it shows again with the hand half over it (its appearance gate refuses the box), beside
    # the hand's long-lost track. Its whole view must have followed it to claim the box.
    from services.tracker.appearance import DESCRIPTOR_DIM

    fruit_f, hand_f = np.zeros(DESCRIPTOR_DIM), np.zeros(DESCRIPTOR_DIM)
    fruit_f[0] = hand_f[1] = 1.0
    hand = np.array([40.0, 60.0, 120.0, 140.0])
    tr = Tracker(TrackerParams(n_init=3))
    whole = np.array([140.0, 110.0, 220.0, 185.0])  # 80 x 75 px
    for _ in range(5):
        tr.predict()
        tr.update([m(whole, feature=fruit_f), m(hand, feature=hand_f)])
    part = np.array([140.0, 110.0, 198.0, 184.0])  # 58 x 74 px: 0.72 of its area
    for dx in range(0, 45, 3):  # pushed left, a leaf over its right quarter
        tr.predict()
        assert tr.update([m(part - [dx, dx / 2, dx, dx / 2], feature=fruit_f)]) == {0: 1}
    there = part - [42.0, 21.0, 42.0, 21.0]
    for _ in range(20):
        tr.predict()
        assert tr.update([m(there, feature=fruit_f)]) == {0: 1}
    for _ in range(4):
        tr.predict()
        tr.update([])
    tr.predict()
    assert tr.update([m(there, feature=hand_f)]) == {0: 1}


def test_min_cost_matching_leaves_costly_pairs_unmatched() -> None:
    cost = np.array([[0.1, 0.9], [0.8, 0.95]])
    matches, ut, ud = min_cost_matching(lambda t, d: cost[np.ix_(t, d)], 0.5, [0, 1], [0, 1])
    assert matches == [(0, 0)] and ut == [1] and ud == [1]


def test_cascade_gives_a_detection_to_the_most_recently_seen_track() -> None:
    cost = np.array([[0.3], [0.1]])  # the older track (1) is even the cheaper one
    tsu = {0: 1, 1: 5}
    matches, unmatched, _ = matching_cascade(
        lambda t, d: cost[np.ix_(t, d)], 0.5, 300, [0, 1], [0], tsu.__getitem__
    )
    assert matches == [(0, 0)] and unmatched == [1]


def test_a_hand_covering_a_fruit_does_not_take_its_id() -> None:
    # The detector fires on the hand: its box (~4x the fruit's area) contains the fruit's box.
    # Containment must not hand the fruit's ID to it; the fruit keeps its ID when it reappears.
    tr = Tracker(TrackerParams(n_init=3))
    for _ in range(5):
        step(tr, [BOX_A])
    hand = np.array([80.0, 80.0, 160.0, 160.0])
    for _ in range(3):
        ids = step(tr, [hand])
        assert ids[0] != 1  # a new (tentative) track, not fruit 1
    assert step(tr, [BOX_A]) == {0: 1}


def test_the_track_of_a_harvested_fruit_does_not_take_another_fruits_box() -> None:
    # Fruit A (40 px box, 0.58 m) is tracked, then harvested: its track coasts. 6 s later a
    # fruit that was hidden by leaves shows 1.75 box heights away and 0.24 m deeper: inside the
    # depth gate, and inside the Kalman gate of a track that coasted that long. Paper-exp1 had
    # this: the harvested fruit's ID went to the next fruit, which the planner took for done.
    tr = Tracker(TrackerParams(n_init=3))
    for _ in range(5):
        step(tr, [BOX_A], [0.58])
    for _ in range(90):
        step(tr, [])
    other = BOX_A + np.array([70.0, 0.0, 70.0, 0.0])
    assert step(tr, [other], [0.82]) == {0: 2}


def test_a_track_seen_once_after_a_long_coast_does_not_jump_to_another_fruit_next() -> None:
    # One stray box where the harvested fruit was re-acquires its track; its velocity is still
    # uncertain, so the Kalman gate of the next frame is wide: the other fruit's box must not
    # be taken (1.75 box sides away, 0.15 m deeper: inside the depth gate).
    tr = Tracker(TrackerParams(n_init=3))
    for _ in range(5):
        step(tr, [BOX_A], [0.6])
    for _ in range(90):
        step(tr, [])
    assert step(tr, [BOX_A], [0.6]) == {0: 1}
    other = BOX_A + np.array([70.0, 0.0, 70.0, 0.0])
    assert step(tr, [other], [0.75]) == {0: 2}


def test_a_fruit_hidden_for_long_keeps_its_id_when_it_shows_again_nearly_in_place() -> None:
    tr = Tracker(TrackerParams(n_init=3))
    for _ in range(5):
        step(tr, [BOX_A], [0.6])
    for _ in range(90):
        step(tr, [])
    # Half a box height off (a leaf still covers its top), 3 cm deeper: the same fruit.
    assert step(tr, [BOX_A + np.array([0.0, 20.0, 0.0, 0.0])], [0.63]) == {0: 1}


def test_batched_kalman_steps_equal_the_per_track_textbook_steps_to_the_bit() -> None:
    # The batched predict/update replace 30 tracks' worth of per-track numpy calls; the
    # tracker's outputs (and so every harvest run) must not move by a bit.
    kf = KalmanFilter()
    rng = np.random.default_rng(3)
    means = np.c_[rng.uniform(50, 600, (7, 2)), rng.uniform(0.6, 1.4, 7), rng.uniform(10, 90, 7)]
    means = np.c_[means, rng.normal(0, 2, (7, 4))]
    a = rng.normal(0, 1, (7, 8, 8))
    covs = a @ a.transpose(0, 2, 1) + np.eye(8)
    zs = means[:, :4] + rng.normal(0, 3, (7, 4))
    pm, pc = kf.predict_many(means, covs)
    um, uc = kf.update_many(means, covs, zs)
    F, H = kf._F, kf._H
    for i in range(7):
        h = means[i, 3]
        wp, wv = kf._wp * h, kf._wv * h
        q = np.diag(np.square([wp, wp, 1e-2, wp, wv, wv, 1e-5, wv]))
        assert np.array_equal(pm[i], F @ means[i])
        assert np.array_equal(pc[i], F @ covs[i] @ F.T + q)
        s = H @ covs[i] @ H.T + np.diag(np.square([wp, wp, 1e-1, wp]))
        gain = np.linalg.solve(s, (covs[i] @ H.T).T).T
        np.testing.assert_allclose(um[i], means[i] + gain @ (zs[i] - H @ means[i]), rtol=1e-12)
        np.testing.assert_allclose(uc[i], covs[i] - gain @ s @ gain.T, rtol=1e-9, atol=1e-9)
