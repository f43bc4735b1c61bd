"""The trunk: the circle fit against the paper's mean on a synthetic cylinder with branches, the
clear failures, and the smoothing over frames (gate, re-acquisition, 'not found')."""

from __future__ import annotations

import numpy as np

from services.scene.geometry import RigidTransform
from services.scene.obstacles import build_obstacles, trunk_radius_m
from services.scene.trunk import TrunkFailure, TrunkFix, TrunkParams, measure_trunk
from services.scene.trunk_track import TrackParams, TrunkTrack
from services.vision.trunk_mask import hsv_depth_mask
from tests.scene_helpers import BARK, LEVEL_POSE, K, Scene

T = RigidTransform.of(LEVEL_POSE)
AXIS = (1.2, 0.05)


def trunk_scene(branches: bool) -> Scene:
    s = Scene()
    s.vertical_cylinder(AXIS, 0.07)
    if branches:  # bark-coloured branches going off to the side, nearer than the trunk
        for cam_x, v0, v1 in ((0.15, 120, 135), (-0.2, 300, 312), (0.25, 380, 392)):
            u0 = int(K.fx * cam_x / 1.0 + K.cx)
            s.plane_rect(1.0, min(u0, 320), max(u0, 320), v0, v1, colour=BARK)
    s.plane_rect(0.6, 280, 300, 0, 480)  # a leafy occluder in front of part of the trunk
    return s


def measure(s: Scene, method: str = "circle", noise_mm: float = 0.0):
    depth_mm = s.depth_mm(noise_mm)
    mask = hsv_depth_mask(s.rgb, depth_mm, 0.001, 2.0)
    return measure_trunk(mask, depth_mm / 1000.0, K, T, TrunkParams(method=method))  # type: ignore[arg-type]


def horizontal_error(fix: TrunkFix) -> float:
    return float(np.hypot(fix.axis_point_world_m[0] - AXIS[0], fix.axis_point_world_m[1] - AXIS[1]))


def test_circle_fit_finds_the_axis_and_radius_despite_branches_and_noise() -> None:
    fix = measure(trunk_scene(branches=True), noise_mm=5.0)
    assert isinstance(fix, TrunkFix), fix
    assert horizontal_error(fix) < 0.01
    assert fix.radius_m is not None and abs(fix.radius_m - 0.07) < 0.01


def test_the_papers_mean_lies_on_the_front_surface_pulled_by_branches() -> None:
    fix = measure(trunk_scene(branches=True), method="paper")
    assert isinstance(fix, TrunkFix)
    assert horizontal_error(fix) > 0.05  # the 2 cm goal needs the circle fit


def test_an_empty_mask_and_too_little_trunk_are_clear_failures() -> None:
    empty = measure(Scene())
    assert isinstance(empty, TrunkFailure) and empty.reason == "trunk_mask_empty"
    s = Scene()
    s.plane_rect(1.0, 100, 105, 100, 105, colour=BARK)  # 25 bark pixels: a twig
    few = measure(s)
    assert isinstance(few, TrunkFailure) and few.reason == "trunk_too_little"


def test_a_flat_bark_coloured_board_is_not_a_trunk() -> None:
    s = Scene()
    s.plane_rect(1.0, 100, 500, 100, 400, colour=BARK)
    f = measure(s)
    assert isinstance(f, TrunkFailure) and f.reason == "trunk_no_circle", f


def test_a_best_circle_through_no_key_is_a_failure_not_a_crash(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    # Seen in a paper-exp1 harvest run: the circle ranked best on a subsample of the cells had
    # no inlier among the keys, and the height span of no keys raised (the scene service died).
    import services.scene.trunk as trunk

    def no_inlier(keys_xy, cam, p):  # type: ignore[no-untyped-def]
        return np.array([1.2, 0.05]), 0.07, np.zeros(len(keys_xy), bool)

    monkeypatch.setattr(trunk, "_ransac_circle", no_inlier)
    f = measure(trunk_scene(branches=False))
    assert isinstance(f, TrunkFailure) and f.reason == "trunk_too_little", f


def fix_at(x: float, y: float, r: float = 0.07) -> TrunkFix:
    return TrunkFix(np.array([x, y, 1.0]), r, 1000, 500)


def miss() -> TrunkFailure:
    return TrunkFailure("trunk_mask_empty", "", 0)


def test_track_averages_gates_outliers_and_reacquires() -> None:
    tt = TrunkTrack(TrackParams(smoothing=0.5, gate_m=0.1, reacquire_frames=3))
    tt.step(fix_at(1.0, 0.0))
    tt.step(fix_at(1.02, 0.0))
    assert tt.state is not None and abs(tt.state.axis_world_m[0] - 1.01) < 1e-9
    tt.step(fix_at(1.5, 0.0))  # an outlier: not averaged in
    assert abs(tt.state.axis_world_m[0] - 1.01) < 1e-9 and tt.state.frames_unseen == 1
    tt.step(fix_at(1.5, 0.0))
    tt.step(fix_at(1.5, 0.0))  # three agreeing outliers replace the estimate
    assert tt.state is not None and tt.state.axis_world_m[0] == 1.5


def test_track_is_not_found_after_its_forget_limit() -> None:
    tt = TrunkTrack(TrackParams(forget_after_frames=3))
    tt.step(miss())
    assert tt.state is None
    tt.step(fix_at(1.0, 0.0))
    tt.step(miss())
    tt.step(miss())
    assert tt.state is not None and tt.state.frames_unseen == 2
    tt.step(miss())
    assert tt.state is None


def test_obstacle_radius_uses_the_horizontal_distance_minus_d_h() -> None:
    from services.scene.fruit_list import Entry, Measurement

    tt = TrunkTrack(TrackParams())
    tt.step(fix_at(1.2, 0.0, r=0.06))
    assert tt.state is not None
    # A fruit 0.5 m in front of the axis and 0.4 m higher than P_t: the 3D distance would be
    # 0.64 m and the cylinder would swallow the fruit.
    p = np.array([0.7, 0.0, 1.4])
    fruit = Entry(1, Measurement(p, p, 0.04, 0.038), 0, 0)
    r_obs, own = trunk_radius_m(tt.state, fruit, 0.08)
    assert abs(r_obs - (0.5 - 0.04)) < 1e-9 and own == 0.06
    # A fruit against the trunk: never less than the trunk itself.
    q = np.array([1.17, 0.0, 1.4])
    close = Entry(2, Measurement(q, q, 0.04, 0.038), 0, 0)
    assert trunk_radius_m(tt.state, close, 0.08)[0] == 0.06
    obs = build_obstacles([fruit, close], {2}, tt.state, fruit, 0.08)
    assert [e.fruit_id for e in obs.ellipsoids] == [1]  # harvested fruit are no obstacles
    assert obs.cylinders[0].radius_m == r_obs
    assert build_obstacles([fruit], set(), None, fruit, 0.08).cylinders == ()
