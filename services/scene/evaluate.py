"""Evaluation of the scene estimator against the sim's ground truth (``harvest eval scene``).

The sim core runs in-process on a scenario and a range of seeds, D435-like depth noise on, the
robot still in its ready posture. Each camera frame goes to the scene core with Tracks made from
the truth's visible boxes (``truth_tracks.py``: a perfect detector and tracker), so the figures
measure localisation alone. Compared with sim/truth of the same frame:

* fruit centre error (3D, world frame), |d_v - truth vertical semi-axis| and |d_h - truth
  horizontal semi-axis|, for every fruit measured in that frame (``frames_unseen == 0``, no
  failure flag) whose true centre is ``range_m`` (0.4-1.0 m) from the camera's optical centre;
* the bias along the camera ray: the estimate's distance from the optical centre minus the
  truth's (negative: nearer the camera), and d_h's signed error, split into fruit at least
  ``VISIBLE_SHARE`` visible and fruit partly hidden (a cut box is where a bias comes from: a
  fit that takes a cut side for the silhouette makes the fruit smaller, and so nearer);
* the trunk: horizontal distance between the estimated axis and the true one, every frame the
  trunk is found; and the share of frames it is found.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from schemas.scene import SceneState
from schemas.sim import GroundTruth
from services.scene import Settings
from services.scene.truth_tracks import TruthTracks

FAILURE_FLAGS = ("box_invalid", "depth_invalid", "depth_inconsistent")
VISIBLE_SHARE = 0.9  # a fruit at least this visible counts as whole for the bias split


@dataclass
class SeedResult:
    scenario: str
    seed: int
    frames: int = 0
    centre_err_m: list[float] = field(default_factory=list)
    dv_err_m: list[float] = field(default_factory=list)
    dh_err_m: list[float] = field(default_factory=list)
    # (signed range error m, signed d_h error m, visible fraction) per scored estimate
    signed_m: list[tuple[float, float, float]] = field(default_factory=list)
    in_range_tracks: int = 0  # tracks given for fruit in range
    failed: int = 0  # of those, frames with no estimate (failure flag or not in the list)
    trunk_err_m: list[float] = field(default_factory=list)
    trunk_found: int = 0
    flags: Counter[str] = field(default_factory=Counter)
    core_ms: list[float] = field(default_factory=list)
    counters: Counter[str] = field(default_factory=Counter)


def evaluate_seed(
    scenario: str,
    seed: int,
    seconds: float,
    settings: Settings,
    min_visible: float = 0.5,
    range_m: tuple[float, float] = (0.4, 1.0),
    on_frame: Callable[[], None] | None = None,
    box_noise_px: float = 0.0,
) -> SeedResult:
    """Run one seed of ``scenario`` for ``seconds`` of sim time and score every frame."""
    from services.runtime.settings import load_settings
    from services.scene.core import SceneCore
    from services.sim import Settings as SimSettings
    from services.sim.core import SimCore

    sim = SimCore(
        load_settings(  # type: ignore[arg-type]
            SimSettings,
            {"scenario": scenario, "seed": seed, "depth_noise": True, "duration_s": seconds},
            service="sim",
        )
    )
    core = SceneCore(settings)
    oracle = TruthTracks(min_visible, box_noise_px, seed)
    res = SeedResult(scenario, seed)
    try:
        while not sim.done():
            for group in sim.emit():
                topics = dict(group)
                if "camera/rgbd" not in topics:
                    continue
                truth: GroundTruth = topics["sim/truth"]
                t0 = time.perf_counter()
                core.handle("camera/rgbd", topics["camera/rgbd"])
                tracks = oracle(truth)
                ((_, state),) = core.handle("perception/tracks", tracks)
                res.core_ms.append((time.perf_counter() - t0) * 1e3)
                cam = np.asarray(topics["camera/rgbd"].meta.T_world_camera.position_m)
                _score(res, state, truth, {t.track_id for t in tracks.tracks}, cam, range_m)
                if on_frame:
                    on_frame()
            sim.advance()
    finally:
        sim.close()
    res.counters = Counter(core.counters)
    return res


def _score(
    res: SeedResult,
    state: SceneState,
    truth: GroundTruth,
    tracked: set[int],
    cam: np.ndarray,
    range_m: tuple[float, float],
) -> None:
    res.frames += 1
    by_id = {f.fruit_id: f for f in state.fruits}
    for ft in truth.fruits:
        tid = ft.fruit_id + 1
        if tid not in tracked:
            continue
        p_true = np.asarray(ft.position_world_m)
        if not range_m[0] <= float(np.linalg.norm(p_true - cam)) <= range_m[1]:
            continue
        res.in_range_tracks += 1
        est = by_id.get(tid)
        if est is None or est.frames_unseen > 0 or any(f in FAILURE_FLAGS for f in est.flags):
            res.failed += 1
            continue
        res.flags.update(est.flags)
        res.centre_err_m.append(float(np.linalg.norm(np.asarray(est.position_world_m) - p_true)))
        res.dv_err_m.append(abs(est.semi_axis_v_m - ft.semi_axes_m[2]))
        res.dh_err_m.append(abs(est.semi_axis_h_m - ft.semi_axes_m[0]))
        p_est = np.asarray(est.position_world_m)
        range_err = float(np.linalg.norm(p_est - cam) - np.linalg.norm(p_true - cam))
        res.signed_m.append((range_err, est.semi_axis_h_m - ft.semi_axes_m[0], ft.visible_fraction))
    t = state.trunk
    if t.found and t.position_world_m is not None:
        res.trunk_found += 1
        ax = truth.trunk.axis_point_world_m
        res.trunk_err_m.append(
            float(np.hypot(t.position_world_m[0] - ax[0], t.position_world_m[1] - ax[1]))
        )


def summary(results: list[SeedResult], settings: Settings, **meta: Any) -> dict[str, Any]:
    """Pooled figures over all seeds (the --json object) plus one row per seed."""
    c = [v for r in results for v in r.centre_err_m]
    dv = [v for r in results for v in r.dv_err_m]
    dh = [v for r in results for v in r.dh_err_m]
    tr = [v for r in results for v in r.trunk_err_m]
    frames = sum(r.frames for r in results)
    tracks = sum(r.in_range_tracks for r in results)
    flags: Counter[str] = Counter()
    counters: Counter[str] = Counter()
    for r in results:
        flags.update(r.flags)
        counters.update(r.counters)
    return {
        **meta,
        "fruit_method": settings.fruit_method,
        "trunk_method": settings.trunk_method,
        "frames": frames,
        "fruit_estimates": len(c),
        "in_range_tracks": tracks,
        "estimate_share": len(c) / tracks if tracks else None,
        "center_err_median_m": _q(c, 50),
        "center_err_p95_m": _q(c, 95),
        "center_err_max_m": max(c) if c else None,
        "dv_err_median_m": _q(dv, 50),
        "dv_err_p95_m": _q(dv, 95),
        "dh_err_median_m": _q(dh, 50),
        **_biases([v for r in results for v in r.signed_m]),
        "trunk_err_m": _q(tr, 50),
        "trunk_err_p95_m": _q(tr, 95),
        "trunk_found_share": len(tr) / frames if frames else None,
        "core_ms_median": _q([v for r in results for v in r.core_ms], 50),
        "flags": dict(sorted(flags.items())),
        "core_counters": dict(sorted(counters.items())),
        "per_seed": [
            {
                "seed": r.seed,
                "frames": r.frames,
                "fruit_estimates": len(r.centre_err_m),
                "center_err_median_m": _q(r.centre_err_m, 50),
                "center_err_p95_m": _q(r.centre_err_m, 95),
                "dv_err_median_m": _q(r.dv_err_m, 50),
                "trunk_err_m": _q(r.trunk_err_m, 50),
                "trunk_found_share": r.trunk_found / r.frames if r.frames else None,
            }
            for r in results
        ],
    }


def _biases(signed: list[tuple[float, float, float]]) -> dict[str, Any]:
    """Mean signed errors, all fruit and split by visibility: ``range_bias*_m`` (estimate's
    distance from the camera minus the truth's) and ``dh_bias*_m``, with the counts."""
    out: dict[str, Any] = {}
    for name, keep in (
        ("", lambda v: True),
        ("_visible", lambda v: v >= VISIBLE_SHARE),
        ("_hidden", lambda v: v < VISIBLE_SHARE),
    ):
        rows = [(r, h) for r, h, v in signed if keep(v)]
        out[f"range_bias{name}_m"] = float(np.mean([r for r, _ in rows])) if rows else None
        out[f"dh_bias{name}_m"] = float(np.mean([h for _, h in rows])) if rows else None
        out[f"fruit_estimates{name}"] = len(rows)
    return out


def _q(values: list[float], pct: float) -> float | None:
    return float(np.percentile(values, pct)) if values else None
