"""services/scene/occupancy.py and its use in the scene core: bark-coloured depth points become
bounded sphere obstacles in the world frame; the robot, the selected fruit's working space,
leaves and broken depth frames do not create (or wipe) any."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from schemas.scene import SphereObstacle
from services.robot.clearance import axis_distances_m
from services.runtime.settings import load_settings
from services.scene import Settings, occupancy
from services.scene.core import SceneCore
from services.scene.fruit_list import Entry, Measurement
from services.scene.geometry import RigidTransform
from services.scene.occupancy import OccupancyGrid, OccupancyParams
from tests.scene_helpers import BARK, LEAF, LEVEL_POSE, R_WORLD_CAM, T_WORLD_CAM_M, K, Scene, tracks
from tests.unit.test_scene_self_filter import joint_state

T = RigidTransform.of(LEVEL_POSE)
P = OccupancyParams(voxel_m=0.04, sphere_radius_m=0.03, stride_px=2, clear_frames=3)
BRANCH = (300, 340, 40, 440)  # u0, u1, v0, v1: a bark-coloured strip 0.8 m ahead


def branch_scene(z_m: float = 0.8, colour: tuple[int, int, int] = BARK) -> Scene:
    sc = Scene()
    sc.plane_rect(z_m, *BRANCH, colour=colour)
    return sc


def bark_mask(sc: Scene) -> np.ndarray:
    return np.all(sc.rgb == BARK, axis=-1)


def centres(grid: OccupancyGrid, **kw: object) -> np.ndarray:
    return np.array([s.center_world_m for s in grid.obstacles(**kw)]).reshape(-1, 3)  # type: ignore[arg-type]


def strip_world_box() -> tuple[np.ndarray, np.ndarray]:
    """World bounds of the strip's surface at 0.8 m."""
    u0, u1, v0, v1 = BRANCH
    corners = [K.deproject(u, v, 0.8) for u in (u0, u1) for v in (v0, v1)]
    w = np.array(corners) @ R_WORLD_CAM.T + T_WORLD_CAM_M
    return w.min(axis=0), w.max(axis=0)


def test_bark_points_become_spheres_on_the_strip() -> None:
    sc = branch_scene()
    grid = OccupancyGrid(P)
    grid.step(bark_mask(sc), sc.depth, K, T, ())
    c = centres(grid)
    lo, hi = strip_world_box()
    assert len(c) >= 5
    assert np.all(c >= lo - 0.005) and np.all(c <= hi + 0.005)
    assert all(s.radius_m == P.sphere_radius_m for s in grid.obstacles())


def test_points_on_the_robot_are_left_out() -> None:
    sc = branch_scene()
    lo, hi = strip_world_box()
    mid = (lo + hi) / 2
    # a link (capsule) along the strip's upper half
    capsule = (np.array([mid[0], mid[1], mid[2]]), np.array([mid[0], mid[1], hi[2] + 0.1]), 0.03)
    grid = OccupancyGrid(P)
    grid.step(bark_mask(sc), sc.depth, K, T, (capsule,))
    c = centres(grid)
    assert len(c) > 0, "the lower half is still a branch"
    assert np.all(c[:, 2] < mid[2] + 0.02)


def stepped_grid() -> tuple[OccupancyGrid, np.ndarray]:
    """A grid that has seen the branch scene once, and the strip's middle (world, m)."""
    sc = branch_scene()
    grid = OccupancyGrid(P)
    grid.step(bark_mask(sc), sc.depth, K, T, ())
    lo, hi = strip_world_box()
    return grid, (lo + hi) / 2


def test_nothing_within_the_keep_out_sphere_and_the_cylinder() -> None:
    grid, mid = stepped_grid()
    kept = centres(grid, keep_out=[(mid, mid, 0.05)])
    assert len(kept) > 0 and len(kept) < len(centres(grid))
    assert np.all(np.linalg.norm(kept - mid, axis=1) >= 0.05 + P.sphere_radius_m)
    assert len(centres(grid, inside_cylinder=(mid, 0.5))) == 0


def test_the_keep_out_hands_its_spheres_over_to_within() -> None:
    grid, mid = stepped_grid()
    keep_out = [(mid, mid, 0.05)]
    out = {s.center_world_m for s in grid.obstacles(keep_out)}
    near = {s.center_world_m for s in grid.within(keep_out)}
    assert near and not (out & near)  # one or the other, never both
    assert out | near == {s.center_world_m for s in grid.obstacles()}  # together: all of it
    assert grid.within(keep_out, inside_cylinder=(keep_out[0][0], 0.5)) == ()  # trunk's own
    assert grid.within([]) == ()


