"""services/controller/dampers.py: the damper law and its rows."""

from __future__ import annotations

import numpy as np
import pytest

from services.controller.dampers import DamperParams, damper_rows, inactive_rows
from services.controller.distances import DistanceEngine
from services.controller.kinsim import KinematicSim
from services.controller.obstacles import obstacle_arrays
from services.controller.robot import N_FBASE_Q, ControlledRobot
from services.controller.scenarios import fruit, scene
from services.robot.model import URDF_PATH

P = DamperParams(activation_m=0.10, safety_m=0.02, speed_m_s=0.3, margin_m=0.0)
DT = 1 / 120


def test_the_law_is_the_papers_above_d_s() -> None:
    assert P.ddot_min_m_s(0.10, DT) == pytest.approx(-0.3)  # at d_i: approach at ξ
    assert P.ddot_min_m_s(0.06, DT) == pytest.approx(-0.15)
    assert P.ddot_min_m_s(0.02, DT) == 0.0  # at d_s: no approach


def test_below_d_s_the_deficit_is_recovered_in_one_step_at_most_at_xi() -> None:
    assert P.ddot_min_m_s(0.0199, DT) == pytest.approx(0.0001 / DT)
    assert P.ddot_min_m_s(-0.03, DT) == pytest.approx(0.3)
    # continuous at d_s
    assert abs(P.ddot_min_m_s(0.02 - 1e-9, DT) - P.ddot_min_m_s(0.02 + 1e-9, DT)) < 1e-6


def test_the_margin_shifts_d_s_inside_the_law() -> None:
    m = DamperParams(0.10, 0.02, 0.3, margin_m=0.0005)
    assert m.ddot_min_m_s(0.0205, DT) == 0.0


def test_no_pair_gives_one_inactive_row() -> None:
    rows = inactive_rows(21)
    assert rows.active == 0 and rows.A.shape == (1, 21) and rows.b.tolist() == [1.0]


@pytest.fixture(scope="module")
def robot() -> ControlledRobot:
    return ControlledRobot(URDF_PATH)


def test_a_row_predicts_the_change_of_its_distance(robot: ControlledRobot) -> None:
    """First order: A Δq = −Δd for a small joint step (finite differences through coal)."""
    obs = scene([fruit(1, (0.62, 0.0, 1.06))], trunk_xy_m=(0.7, -0.2), trunk_radius_m=0.06)
    arrays = obstacle_arrays(obs.obstacles)
    act = {"self": 0.08, "trunk": 0.2, "fruit": 0.2}
    params = {k: DamperParams(v, 0.01, 0.3) for k, v in act.items()}
    engine = DistanceEngine(robot, cull_m=0.25)
    q0 = KinematicSim().q_arm_order()
    robot.set_q(q0)
    before = engine.compute(arrays, act)
    rows = damper_rows(before.pairs, robot, params, DT)
    assert rows.active == len(before.pairs) >= 3
    rng = np.random.default_rng(0)
    for _ in range(5):
        dq = rng.normal(0, 1e-4, 14)
        robot.set_q(q0 + dq)
        after = engine.compute(arrays, act)
        full = np.zeros(robot.model.nq)
        full[robot.q_idx] = dq
        predicted = -(rows.A @ full)
        d0 = {(p.kind, round(float(p.p1_world_m[0]), 2)): p.distance_m for p in before.pairs}
        # compare the smallest distance of each kind (robust to witness-point bookkeeping)
        for kind in ("fruit", "trunk"):
            i0 = [i for i, p in enumerate(before.pairs) if p.kind == kind]
            k = min(i0, key=lambda i: before.pairs[i].distance_m)
            real = after.min_m[kind] - before.min_m[kind]
            assert real == pytest.approx(predicted[k], abs=2e-6), (kind, d0)
    robot.set_q(q0)


def test_rows_use_configuration_space_columns(robot: ControlledRobot) -> None:
    engine = DistanceEngine(robot, cull_m=0.25)
    robot.set_q(KinematicSim().q_arm_order())
    rep = engine.compute(
        obstacle_arrays(scene([fruit(1, (0.62, 0.0, 1.06))]).obstacles),
        {"self": 0.08, "trunk": 0.2, "fruit": 0.2},
    )
    rows = damper_rows(rep.pairs, robot, {k: P for k in ("self", "trunk", "fruit")}, DT)
    assert rows.A.shape[1] == robot.model.nq == 21
    assert not rows.A[:, :N_FBASE_Q].any()  # the floating base never appears
