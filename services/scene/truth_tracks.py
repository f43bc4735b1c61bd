"""Tracks made from the sim's ground truth: a perfect detector and tracker, for evaluating the
scene estimator on localisation alone (``harvest eval scene``) and for its tests.

Every attached fruit whose visible share of pixels is at least ``min_visible`` becomes a
confirmed, matched track with ID = sim fruit index + 1 (track IDs start at 1) and the box of its
*visible* pixels (what a detector trained on visible boxes reports; the box is cut where a leaf
or a hand hides the fruit).
"""

from __future__ import annotations

from schemas.base import Header
from schemas.perception import Track, Tracks
from schemas.sim import GroundTruth


class TruthTracks:
    """Turns sim/truth messages into perception/tracks messages (one per truth message)."""

    def __init__(self, min_visible: float = 0.5, source: str = "truth_tracks") -> None:
        if not 0.0 < min_visible <= 1.0:
            raise ValueError(f"min_visible must be in (0, 1], got {min_visible}")
        self.min_visible = min_visible
        self.source = source
        self.first_frame: dict[int, int] = {}
        self.last_seen: dict[int, int] = {}
        self.seq = 0

    def __call__(self, truth: GroundTruth) -> Tracks:
        k = truth.frame_seq
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
                    xyxy_px=f.box_xyxy_px,
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