def test_a_keep_out_capsule_clears_its_whole_segment() -> None:
    grid, mid = stepped_grid()
    front = mid - R_WORLD_CAM[:, 2] * 0.3  # 0.3 m towards the camera
    assert len(centres(grid, keep_out=[(front, front, 0.05)])) == len(centres(grid))
    kept = centres(grid, keep_out=[(mid, front, 0.05)])
    assert len(kept) == len(centres(grid, keep_out=[(mid, mid, 0.05)]))  # the strip's end: mid
    assert len(kept) < len(centres(grid))


def test_the_count_is_capped_to_the_most_recently_hit() -> None:
    sc = branch_scene()
    grid = OccupancyGrid(OccupancyParams(stride_px=2, max_obstacles=3))
    grid.step(bark_mask(sc), sc.depth, K, T, ())
    assert len(grid.voxels) > 3 and len(grid.obstacles()) == 3


@pytest.mark.parametrize("bad", ["zero", "nan", "inf"])
def test_a_broken_depth_frame_neither_creates_nor_wipes_obstacles(bad: str) -> None:
    value = {"zero": 0.0, "nan": np.nan, "inf": np.inf}[bad]
    sc = branch_scene()
    broken = np.full_like(sc.depth, value)
    first = OccupancyGrid(P)
    for _ in range(5):
        first.step(bark_mask(sc), broken, K, T, ())
    assert first.obstacles() == ()
    grid = OccupancyGrid(P)
    grid.step(bark_mask(sc), sc.depth, K, T, ())
    before = centres(grid)
    for _ in range(2 * P.clear_frames):
        grid.step(bark_mask(sc), broken, K, T, ())
    assert np.array_equal(centres(grid), before)


def test_a_branch_hidden_behind_an_arm_is_remembered_and_one_gone_is_forgotten() -> None:
    sc = branch_scene()
    grid = OccupancyGrid(P)
    grid.step(bark_mask(sc), sc.depth, K, T, ())
    n = len(grid.obstacles())
    hidden = Scene()
    hidden.plane_rect(0.5, 250, 400, 20, 460, colour=(120, 120, 120))  # an arm in front
    hidden.plane_rect(1.4, 0, K.width, 0, K.height, colour=(200, 200, 200))  # background
    for _ in range(2 * P.clear_frames):
        grid.step(bark_mask(hidden), hidden.depth, K, T, ())
    assert len(grid.obstacles()) == n
    gone = Scene()
    gone.plane_rect(1.4, 0, K.width, 0, K.height, colour=(200, 200, 200))  # seen through
    for _ in range(P.clear_frames - 1):
        grid.step(bark_mask(gone), gone.depth, K, T, ())
    assert len(grid.obstacles()) == n
    grid.step(bark_mask(gone), gone.depth, K, T, ())
    assert grid.obstacles() == ()


def test_a_hand_gone_is_forgotten_when_the_background_is_beyond_the_depth_limit() -> None:
    """A skin-coloured hand (bark to the HSV box) sweeps 0.3 m ahead and leaves; the background
    behind it is beyond max_depth_m. Its far depth still shows the hand gone."""
    near = Scene()
    near.plane_rect(0.3, 250, 400, 200, 300, colour=BARK)
    grid = OccupancyGrid(P)
    grid.step(bark_mask(near), near.depth, K, T, ())
    assert len(grid.obstacles()) > 0
    far = Scene()
    far.plane_rect(P.max_depth_m + 1.4, 0, K.width, 0, K.height, colour=(200, 200, 200))
    for _ in range(P.clear_frames):
        grid.step(bark_mask(far), far.depth, K, T, ())
    assert grid.obstacles() == ()


def scene_of(*rects: tuple[float, tuple[int, int, int, int], tuple[int, int, int]]) -> Scene:
    """Fronto-parallel rectangles (depth m, (u0, u1, v0, v1), colour), nearest in front."""
    sc = Scene()
    for z, (u0, u1, v0, v1), colour in rects:
        sc.plane_rect(z, u0, u1, v0, v1, colour=colour)
    return sc


