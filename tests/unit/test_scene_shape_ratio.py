"""The d_v/d_h ratio a cut fruit borrows: its own, else the fruit seen whole in the list."""

from __future__ import annotations

import numpy as np
import pytest

from services.runtime.settings import load_settings
from services.scene import Settings
from services.scene.core import SceneCore
from tests.scene_helpers import K, Scene, tracks

A_M, C_M = 0.040, 0.034  # oblate oranges: d_v / d_h = 0.85
WHOLE = {1: (-0.22, 0.0, 0.6), 2: (-0.12, 0.0, 0.6), 3: (-0.02, 0.0, 0.6)}
CUT_ID, CUT_CENTRE = 4, np.array([0.12, 0.0, 0.6])


def _scene() -> Scene:
    s = Scene()
    for fid, centre in WHOLE.items():
        s.ellipsoid(centre, a=A_M, c=C_M, label=fid)
    s.ellipsoid(CUT_CENTRE, a=A_M, c=C_M, label=CUT_ID)
    # A leaf in front hides the cut fruit's right third: its box's right side is the leaf's edge.
    u_leaf = round(float(CUT_CENTRE[0] / CUT_CENTRE[2]) * K.fx + K.cx + 15)
    s.plane_rect(0.45, u_leaf, u_leaf + 60, 150, 330)
    return s


def _cut_fruit(population_min: int) -> tuple[float, float]:
    """(d_h error, range error) of the cut fruit, m, after one frame with all four tracked."""
    s = _scene()
    core = SceneCore(load_settings(Settings, {"v_over_h_population_min_fruit": population_min}))
    core.handle("camera/rgbd", s.frame(seq=0, stamp_ns=1000))
    boxes = {fid: s.box(fid) for fid in (*WHOLE, CUT_ID)}
    ((_, state),) = core.handle("perception/tracks", tracks(0, 1000, 0, boxes))
    (f,) = [f for f in state.fruits if f.fruit_id == CUT_ID]
    assert "edge_occluded" in f.flags
    rng = float(np.linalg.norm(f.position_cam_m)) - float(np.linalg.norm(CUT_CENTRE))
    return f.semi_axis_h_m - A_M, rng


def test_a_cut_fruit_takes_the_shape_of_the_fruit_seen_whole() -> None:
    dh_err, range_err = _cut_fruit(population_min=3)
    assert abs(dh_err) < 1.5e-3 and abs(range_err) < 2e-3


def test_without_enough_whole_fruit_the_prior_is_taken() -> None:
    # The prior 1.0 against the true 0.85: the fruit comes out ~15 % narrow and so nearer.
    for population_min in (0, 4):
        dh_err, range_err = _cut_fruit(population_min)
        assert dh_err < -4e-3 and range_err < -3e-3


def test_a_negative_population_size_is_refused_at_start_up() -> None:
    with pytest.raises(Exception, match="v_over_h_population_min_fruit"):
        load_settings(Settings, {"v_over_h_population_min_fruit": -1})
