"""Tracks made from the sim's ground truth: a perfect detector and tracker, for evaluating the
scene estimator on localisation alone (``harvest eval scene``) and for its tests.

Every attached fruit whose visible share of pixels is at least ``min_visible`` becomes a
confirmed, matched track with ID = sim fruit index + 1 (track IDs start at 1) and the box of its
*visible* pixels (what a detector trained on visible boxes reports; the box is cut where a leaf
or a hand hides the fruit). ``box_noise_px`` > 0 moves each box edge by seeded Gaussian noise
of that standard deviation: a detector's boxes are not pixel-exact.
"""

from __future__ import annotations

import numpy as np

from schemas.base import Header
from schemas.perception import Track, Tracks
from schemas.sim import GroundTruth


class TruthTracks:
    """Turns sim/truth messages into perception/tracks messages (one per truth message)."""

    def __init__(
        self,
        min_visible: float = 0.5,
        box_noise_px: float = 0.0,
        seed: int = 0,
        source: str = "truth_tracks",
    ) -> None:
        if not 0.0 < min_visible <= 1.0:
            raise ValueError(f"min_visible must be in (0, 1], got {min_visible}")
        if not box_noise_px >= 0.0:
            raise ValueError(f"box_noise_px must be >= 0, got {box_noise_px}")
        self.min_visible, self.box_noise_px, self.seed = min_visible, box_noise_px, seed
        self.source = source
        self.first_frame: dict[int, int] = {}
        self.last_seen: dict[int, int] = {}
        self.seq = 0

    def __call__(self, truth: GroundTruth) -> Tracks:
        k = truth.frame_seq
        rng = np.random.default_rng([self.seed, k])
        tracks = []
        for f in truth.fruits:
            if f.state != "attached" or f.box_xyxy_px is None:
                continue
            if f.visible_fraction < self.min_visible:
                continue
            tid = f.fruit_id + 1
            self.first_frame.setdefault(tid, k)
            self.last_seen[tid] = k
            tracks.append(
                Track(
                    track_id=tid,
                    xyxy_px=self._noisy(f.box_xyxy_px, rng),
                    score=1.0,
                    confirmed=True,
                    age_frames=k - self.first_frame[tid],
                    frames_since_update=0,
                    matched=True,
                )
            )
        h = Header(
            stamp_ns=truth.header.stamp_ns,
            seq=self.seq,
            frame_id="camera_optical",
            source=self.source,
            answers_seq=truth.header.seq,
        )
        self.seq += 1
        return Tracks(header=h, frame_seq=k, tracks=tuple(tracks))

    def _noisy(
        self, box: tuple[float, float, float, float], rng: np.random.Generator
    ) -> tuple[float, float, float, float]:
        if self.box_noise_px == 0:
            return box
        x1, y1, x2, y2 = (float(v) for v in np.asarray(box) + rng.normal(0, self.box_noise_px, 4))
        # Keep the box at least 2 px wide and tall, edges in order.
        cx, cy = (x1 + x2) / 2, (y1 + y2) / 2
        hw, hh = max((x2 - x1) / 2, 1.0), max((y2 - y1) / 2, 1.0)
        return (cx - hw, cy - hh, cx + hw, cy + hh)