WALL = (1.4, (0, K.width, 0, K.height), (200, 200, 200))  # a grey background within range
ARM = (0.3, (250, 400, 20, 460), (120, 120, 120))  # in front of the strip


def test_a_hand_that_swept_past_is_forgotten_though_an_arm_hides_where_it_was() -> None:
    """Skin falls in the bark HSV box. The hand moved into space the camera saw through: it is
    an obstacle while seen, then forgotten, also where an arm now hides the spot (paper-exp1:
    the voxels of the hand held a cutter elbow 25 cm from any branch)."""
    grid = OccupancyGrid(P)
    before, hand, hidden = scene_of(WALL), scene_of(WALL, (0.8, BRANCH, BARK)), scene_of(WALL, ARM)
    for sc in (before, before, hand, hand, hand):
        grid.step(bark_mask(sc), sc.depth, K, T, ())
    assert len(grid.obstacles()) > 0  # an obstacle while it is there
    for _ in range(P.transient_forget_frames):
        grid.step(bark_mask(hidden), hidden.depth, K, T, ())
    assert len(grid.obstacles()) > 0
    grid.step(bark_mask(hidden), hidden.depth, K, T, ())
    assert grid.obstacles() == ()


@pytest.mark.parametrize(("window", "kept"), [(0, True), (occupancy.THROUGH_WINDOW, False)])
def test_a_hand_that_came_where_the_wall_gave_depth_only_between_holes_is_a_newcomer(
    monkeypatch: pytest.MonkeyPatch, window: int, kept: bool
) -> None:
    """The wall behind where the hand came gave depth at one pixel in 64 (dark texture, the
    stereo shadow of a nearer fruit): the pixel of a voxel's centre was a hole in every frame
    remembered, a neighbour was not. The hand is a newcomer, forgotten once gone though an arm
    hides the spot (orchard seed 1: with the centre pixel alone, its thumb stayed as a branch
    in the dish's way). Window 0, the centre pixel alone, keeps it."""
    monkeypatch.setattr(occupancy, "THROUGH_WINDOW", window)
    holed = scene_of(WALL)
    v_px, u_px = np.indices(holed.depth.shape)
    holed.depth[(u_px % 8 != 0) | (v_px % 8 != 0)] = 0.0  # every 4th kept cell either way
    hand, hidden = scene_of(WALL, (0.8, BRANCH, BARK)), scene_of(WALL, ARM)
    grid = OccupancyGrid(P)
    for sc in [holed] * P.history_frames + [hand] * 3:
        grid.step(bark_mask(sc), sc.depth, K, T, ())
    assert len(grid.obstacles()) > 0  # an obstacle while it is there
    for _ in range(P.transient_forget_frames + 1):
        grid.step(bark_mask(hidden), hidden.depth, K, T, ())
    assert (len(grid.obstacles()) > 0) is kept


def test_a_hand_that_came_where_only_older_frames_saw_through_is_a_newcomer() -> None:
    """The arm hid the spot for longer than the recent frames remember; the hand then came in
    front of it. The first frame, kept in the sparse long memory, saw the wall behind: the hand
    is forgotten once gone (paper-exp1 seed 0: without it, a hand's voxel stayed in the dish's
    way for the rest of the run)."""
    hand = scene_of(WALL, ARM, (0.25, BRANCH, BARK))
    hidden = scene_of(WALL, ARM)
    for long_frames, kept in ((P.history_long_frames, False), (0, True)):
        grid = OccupancyGrid(OccupancyParams(**{**P.__dict__, "history_long_frames": long_frames}))
        for sc in [scene_of(WALL)] + [hidden] * (P.history_frames + 5) + [hand] * 3:
            grid.step(bark_mask(sc), sc.depth, K, T, ())
        assert len(grid.obstacles()) > 0  # an obstacle while it is there
        for _ in range(P.transient_forget_frames + 1):
            grid.step(bark_mask(hidden), hidden.depth, K, T, ())
        assert (len(grid.obstacles()) > 0) is kept


