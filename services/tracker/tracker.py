"""The multi-object tracker: Deep SORT's predict → cascade → IoU → birth/death, per frame.

1. Every track is predicted one frame ahead (Kalman).
2. Confirmed tracks are matched to detections by a cascade over the frames since their last
   hit (1, 2, ..., max_age). The cost mixes the cosine distance of the appearance gallery and
   the Mahalanobis distance of the box (normalised by the gate), gated by the chi-square 0.95
   bound, by ``max_cosine_distance`` and, when depth is known, by ``max_depth_jump_m``.
3. Tentative tracks, and confirmed tracks missed for exactly one frame, are matched to what is
   left by IoU (``max_iou_distance`` = 1 - IoU).
4. (Our addition for fruit.) Confirmed tracks still unmatched are matched to what is left by
   containment: intersection over the smaller box (>= ``min_containment``), under the depth
   gate (not the appearance gate: the occluder is inside the box). A fruit that a hand half
   covers shrinks to its visible part and grows back when the hand leaves; neither the
   Mahalanobis gate nor IoU accepts that jump, and Deep SORT would start a new ID for it. A
   detection larger than ``max_containment_growth`` times the largest box the track ever had
   is not taken, in any stage (a hand's box contains the fruit it covers). The track's box
   here is its prediction or its last whole view (see ``_containment_cost``).
   (Ours, cascade and containment) A confirmed track takes a box only within
   ``max_shift_sides`` of its whole box's side from its last matched box and at most
   ``max_depth_step_m`` deeper than its depth: fruit hang still, while the Kalman covariance of
   a coasting track grows without bound (after 10 s its gate spans the image, and one
   sighting does not shrink its velocity part), so the track of a harvested fruit would
   otherwise take the box of another fruit. A box reading *nearer* than that is an occluded
   view (a hand or a leaf in front: its pixels are in the box) and may match, but its depth is
   not averaged into the track's: the fruit did not come nearer, and a track whose depth had
   followed the hand would refuse the fruit's own box when the hand has passed.
5. Unmatched tracks are marked missed; unmatched detections start tentative tracks with IDs
   from this tracker's own counter (1, 2, ...).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from services.tracker.appearance import appearance_distances
from services.tracker.kalman_filter import CHI2INV95, KalmanFilter, xyxy_to_xyah
from services.tracker.linear_assignment import (
    INFTY_COST,
    iou,
    matching_cascade,
    min_cost_matching,
)
from services.tracker.track import Measurement, Track, predict_all, update_all


@dataclass(frozen=True)
class TrackerParams:
    """Deep SORT's hyper-parameters; the defaults are the paper's (§III-B)."""

    max_cosine_distance: float = 0.2
    max_iou_distance: float = 0.5
    max_age: int = 300
    n_init: int = 10
    nn_budget: int = 30
    appearance_weight: float = 0.5
    max_depth_jump_m: float = 0.25
    depth_smoothing: float = 0.3
    min_containment: float = 0.5
    max_containment_growth: float = 1.5
    coast_velocity_decay: float = 0.8
    max_shift_sides: float = 1.0
    max_depth_step_m: float = 0.1


RECENT_FRAMES = 15
"""A confirmed track lost for at most this many frames (1 s at 15 Hz) has first claim on the boxes
inside its last whole view (see ``Tracker._claimed_by_a_fresher_track``)."""


class Tracker:
    """``predict()`` then ``update(measurements)`` once per frame, also with no measurements."""

    def __init__(self, params: TrackerParams | None = None) -> None:
        self.p = params or TrackerParams()
        self.kf = KalmanFilter()
        self.tracks: list[Track] = []
        self._next_id = 1  # per instance: two trackers never share a counter

    def predict(self) -> None:
        predict_all(self.tracks, self.kf, self.p.coast_velocity_decay)

    def update(self, dets: Sequence[Measurement]) -> dict[int, int]:
        """Update with this frame's measurements; returns detection index → track ID."""
        matches, unmatched_tracks, unmatched_dets = self._match(dets)
        update_all(
            [(self.tracks[ti], self._unoccluded(self.tracks[ti], dets[di])) for ti, di in matches],
            self.kf,
        )
        for ti in unmatched_tracks:
            self.tracks[ti].mark_missed()
        assigned = {di: self.tracks[ti].track_id for ti, di in matches}
        for di in unmatched_dets:
            t = Track(
                self._next_id,
                self.kf,
                dets[di],
                self.p.n_init,
                self.p.max_age,
                self.p.nn_budget,
                self.p.depth_smoothing,
            )
            assigned[di] = t.track_id
            self._next_id += 1
            self.tracks.append(t)
        self.tracks = [t for t in self.tracks if not t.deleted]
        return assigned

    def _unoccluded(self, t: Track, m: Measurement) -> Measurement:
        """The measurement without its depth when it reads nearer than the confirmed track by
        more than ``max_depth_step_m``: the depth of whatever is in front of the fruit."""
        if (
            t.confirmed
            and t.depth_m is not None
            and m.depth_m is not None
            and m.depth_m < t.depth_m - self.p.max_depth_step_m
        ):
            return replace(m, depth_m=None)
        return m

    # ---- matching --------------------------------------------------------------------------
    def _gated_cost(self, tis: Sequence[int], dis: Sequence[int], dets: Sequence[Measurement]):
        gate = CHI2INV95[4]
        zs = xyxy_to_xyah(np.stack([dets[d].xyxy_px for d in dis]))
        feats = [dets[d].feature for d in dis]
        depths = np.array([np.nan if dets[d].depth_m is None else dets[d].depth_m for d in dis])
        w = self.p.appearance_weight
        means = np.stack([self.tracks[ti].mean for ti in tis])
        covs = np.stack([self.tracks[ti].cov for ti in tis])
        # Also gated at the fruit's last whole view: a box shrinking behind an occluder drags
        # the prediction away, and the fruit shows again whole where it was.
        whole = means.copy()
        whole[:, :4] = xyxy_to_xyah(np.stack([self.tracks[ti].whole_xyxy for ti in tis]))
        mahas = np.minimum(
            self.kf.gating_distances(means, covs, zs), self.kf.gating_distances(whole, covs, zs)
        )
        app = appearance_distances([self.tracks[ti].gallery for ti in tis], feats)
        cost = np.where(np.isnan(app), mahas / gate, w * app + (1 - w) * mahas / gate)
        bad = mahas > gate
        bad |= np.nan_to_num(app, nan=0.0) > self.p.max_cosine_distance
        bad |= self._depth_jumps(tis, depths)
        bad |= self._far_from_last(tis, zs, depths)
        boxes = np.stack([dets[d].xyxy_px for d in dis])
        bad |= self._grown(tis, boxes)
        bad |= self._claimed_by_a_fresher_track(tis, boxes)
        return np.where(bad, INFTY_COST, cost)

    def _claimed_by_a_fresher_track(self, tis: Sequence[int], boxes: np.ndarray) -> np.ndarray:
        """(T, N) True where a track lost for more than ``RECENT_FRAMES`` would take a box that
        the last whole view of a confirmed track seen within them contains: that fruit's box,
        left to the containment stage. Its own gates may fail while it shows again (a hand
        still half over it spoils its appearance), and a long-lost track (the hand's own,
        coasting where it passed) would otherwise take it in the cascade and keep it."""
        old = np.array([self.tracks[ti].time_since_update > RECENT_FRAMES for ti in tis])
        if not old.any():  # the common case: no long-lost track asks
            return np.zeros((len(tis), len(boxes)), bool)
        claimed = np.zeros(len(boxes), bool)
        recent = [
            t for t in self.tracks if t.confirmed and 0 < t.time_since_update <= RECENT_FRAMES
        ]
        for t in recent:
            claimed |= _contained(t.whole_xyxy, boxes) >= self.p.min_containment
        return old[:, None] & claimed[None, :]

    def _far_from_last(self, tis: Sequence[int], zs: np.ndarray, depths: np.ndarray) -> np.ndarray:
        """(T, N) True where the detection (xyah rows ``zs``) lies farther from the track's last
        matched box than ``max_shift_sides`` times the side of the fruit's whole box (the
        square root of the largest box area the track matched), or reads deeper than the track
        by more than ``max_depth_step_m`` (both known; nearer is an occluder in front). Also
        for a track seen in the last frame: one sighting after a long coast leaves the
        velocity covariance huge, so the next prediction's gate is still wide (paper-exp1: a
        harvested fruit's track, re-acquired on a stray box where the fruit was, took the next
        fruit's box one frame later)."""
        last = np.stack([self.tracks[t].last_xyah for t in tis])  # (T, 4)
        side_px = np.sqrt([self.tracks[t].max_area_px for t in tis])  # the whole fruit's box
        shift_px = np.linalg.norm(zs[None, :, :2] - last[:, None, :2], axis=2)
        far = shift_px > self.p.max_shift_sides * side_px[:, None]
        td = np.array(
            [np.nan if self.tracks[t].depth_m is None else self.tracks[t].depth_m for t in tis]
        )
        with np.errstate(invalid="ignore"):
            deeper = depths[None, :] - td[:, None]
        return far | (np.nan_to_num(deeper, nan=0.0) > self.p.max_depth_step_m)

    def _grown(self, tis: Sequence[int], boxes: np.ndarray) -> np.ndarray:
        """(T, N) True where the box is larger (area) than ``max_containment_growth`` times the
        largest box the track ever matched: a fruit does not grow; a hand over it does."""
        area = np.prod(boxes[:, 2:] - boxes[:, :2], axis=1)
        most = np.array([self.tracks[t].max_area_px for t in tis])
        return area[None, :] > self.p.max_containment_growth * most[:, None]

    def _depth_jumps(self, tis: Sequence[int], depths: np.ndarray) -> np.ndarray:
        """(T, N) True where both depths are known and the detection reads deeper than the
        track by more than the gate (nearer: an occluder in front, see ``_unoccluded``)."""
        td = np.array(
            [np.nan if self.tracks[t].depth_m is None else self.tracks[t].depth_m for t in tis]
        )
        with np.errstate(invalid="ignore"):
            deeper = depths[None, :] - td[:, None]
        return np.nan_to_num(deeper, nan=0.0) > self.p.max_depth_jump_m

    def _iou_cost(self, tis: Sequence[int], dis: Sequence[int], dets: Sequence[Measurement]):
        boxes = np.stack([dets[d].xyxy_px for d in dis])
        cost = np.empty((len(tis), len(dis)))
        for r, ti in enumerate(tis):
            t = self.tracks[ti]
            cost[r] = INFTY_COST if t.time_since_update > 1 else 1.0 - iou(t.xyxy(), boxes)
        confirmed = np.array([self.tracks[ti].confirmed for ti in tis])
        grown = self._grown(tis, boxes) & confirmed[:, None]  # a tentative track has no size yet
        return np.where(grown, INFTY_COST, cost)

    def _containment_cost(
        self, tis: Sequence[int], dis: Sequence[int], dets: Sequence[Measurement]
    ):
        boxes = np.stack([dets[d].xyxy_px for d in dis])
        depths = np.array([np.nan if dets[d].depth_m is None else dets[d].depth_m for d in dis])
        cost = np.empty((len(tis), len(dis)))
        for r, ti in enumerate(tis):
            t = self.tracks[ti]
            # The predicted box, or the fruit's last whole view: a box that shrank behind an
            # occluder taught the Kalman filter to shrink it further while it coasts, and the
            # fruit reappears on the side the occluder leaves, outside the shrunk prediction.
            cost[r] = 1.0 - np.maximum(_contained(t.xyxy(), boxes), _contained(t.whole_xyxy, boxes))
        bad = self._depth_jumps(tis, depths) | self._far_from_last(tis, xyxy_to_xyah(boxes), depths)
        bad |= self._grown(tis, boxes)
        return np.where(bad, INFTY_COST, cost)

    def _match(self, dets: Sequence[Measurement]):
        confirmed = [i for i, t in enumerate(self.tracks) if t.confirmed]
        unconfirmed = [i for i, t in enumerate(self.tracks) if not t.confirmed]
        all_dets = list(range(len(dets)))
        m_a, um_a, ud = matching_cascade(
            lambda ti, di: self._gated_cost(ti, di, dets),
            1.0,
            self.p.max_age,
            confirmed,
            all_dets,
            lambda i: self.tracks[i].time_since_update,
        )
        iou_candidates = unconfirmed + [i for i in um_a if self.tracks[i].time_since_update == 1]
        um_a = [i for i in um_a if self.tracks[i].time_since_update != 1]
        m_b, um_b, ud = min_cost_matching(
            lambda ti, di: self._iou_cost(ti, di, dets),
            self.p.max_iou_distance,
            iou_candidates,
            ud,
        )
        left = sorted(set(um_a + um_b))
        m_c, _, ud = min_cost_matching(
            lambda ti, di: self._containment_cost(ti, di, dets),
            1.0 - self.p.min_containment,
            [i for i in left if self.tracks[i].confirmed],
            ud,
        )
        matched_c = {ti for ti, _ in m_c}
        return m_a + m_b + m_c, [i for i in left if i not in matched_c], ud


def _contained(box: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """(N,) intersection of ``box`` with each of ``boxes`` over the smaller of the two areas."""
    lt = np.maximum(box[:2], boxes[:, :2])
    rb = np.minimum(box[2:], boxes[:, 2:])
    inter = np.prod(np.clip(rb - lt, 0, None), axis=1)
    area = np.prod(boxes[:, 2:] - boxes[:, :2], axis=1)
    own = max(float(np.prod(box[2:] - box[:2])), 1e-6)
    return inter / np.maximum(np.minimum(area, own), 1e-6)
