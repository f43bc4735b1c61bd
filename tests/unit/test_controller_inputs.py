"""services/controller/inputs.py: joint states and plan targets become controller quantities,
or a stated refusal."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from schemas import AbsoluteTarget, ArmJointState, Header, JointState, PlanTarget, RelativeTarget
from services.controller.inputs import Goals, Refusal, Workspace, goals, joint_positions
from services.robot.model import CAMERA_FRAME, joint_names

BY_ROLE = {r: joint_names(r) for r in ("cutter", "collector")}
WS = Workspace((-0.2, -1.2, 0.3), (1.6, 1.2, 2.4), np.array([0.0, 0.17, 1.16]), 1.37, 0.6)
H = Header(stamp_ns=0, seq=0, source="t")


def arm(names: tuple[str, ...], offset: float = 0.0) -> ArmJointState:
    n = len(names)
    return ArmJointState(
        names=names,
        position_rad=tuple(offset + 0.1 * i for i in range(n)),
        velocity_rad_s=(0.0,) * n,
    )


def test_joints_are_mapped_by_name_whatever_their_order() -> None:
    rev = tuple(reversed(BY_ROLE["collector"]))
    js = JointState(header=H, arms={"cutter": arm(BY_ROLE["cutter"]), "collector": arm(rev, 1.0)})
    q = joint_positions(js, BY_ROLE)
    assert isinstance(q, np.ndarray)
    assert np.allclose(q[:7], 0.1 * np.arange(7))
    assert np.allclose(q[7:], (1.0 + 0.1 * np.arange(7))[::-1])


@pytest.mark.parametrize(
    ("cutter", "want"),
    [
        (BY_ROLE["cutter"][:6], "missing cutter_j7"),
        ((*BY_ROLE["cutter"][:6], "cutter_j9"), "unknown cutter_j9"),
        ((*BY_ROLE["cutter"][:6], "cutter_j6"), "missing cutter_j7"),
    ],
)
def test_joint_states_with_missing_or_unknown_joints_are_refused(
    cutter: tuple[str, ...], want: str
) -> None:
    js = JointState(header=H, arms={"cutter": arm(cutter), "collector": arm(BY_ROLE["collector"])})
    got = joint_positions(js, BY_ROLE)
    assert isinstance(got, Refusal) and want in got.reason


def test_a_joint_state_without_an_arm_is_refused() -> None:
    js = JointState(header=H, arms={"cutter": arm(BY_ROLE["cutter"])})
    got = joint_positions(js, BY_ROLE)
    assert isinstance(got, Refusal) and "no collector arm" in got.reason


def target(p=(0.7, 0.0, 1.1), q=(0.0, 0.0, 0.0, 1.0), rel=(0.14, 0.0, 0.0), frame="world"):
    return PlanTarget(
        header=H,
        phase="approach",
        absolute=AbsoluteTarget(frame_id=frame, position_m=p, orientation_xyzw=q),
        relative=RelativeTarget(position_m=rel, orientation_xyzw=(0.0, 0.0, 0.0, 1.0)),
    )


def test_a_valid_target_gives_goals_with_the_free_axes() -> None:
    g = goals(target(), np.eye(4), WS)
    assert isinstance(g, Goals)
    assert g.absolute.free_axis == "x" and g.relative.free_axis == "z"  # schema defaults


def test_a_camera_frame_target_is_turned_into_the_world_frame() -> None:
    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    T[:3, 3] = (0.02, 0.0, 1.44)
    g = goals(target(p=(0.1, 0.2, 0.6), frame=CAMERA_FRAME), T, WS)
    assert isinstance(g, Goals)
    assert np.allclose(g.absolute.p_m, [0.62, -0.1, 1.24])
    assert np.allclose(g.absolute.R, T[:3, :3])


@pytest.mark.parametrize(
    ("kw", "want"),
    [
        ({"p": (0.7, 0.0, 0.1)}, "outside the workspace box"),
        ({"p": (1.55, -1.1, 2.3)}, "reach"),
        ({"q": (0.0, 0.0, 0.0, 0.5)}, "norm 0.5"),
        ({"q": (0.0, 0.0, 0.0, 0.0)}, "norm 0"),
        ({"rel": (0.0, 0.9, 0.0)}, "relative target"),
        ({"frame": "base_link"}, "neither 'world'"),
    ],
)
def test_targets_that_cannot_be_trusted_are_refused(kw: dict, want: str) -> None:
    got = goals(target(**kw), np.eye(4), WS)
    assert isinstance(got, Refusal) and want in got.reason


def test_a_nan_target_never_reaches_the_controller() -> None:
    with pytest.raises(ValidationError):
        target(p=(math.nan, 0.0, 1.0))
    # ... and one built around validation (in-process) is refused by the core's check.
    bad = target().model_copy(
        update={
            "absolute": AbsoluteTarget.model_construct(
                frame_id="world",
                position_m=(math.nan, 0.0, 1.0),
                orientation_xyzw=(0.0, 0.0, 0.0, 1.0),
                free_axis="x",
            )
        }
    )
    got = goals(bad, np.eye(4), WS)
    assert isinstance(got, Refusal) and "not finite" in got.reason


def test_a_missing_task_means_hold() -> None:
    assert goals(target().model_copy(update={"relative": None}), np.eye(4), WS) is None