def test_a_hand_in_front_of_nothing_in_range_is_forgotten_once_gone() -> None:
    """Nothing behind the hand gives depth (the sky, a far wall): it is never seen through.
    Once its pixels show no depth and no bark for blank_frames it is forgotten; a branch whose
    pixels lose their depth but still show bark (a stereo shadow) is kept, and so is one with
    the robot in its line of sight."""
    hand, empty = scene_of((0.3, BRANCH, BARK)), Scene()  # Scene(): no depth anywhere
    shadow = scene_of((0.3, BRANCH, BARK))
    shadow.depth[:] = 0.0  # bark in the image, no depth at all
    centre_cam = K.deproject((BRANCH[0] + BRANCH[1]) / 2, (BRANCH[2] + BRANCH[3]) / 2, 0.15)
    centre, along_y = T.to_world(centre_cam), np.array([0.0, 0.05, 0.0])
    arm = (centre - along_y, centre + along_y, 0.04)  # an arm capsule across the line of sight
    for blank, after, robot, kept in (
        (P.blank_frames, empty, (), False),
        (0, empty, (), True),
        (P.blank_frames, shadow, (), True),
        (P.blank_frames, empty, (arm,), True),
    ):
        grid = OccupancyGrid(OccupancyParams(**{**P.__dict__, "blank_frames": blank}))
        for _ in range(3):
            grid.step(bark_mask(hand), hand.depth, K, T, ())
        assert len(grid.obstacles()) > 0
        for _ in range(P.blank_frames - 1):
            grid.step(bark_mask(after), after.depth, K, T, robot)
        assert len(grid.obstacles()) > 0  # not yet
        grid.step(bark_mask(after), after.depth, K, T, robot)
        assert (len(grid.obstacles()) > 0) is kept, (blank, robot)


def test_bark_far_behind_a_hand_does_not_keep_it() -> None:
    """A hand in front of nothing in range, then a branch far behind where it was whose bark
    edges the voxels' pixels (their own pixels give no depth): the bark is 0.9 m behind, no
    branch at the hand's place, and the hand is forgotten after blank_frames (paper-exp1 seed
    11: the hand that moved a fruit stayed as a branch under it and the fruit was given up).
    The same bark with no depth (a stereo shadow: it may stand there) keeps it."""
    hand = scene_of((0.3, BRANCH, BARK))
    probe = OccupancyGrid(P)
    probe.step(bark_mask(hand), hand.depth, K, T, ())
    uv = [
        (round(K.fx * c[0] / c[2] + K.cx), round(K.fy * c[1] / c[2] + K.cy))
        for c in T.to_camera(np.array([s.center_world_m for s in probe.obstacles()]))
    ]
    for far_depth_m, kept in ((1.2, False), (0.0, True)):
        behind = scene_of((1.2, BRANCH, BARK))
        behind.depth[behind.depth > 0] = far_depth_m
        for u, v in uv:
            behind.depth[v, u], behind.rgb[v, u] = 0.0, 200  # its own pixel: the far wall
        grid = OccupancyGrid(P)
        for _ in range(3):
            grid.step(bark_mask(hand), hand.depth, K, T, ())
        assert len(near_hand(grid)) == len(uv) > 0
        for _ in range(P.blank_frames):
            grid.step(bark_mask(behind), behind.depth, K, T, ())
        assert len(near_hand(grid)) == (len(uv) if kept else 0), far_depth_m


def near_hand(grid: OccupancyGrid) -> list[object]:
    """The spheres nearer the camera than 0.6 m (the hand's; the far branch makes its own)."""
    z = T.to_camera(centres(grid).reshape(-1, 3))[:, 2] if grid.obstacles() else np.zeros(0)
    return [s for s, zi in zip(grid.obstacles(), z, strict=True) if zi < 0.6]


def test_a_branch_seen_from_the_start_or_uncovered_stays_where_an_arm_hides_it() -> None:
    """A branch is never seen through before it is seen: there from the first frame, or
    uncovered by a leaf that swung away, it is remembered behind the arm."""
    branch = scene_of(WALL, (0.8, BRANCH, BARK))
    leaf = scene_of(WALL, (0.8, BRANCH, BARK), (0.6, BRANCH, LEAF))
    hidden = scene_of(WALL, ARM)
    for frames in ([branch], [leaf, leaf, branch]):
        grid = OccupancyGrid(P)
        for sc in frames:
            grid.step(bark_mask(sc), sc.depth, K, T, ())
        n = len(grid.obstacles())
        assert n > 0
        for _ in range(3 * P.transient_forget_frames):
            grid.step(bark_mask(hidden), hidden.depth, K, T, ())
        assert len(grid.obstacles()) == n


