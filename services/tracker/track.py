"""One track: Kalman state, life cycle (tentative → confirmed → deleted), gallery and depth."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum

import numpy as np

from services.tracker.appearance import Gallery
from services.tracker.kalman_filter import KalmanFilter, xyxy_to_xyah

WHOLE_VIEW_SHARE = 0.8
"""A box of at least this share of the largest box a track matched is a whole view of the fruit
(not its part left visible beside an occluder)."""


class TrackState(Enum):
    TENTATIVE = 1
    CONFIRMED = 2
    DELETED = 3


@dataclass(frozen=True)
class Measurement:
    """A detection as the tracker uses it: box (px), score, descriptor and depth when known."""

    xyxy_px: np.ndarray
    score: float
    feature: np.ndarray | None = None
    depth_m: float | None = None


class Track:
    """A tracked fruit. Tentative until ``n_init`` consecutive hits; a tentative track missed
    once is deleted; a confirmed one after more than ``max_age`` frames without a hit."""

    def __init__(
        self,
        track_id: int,
        kf: KalmanFilter,
        m: Measurement,
        n_init: int,
        max_age: int,
        nn_budget: int,
        depth_smoothing: float,
    ) -> None:
        self.track_id = track_id
        self.mean, self.cov = kf.initiate(xyxy_to_xyah(m.xyxy_px))
        self.hits = 1
        self.age = 0
        self.time_since_update = 0
        self.state = TrackState.TENTATIVE if n_init > 1 else TrackState.CONFIRMED
        self.gallery = Gallery(nn_budget)
        self.gallery.add(m.feature)
        self.score = m.score
        self.depth_m = m.depth_m
        self.max_area_px = _area(m.xyxy_px)  # the largest box matched: the fruit's whole size
        self.last_xyah = xyxy_to_xyah(m.xyxy_px)  # the last box matched, not the prediction
        self.whole_xyxy = np.asarray(m.xyxy_px, float)  # the last whole view (see update)
        self._n_init, self._max_age, self._alpha = n_init, max_age, depth_smoothing

    @property
    def confirmed(self) -> bool:
        return self.state is TrackState.CONFIRMED

    @property
    def deleted(self) -> bool:
        return self.state is TrackState.DELETED

    def xyxy(self) -> np.ndarray:
        return np.array(self.xyxy_floats())

    def xyxy_floats(self) -> tuple[float, float, float, float]:
        """The predicted box, (x1, y1, x2, y2) px: ``xyah_to_xyxy`` in plain floats (the same
        IEEE operations, without numpy's per-call cost on a 4-vector)."""
        cx, cy, a, h = self.mean[:4].tolist()
        hw, hh = a * h / 2, h / 2
        return cx - hw, cy - hh, cx + hw, cy + hh

    def predict(self, kf: KalmanFilter, coast_velocity_decay: float = 1.0) -> None:
        """One frame ahead (``predict_all`` for many tracks at once)."""
        predict_all([self], kf, coast_velocity_decay)

    def update(self, kf: KalmanFilter, m: Measurement) -> None:
        """Correct with a matched measurement (``update_all`` for many tracks at once)."""
        update_all([(self, m)], kf)

    def _absorb(self, m: Measurement, z: np.ndarray) -> None:
        """Everything but the Kalman correction: gallery, size, whole view, depth, life cycle."""
        self.gallery.add(m.feature)
        self.score = m.score
        self.max_area_px = max(self.max_area_px, _area(m.xyxy_px))
        self.last_xyah = z
        box = np.asarray(m.xyxy_px, float)
        if _area(box) >= WHOLE_VIEW_SHARE * self.max_area_px:
            self.whole_xyxy = box
        else:  # a part of the fruit: it lies inside the whole fruit, wherever that went
            self.whole_xyxy = _shifted_over(self.whole_xyxy, box)
        if m.depth_m is not None:
            # Depth from one box is noisy (leaf edges, fruit rim): smooth it.
            self.depth_m = (
                m.depth_m
                if self.depth_m is None
                else (1 - self._alpha) * self.depth_m + self._alpha * m.depth_m
            )
        self.hits += 1
        self.time_since_update = 0
        if self.state is TrackState.TENTATIVE and self.hits >= self._n_init:
            self.state = TrackState.CONFIRMED

    def mark_missed(self) -> None:
        if self.state is TrackState.TENTATIVE or self.time_since_update > self._max_age:
            self.state = TrackState.DELETED


def predict_all(tracks: Sequence[Track], kf: KalmanFilter, coast_velocity_decay: float) -> None:
    """Every track one frame ahead, in one batched Kalman step. While a track coasts (missed
    last frame), its velocity decays: fruit hang still, and a velocity learnt from a box
    shrinking behind an occluder would otherwise carry the prediction away during a long
    occlusion."""
    if not tracks:
        return
    means = np.stack([t.mean for t in tracks])
    coasting = np.array([t.time_since_update > 0 for t in tracks])
    means[coasting, 4:] *= coast_velocity_decay
    means, covs = kf.predict_many(means, np.stack([t.cov for t in tracks]))
    for t, mean, cov in zip(tracks, means, covs, strict=True):
        t.mean, t.cov = mean, cov
        t.age += 1
        t.time_since_update += 1


def update_all(pairs: Sequence[tuple[Track, Measurement]], kf: KalmanFilter) -> None:
    """Every matched track corrected by its measurement, in one batched Kalman step."""
    if not pairs:
        return
    zs = xyxy_to_xyah(np.stack([m.xyxy_px for _, m in pairs]))
    means = np.stack([t.mean for t, _ in pairs])
    covs = np.stack([t.cov for t, _ in pairs])
    means, covs = kf.update_many(means, covs, zs)
    for (t, m), mean, cov, z in zip(pairs, means, covs, zs, strict=True):
        t.mean, t.cov = mean, cov
        t._absorb(m, z)


def _area(xyxy: np.ndarray) -> float:
    return float(max(xyxy[2] - xyxy[0], 0.0) * max(xyxy[3] - xyxy[1], 0.0))


def _shifted_over(whole: np.ndarray, part: np.ndarray) -> np.ndarray:
    """The whole view moved the least that puts the part of the fruit seen inside it (centred
    on the part along an axis where the part is the longer): a part seen outside the whole view
    means the fruit moved (a hand pushed it) while a leaf or the hand hides some of it."""
    out = whole.copy()
    for lo, hi in ((0, 2), (1, 3)):
        if part[hi] - part[lo] >= whole[hi] - whole[lo]:
            shift = (part[lo] + part[hi] - whole[lo] - whole[hi]) / 2
        else:
            shift = min(part[lo] - whole[lo], 0.0) + max(part[hi] - whole[hi], 0.0)
        out[lo] += shift
        out[hi] += shift
    return out
