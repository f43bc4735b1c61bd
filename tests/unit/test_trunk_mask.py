"""The paper's trunk mask: HSV box ∩ valid, near depth."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from services.vision.trunk_mask import PAPER_TRUNK_HSV, HsvBox, hsv_depth_mask


def rgb_of_hsv(h: int, s: int, v: int) -> tuple[int, int, int]:
    px = cv2.cvtColor(np.array([[[h, s, v]]], np.uint8), cv2.COLOR_HSV2RGB)[0, 0]
    return int(px[0]), int(px[1]), int(px[2])


def test_mask_keeps_trunk_coloured_near_pixels_only() -> None:
    rgb = np.zeros((2, 4, 3), np.uint8)
    rgb[:, 0] = rgb_of_hsv(15, 100, 110)  # trunk colour, near
    rgb[:, 1] = rgb_of_hsv(15, 100, 110)  # trunk colour, too far
    rgb[:, 2] = rgb_of_hsv(15, 100, 110)  # trunk colour, no depth
    rgb[:, 3] = rgb_of_hsv(60, 200, 200)  # green leaf, near
    depth = np.array([[1500, 2500, 0, 1000]] * 2, np.uint16)
    mask = hsv_depth_mask(rgb, depth, depth_unit_m=0.001, max_depth_m=2.0)
    assert mask.dtype == bool and mask.shape == (2, 4)
    assert mask[:, 0].all() and not mask[:, 1:].any()


def test_depth_limit_is_inclusive() -> None:
    rgb = np.full((1, 1, 3), rgb_of_hsv(12, 80, 90), np.uint8)
    assert hsv_depth_mask(rgb, np.array([[2000]], np.uint16), 0.001, 2.0)[0, 0]
    assert not hsv_depth_mask(rgb, np.array([[2001]], np.uint16), 0.001, 2.0)[0, 0]


@pytest.mark.parametrize(
    ("hsv", "inside"),
    [
        ((10, 70, 80), True),  # the low corner
        ((20, 129, 140), True),  # near the high corner (S 130 does not survive HSV→RGB→HSV)
        ((9, 100, 110), False),  # hue just below
        ((21, 100, 110), False),  # hue just above
        ((15, 65, 110), False),  # too grey
        ((15, 100, 79), False),  # too dark
        ((15, 99, 141), False),  # too bright
    ],
)
def test_paper_bounds(hsv: tuple[int, int, int], inside: bool) -> None:
    rgb = np.full((1, 1, 3), rgb_of_hsv(*hsv), np.uint8)
    assert tuple(int(x) for x in cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)[0, 0]) == hsv  # exact pixel
    assert hsv_depth_mask(rgb, np.array([[1000]], np.uint16), 0.001, 2.0)[0, 0] == inside
    assert HsvBox(low=(10, 70, 80), high=(20, 130, 140)) == PAPER_TRUNK_HSV


def test_bad_inputs_name_the_problem() -> None:
    rgb = np.zeros((2, 2, 3), np.uint8)
    with pytest.raises(ValueError, match="depth shape"):
        hsv_depth_mask(rgb, np.zeros((3, 2), np.uint16), 0.001, 2.0)
    with pytest.raises(ValueError, match="rgb must be"):
        hsv_depth_mask(rgb[..., 0], np.zeros((2, 2), np.uint16), 0.001, 2.0)
    with pytest.raises(ValueError, match="integer counts"):
        hsv_depth_mask(rgb, np.zeros((2, 2), np.float32), 0.001, 2.0)
    with pytest.raises(ValueError, match="max_depth_m"):
        hsv_depth_mask(rgb, np.zeros((2, 2), np.uint16), 0.001, 0.0)
    with pytest.raises(ValueError, match="outside OpenCV"):
        HsvBox(low=(0, 0, 0), high=(200, 255, 255))
    with pytest.raises(ValueError, match="exceeds"):
        HsvBox(low=(20, 0, 0), high=(10, 255, 255))
