"""The robot model: generated files up to date, pybullet and placo agree, the harvest zone is
reachable."""

from __future__ import annotations

import numpy as np

from services.robot.model import COLLISIONS_PATH, HOME_RAD, TOOL_FRAME, URDF_PATH, all_joint_names
from services.robot.urdf import collisions_json, generate


def test_committed_files_match_the_generator() -> None:
    assert URDF_PATH.read_text() == generate(), "run python -m services.robot --write"
    assert COLLISIONS_PATH.read_text() == collisions_json()


def test_pybullet_and_placo_forward_kinematics_agree() -> None:
    import placo
    import pybullet as pb

    robot = placo.RobotWrapper(str(URDF_PATH))
    cid = pb.connect(pb.DIRECT)
    try:
        body = pb.loadURDF(
            str(URDF_PATH),
            useFixedBase=True,
            flags=pb.URDF_USE_IMPLICIT_CYLINDER,
            physicsClientId=cid,
        )
        joints = {
            pb.getJointInfo(body, i, physicsClientId=cid)[1].decode(): i
            for i in range(pb.getNumJoints(body, physicsClientId=cid))
        }
        links = {
            pb.getJointInfo(body, i, physicsClientId=cid)[12].decode(): i
            for i in range(pb.getNumJoints(body, physicsClientId=cid))
        }
        rng = np.random.default_rng(0)
        for _ in range(20):
            for name in all_joint_names():
                lo, hi = robot.get_joint_limits(name)
                q = float(rng.uniform(lo, hi))
                robot.set_joint(name, q)
                pb.resetJointState(body, joints[name], q, physicsClientId=cid)
            robot.update_kinematics()
            for frame in (*TOOL_FRAME.values(), "camera_optical", "cutter_link4"):
                p_placo = robot.get_T_world_frame(frame)[:3, 3]
                p_pb = np.array(
                    pb.getLinkState(
                        body, links[frame], computeForwardKinematics=True, physicsClientId=cid
                    )[4]
                )
                np.testing.assert_allclose(p_placo, p_pb, atol=1e-5, err_msg=frame)
    finally:
        pb.disconnect(cid)


def test_home_posture_is_inside_the_limits_and_collision_free() -> None:
    import placo

    robot = placo.RobotWrapper(str(URDF_PATH))
    for role, q in HOME_RAD.items():
        for i, v in enumerate(q):
            robot.set_joint(f"{role}_j{i + 1}", v)
    robot.update_kinematics()
    assert min(d.min_distance for d in robot.distances()) > 0.02


def test_fruit_04_to_09_m_in_front_of_the_camera_are_reachable_with_tools_forward() -> None:
    from services.robot.reach import ReachSolver, grid

    s = ReachSolver()
    results = [s.reach(p) for p in grid(s)]
    reached = sum(r.reached for r in results)
    assert reached >= 0.95 * len(results), [r for r in results if not r.reached]


def test_urdf_is_well_formed_xml() -> None:
    """Rerun and strict XML parsers refuse '--' in comments (it happened)."""
    import xml.etree.ElementTree as ET

    root = ET.parse(URDF_PATH).getroot()
    assert root.tag == "robot" and len(root.findall("joint")) > 14