def test_what_moved_in_and_stayed_is_kept_like_a_branch() -> None:
    grid = OccupancyGrid(P)
    before, there = scene_of(WALL), scene_of(WALL, (0.8, BRANCH, BARK))
    hidden = scene_of(WALL, ARM)
    grid.step(bark_mask(before), before.depth, K, T, ())
    for _ in range(P.settle_hits):
        grid.step(bark_mask(there), there.depth, K, T, ())
    n = len(grid.obstacles())
    for _ in range(3 * P.transient_forget_frames):
        grid.step(bark_mask(hidden), hidden.depth, K, T, ())
    assert n > 0 and len(grid.obstacles()) == n


# ---- in the scene core --------------------------------------------------------------------
def run_core(sc: Scene, boxes: dict[int, tuple], **settings: object):  # type: ignore[no-untyped-def]
    # the keep-out leaves its spheres out unless a test asks for near spheres
    base = {"robot_self_filter": False, "occupancy_near_radius_m": 0.0}
    core = SceneCore(load_settings(Settings, {**base, **settings}))
    state = None
    for k in range(4):  # the track is confirmed from the first frame; the list fills at once
        core.handle("camera/rgbd", sc.frame(k, 1000 * (k + 1)))
        (out,) = core.handle("perception/tracks", tracks(k, 1000 * (k + 1), k, boxes))
        state = out[1]
    return state


def test_the_scene_publishes_bark_as_spheres_and_leaves_none() -> None:
    state = run_core(branch_scene(), {})
    assert len(state.obstacles.spheres) > 0
    assert run_core(branch_scene(colour=LEAF), {}).obstacles.spheres == ()
    assert run_core(branch_scene(), {}, occupancy=False).obstacles.spheres == ()


def test_the_selected_fruits_working_space_is_kept_free() -> None:
    sc = branch_scene()
    # a fruit hanging beside the strip, 0.8 m ahead
    sc.ellipsoid((0.12, 0.0, 0.78), 0.04, 0.045)
    state = run_core(sc, {1: sc.box(1)})
    (f,) = state.fruits
    assert f.status == "selected"
    c = np.array([s.center_world_m for s in state.obstacles.spheres]).reshape(-1, 3)
    reach = f.semi_axis_v_m + Settings().occupancy_target_clearance_m + 0.03
    assert len(c) > 0, "the strip's far end is still an obstacle"
    assert np.all(np.linalg.norm(c - np.array(f.position_world_m), axis=1) >= reach - 1e-9)
    free = run_core(sc, {})  # no fruit selected: the strip is whole
    assert len(free.obstacles.spheres) > len(c)


def test_the_corridor_keeps_the_approach_line_free_in_front_of_the_fruit() -> None:
    # a fruit 0.78 m ahead and a bark strip 0.23 m in front of it, 0.1 m to its side: outside a
    # 0.1 m keep-out sphere, inside the capsule along the optical axis towards the camera
    centre_cam = np.array([0.12, 0.0, 0.78])
    sc = Scene()
    u, v = K.project(np.array([0.02, 0.0, 0.55]))
    sc.plane_rect(0.55, int(u) - 6, int(u) + 6, int(v) - 30, int(v) + 30, colour=BARK)
    sc.ellipsoid(tuple(centre_cam), 0.04, 0.045)
    sphere = run_core(sc, {1: sc.box(1)}, occupancy_target_clearance_m=0.1)
    corridor = run_core(
        sc, {1: sc.box(1)}, occupancy_target_clearance_m=0.1, occupancy_target_corridor_m=0.3
    )
    assert len(sphere.obstacles.spheres) > 0 and sphere.spheres_near_selected == ()
    assert corridor.obstacles.spheres == ()
    assert len(corridor.spheres_near_selected) == len(sphere.obstacles.spheres)


