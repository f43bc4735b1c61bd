"""`harvest eval scene`'s scoring: the signed bias along the camera ray and of d_h, split by how
much of the fruit is visible (a hidden side biases a fit nearer the camera)."""

from __future__ import annotations

import numpy as np
import pytest

from schemas.base import Header
from schemas.scene import Fruit, Obstacles, SceneState, Trunk
from schemas.sim import FruitTruth, GroundTruth, TrunkTruth
from services.scene import Settings
from services.scene.evaluate import SeedResult, _score, summary

CAM = np.array([0.0, 0.0, 1.3])


def _truth(visible: tuple[float, float]) -> GroundTruth:
    def fruit(i: int, vf: float) -> FruitTruth:
        y = 0.2 * i
        return FruitTruth(
            fruit_id=i,
            position_world_m=(0.6, y, 1.3),
            orientation_xyzw=(0, 0, 0, 1),
            semi_axes_m=(0.04, 0.04, 0.038),
            peduncle_world_m=(0.6, y, 1.338),
            visible_fraction=vf,
            box_xyxy_px=(100.0, 100.0, 140.0, 138.0),
            state="attached",
        )

    return GroundTruth(
        header=Header(stamp_ns=10, seq=1, source="sim"),
        frame_seq=1,
        fruits=tuple(fruit(i, v) for i, v in enumerate(visible)),
        trunk=TrunkTruth(axis_point_world_m=(1.2, 0.0, 0.0), radius_m=0.06),
    )


def _estimate(truth: GroundTruth, i: int, nearer_m: float, dh_m: float) -> Fruit:
    """Truth fruit ``i`` estimated ``nearer_m`` nearer the camera along its ray."""
    p = np.array(truth.fruits[i].position_world_m)
    ray = (p - CAM) / np.linalg.norm(p - CAM)
    q = p - nearer_m * ray
    return Fruit(
        fruit_id=i + 1,
        position_cam_m=(0.0, 0.0, float(np.linalg.norm(q - CAM))),
        position_world_m=tuple(float(v) for v in q),  # type: ignore[arg-type]
        semi_axis_h_m=truth.fruits[i].semi_axes_m[0] + dh_m,
        semi_axis_v_m=truth.fruits[i].semi_axes_m[2],
        distance_m=float(np.linalg.norm(q - CAM)),
        status="candidate",
        frames_unseen=0,
        last_seen_stamp_ns=10,
    )


def test_the_range_bias_is_signed_and_split_by_visibility() -> None:
    truth = _truth((1.0, 0.6))
    state = SceneState(
        header=Header(stamp_ns=10, seq=1, source="scene"),
        fruits=(_estimate(truth, 0, 0.001, 0.0), _estimate(truth, 1, 0.004, -0.003)),
        trunk=Trunk(found=False),
        obstacles=Obstacles(),
    )
    res = SeedResult("test", 0)
    _score(res, state, truth, {1, 2}, CAM, (0.4, 1.0))
    out = summary([res], Settings())
    assert out["range_bias_visible_m"] == pytest.approx(-0.001, abs=1e-9)
    assert out["range_bias_hidden_m"] == pytest.approx(-0.004, abs=1e-9)
    assert out["range_bias_m"] == pytest.approx(-0.0025, abs=1e-9)
    assert out["dh_bias_visible_m"] == pytest.approx(0.0, abs=1e-9)
    assert out["dh_bias_hidden_m"] == pytest.approx(-0.003, abs=1e-9)
    assert (out["fruit_estimates_visible"], out["fruit_estimates_hidden"]) == (1, 1)


def test_no_estimate_in_a_split_gives_none_not_zero() -> None:
    truth = _truth((1.0,))
    state = SceneState(
        header=Header(stamp_ns=10, seq=1, source="scene"),
        fruits=(_estimate(truth, 0, -0.002, 0.001),),
        trunk=Trunk(found=False),
        obstacles=Obstacles(),
    )
    res = SeedResult("test", 0)
    _score(res, state, truth, {1}, CAM, (0.4, 1.0))
    out = summary([res], Settings())
    assert out["range_bias_visible_m"] == pytest.approx(0.002, abs=1e-9)  # + : farther
    assert out["range_bias_hidden_m"] is None and out["fruit_estimates_hidden"] == 0
