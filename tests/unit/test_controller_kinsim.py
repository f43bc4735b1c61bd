"""services/controller/kinsim.py: the kinematic stand-in integrates by name, and its monitor
catches what it is there to catch."""

from __future__ import annotations

import numpy as np

from schemas import ArmJointVelocity, Header, JointVelocityCommand
from services.controller.kinsim import SIM_PERIOD_NS, KinematicSim, SafetyMonitor, SafetyReport
from services.controller.scenarios import fruit, scene
from services.robot.model import joint_names


def command(cutter: list[float], collector: list[float]) -> JointVelocityCommand:
    def arm(role: str, v: list[float]) -> ArmJointVelocity:
        names = joint_names(role)  # type: ignore[arg-type]
        return ArmJointVelocity(names=tuple(reversed(names)), velocity_rad_s=tuple(reversed(v)))

    return JointVelocityCommand(
        header=Header(stamp_ns=0, seq=0, source="t"),
        arms={"cutter": arm("cutter", cutter), "collector": arm("collector", collector)},
    )


def test_commands_are_integrated_by_joint_name_over_one_period() -> None:
    sim = KinematicSim()
    q0 = sim.q_arm_order()
    sim.apply(command([1.0] + [0.0] * 6, [0.0] * 6 + [-2.0]))
    dt = SIM_PERIOD_NS * 1e-9
    assert np.allclose(sim.q_arm_order() - q0, np.r_[dt, [0] * 12, -2 * dt])
    js = sim.joint_state()
    assert js.header.stamp_ns == SIM_PERIOD_NS and js.header.seq == 1
    assert js.arms["collector"].velocity_rad_s[6] == -2.0


def test_the_monitor_flags_limits_speeds_and_distances() -> None:
    sc = scene([fruit(1, (0.55, 0.0, 1.05))])  # a fruit on the cutter tip in the ready posture
    mon = SafetyMonitor(sc.obstacles)
    q = KinematicSim().q_arm_order()
    rep = SafetyReport()
    mon.check(q, np.zeros(14), rep, {"self": 0.01, "trunk": 0.03, "fruit": 0.02})
    assert rep.min_distance_m["fruit"] < 0 and any("fruit distance" in v for v in rep.violations)
    rep = SafetyReport()
    q[0] = mon.upper[0] + 0.01
    qd = np.zeros(14)
    qd[5] = mon.vmax[5] * 1.1
    SafetyMonitor().check(q, qd, rep, {})
    assert len(rep.violations) == 2 and rep.max_speed_ratio > 1.09