def test_near_spheres_reach_the_controller_small_outside_the_inner_working_space() -> None:
    sc = branch_scene()
    sc.ellipsoid((0.12, 0.0, 0.78), 0.04, 0.045)  # beside the strip, as above
    boxes = {1: sc.box(1)}
    full_m = Settings().occupancy_sphere_radius_m
    off = run_core(sc, boxes)
    on = run_core(sc, boxes, occupancy_near_radius_m=0.01)
    no_twig = run_core(sc, boxes, occupancy_near_radius_m=0.01, occupancy_inner_twig_m=0.0)
    assert all(s.radius_m == full_m for s in off.obstacles.spheres)
    assert on.spheres_near_selected == off.spheres_near_selected  # the branch check's: whole
    small = [s for s in on.obstacles.spheres if s.radius_m == 0.01]
    assert [s for s in on.obstacles.spheres if s.radius_m != 0.01] == list(off.obstacles.spheres)
    assert 0 < len(small) < len(off.spheres_near_selected)
    (f,) = on.fruits
    centre = np.array(f.position_world_m)
    top = centre + np.array([0.0, 0.0, f.semi_axis_v_m + 0.1])
    reach = f.semi_axis_v_m + 0.05 + full_m  # the inner clearance + the voxel's sphere radius
    d = [axis_distances_m(np.array(s.center_world_m), [(centre, top, 0.0)])[0] for s in small]
    assert min(d) >= reach - 1e-9
    # the fruit's own twig: the strip above it is left out with the twig, shown without it
    assert len([s for s in no_twig.obstacles.spheres if s.radius_m == 0.01]) > len(small)


def selected_at(fruit_id: int, centre_m: np.ndarray, d_v_m: float = 0.04) -> Entry:
    m = Measurement(np.zeros(3), centre_m, 0.04, d_v_m)
    return Entry(fruit_id, m, 0, 0)


def test_a_near_sphere_shown_stays_shown_while_the_inner_spaces_edge_moves() -> None:
    """Orchard seed 19: a felt branch at the inner working space's edge was shown and hidden on
    alternate states as the fruit's estimate moved a few mm, and the dish struck it 12 times."""
    fruit_m = np.array([0.9, -0.19, 1.48])
    inner_m = 0.04 + Settings().occupancy_inner_clearance_m  # d_v + the inner clearance
    felt = SphereObstacle(  # its surface 1 mm outside the inner working space
        name="touched_near_0",
        center_world_m=tuple(fruit_m + np.array([-(inner_m + 0.035 + 0.001), 0.0, 0.0])),
        radius_m=0.035,
    )
    moved = fruit_m + np.array([-0.004, 0.0, 0.0])  # the next view: 4 mm nearer the sphere

    def shown(core: SceneCore, centre_m: np.ndarray, fruit_id: int = 3) -> list[str]:
        return [s.name for s in core._near_shown(selected_at(fruit_id, centre_m), (felt,))]

    base = {"robot_self_filter": False, "occupancy_near_radius_m": 0.01}
    plain = SceneCore(load_settings(Settings, {**base, "occupancy_near_hold_m": 0.0}))
    assert shown(plain, fruit_m) == ["touched_near_0"]
    assert shown(plain, moved) == []  # 3 mm inside: hidden, the dish goes back in
    held = SceneCore(load_settings(Settings, {**base, "occupancy_near_hold_m": 0.01}))
    assert shown(held, moved) == []  # never shown yet: the hold keeps nothing
    assert shown(held, fruit_m) == ["touched_near_0"]
    assert shown(held, moved) == ["touched_near_0"]  # shown before: held
    deeper = fruit_m + np.array([-0.012, 0.0, 0.0])  # 11 mm inside: past the hold
    assert shown(held, deeper) == []
    assert shown(held, moved) == []  # it left: it must come out again to be shown
    assert shown(held, fruit_m) == ["touched_near_0"]
    assert shown(held, moved, fruit_id=4) == []  # another fruit selected: nothing held


def test_a_near_radius_under_two_millimetres_is_refused_by_name() -> None:
    with pytest.raises(ValueError, match=r"occupancy_near_radius_m 0\.001"):
        load_settings(Settings, {"occupancy_near_radius_m": 0.001})


def test_fruit_colour_no_estimate_explains_is_an_unseen_fruit_obstacle() -> None:
    # A is tracked (its estimate explains its pixels); B, as orange, has no track: a fruit
    # behind leaves the detector misses (orchard seed 18). Opt-in: off, no sphere at all.
    sc = Scene()
    sc.ellipsoid((-0.2, 0.0, 0.8), 0.04, 0.045, label=1)
    sc.ellipsoid((0.25, 0.0, 0.7), 0.04, 0.045, label=2)
    boxes = {1: sc.box(1)}
    assert run_core(sc, boxes).obstacles.spheres == ()
    state = run_core(sc, boxes, occupancy_unseen_fruit=True)
    (a,) = state.fruits
    got = state.obstacles.spheres
    assert got and all(s.name.startswith("unseen_fruit_occupied_") for s in got)
    c = np.array([s.center_world_m for s in got])
    b_world = np.array([0.25, 0.0, 0.7]) @ R_WORLD_CAM.T + T_WORLD_CAM_M
    assert np.all(np.linalg.norm(c - b_world, axis=1) < 0.05 + 0.03)  # on B's visible surface
    assert np.all(np.linalg.norm(c - np.array(a.position_world_m), axis=1) > 0.3)
    # once B is tracked too, its estimate explains its pixels: its spheres go
    both = run_core(sc, {1: sc.box(1), 2: sc.box(2)}, occupancy_unseen_fruit=True)
    assert len(both.fruits) == 2 and both.obstacles.spheres == ()


def test_unseen_fruit_spheres_go_once_an_estimate_explains_them() -> None:
    sc = Scene()
    sc.ellipsoid((-0.2, 0.0, 0.8), 0.04, 0.045, label=1)
    sc.ellipsoid((0.25, 0.0, 0.7), 0.04, 0.045, label=2)
    base = {"robot_self_filter": False, "occupancy_near_radius_m": 0.0}
    core = SceneCore(load_settings(Settings, {**base, "occupancy_unseen_fruit": True}))
    states = []
    for k in range(8):  # B untracked for 4 frames, then tracked
        boxes = {1: sc.box(1)} if k < 4 else {1: sc.box(1), 2: sc.box(2)}
        core.handle("camera/rgbd", sc.frame(k, 1000 * (k + 1)))
        (out,) = core.handle("perception/tracks", tracks(k, 1000 * (k + 1), k, boxes))
        states.append(out[1])
    assert states[3].obstacles.spheres and states[-1].obstacles.spheres == ()


def test_voxels_where_the_robot_now_stands_are_forgotten_when_asked() -> None:
    # The unseen-fruit grid's case: the orange arm seen in a frame without its joint state
    # leaves voxels on it; the next frame's capsules show the robot there (orchard seed 13:
    # such spheres on the cutter at home stalled its first approach for 14 s).
    sc = branch_scene()
    lo, hi = strip_world_box()
    mid = (lo + hi) / 2
    capsule = (mid.copy(), np.array([mid[0], mid[1], hi[2] + 0.1]), 0.03)  # the upper half
    blank = np.zeros_like(bark_mask(sc))
    kept = {}
    for margin in (None, 0.01):
        grid = OccupancyGrid(dataclasses.replace(P, forget_in_robot_m=margin))
        grid.step(bark_mask(sc), sc.depth, K, T, ())  # no capsules: the link's points count
        before = len(grid.voxels)
        grid.step(blank, sc.depth, K, T, (capsule,))
        kept[margin] = (before, centres(grid))
    before, c = kept[None]
    assert len(c) == before  # the bark grid keeps them (a branch the tool touches)
    before, c = kept[0.01]
    assert 0 < len(c) < before, "the lower half stays"
    assert all(float(axis_distances_m(p, [capsule])[0]) >= 0.03 + 0.01 for p in c)


def test_no_joint_state_no_unseen_fruit_from_that_frame() -> None:
    # The self-filter on and no joint state for a frame: its fruit colour may be the arms.
    sc = Scene()
    sc.ellipsoid((0.25, 0.0, 0.7), 0.04, 0.045, label=2)
    on = {"robot_self_filter": True, "occupancy_unseen_fruit": True}
    core = SceneCore(load_settings(Settings, {**on, "occupancy_near_radius_m": 0.0}))
    for k in range(3):
        core.handle("camera/rgbd", sc.frame(k, 1000 * (k + 1)))
        (out,) = core.handle("perception/tracks", tracks(k, 1000 * (k + 1), k, {}))
    assert out[1].obstacles.spheres == ()
    assert core.counters["unseen_fruit_frame_unfiltered"] == 3
    core.handle("robot/joint_state", joint_state(3500))  # the arms at home, away from B
    core.handle("camera/rgbd", sc.frame(3, 4000))
    (out,) = core.handle("perception/tracks", tracks(3, 4000, 3, {}))
    assert out[1].obstacles.spheres and core.counters["unseen_fruit_frame_unfiltered"] == 3
