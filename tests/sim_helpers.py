"""Helpers of the sim tests: small scenario files, a core, commands for the current tick."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import yaml

from schemas.base import Header
from schemas.robot import ArmJointVelocity, JointVelocityCommand, ToolCommand
from services.robot.model import joint_names
from services.runtime.settings import load_settings
from services.sim import Settings
from services.sim.core import SimCore

HOME_TIP_M = (0.55, 0.0, 1.05)  # cutter tip in the ready posture (services/robot/model.py)


def scenario_file(tmp: Path, **over: Any) -> Path:
    """A tiny lab scenario (few leaves, fast to build and render) with ``over`` merged in."""
    sc: dict[str, Any] = {
        "name": "test",
        "seed": 3,
        "tree": {"extra_branches": 1, "leaf_clusters": 2, "leaves_per_cluster": 4},
        "fruits": [{"position_world_m": [0.6, -0.15, 1.35], "leaf_cover": "none"}],
    }
    sc.update(over)
    p = tmp / f"sc-{abs(hash(repr(sorted(sc.items())))) % 10**8}.yaml"
    p.write_text(yaml.safe_dump(sc))
    return p


def fruit_under_tip(dy_m: float = 0.0, above_m: float = 0.03) -> dict[str, Any]:
    """A fruit whose peduncle passes ``above_m`` under the ready cutter tip (shifted by dy)."""
    r, ratio = 0.04, 0.94
    x, y, z = HOME_TIP_M
    return {
        "position_world_m": [x, y + dy_m, z - above_m - r * ratio],
        "radius_m": r,
        "height_ratio": ratio,
        "leaf_cover": "none",
    }


def core(scenario: Path | str, **settings: Any) -> SimCore:
    return SimCore(load_settings(Settings, {"scenario": str(scenario), **settings}))


def command(
    c: SimCore, velocities: dict[str, float] | None = None, seq: int = 0, stamp: int | None = None
) -> JointVelocityCommand:
    """A command for the sim's current tick: named joints at the given velocities, others 0."""
    v = velocities or {}
    arms = {
        role: ArmJointVelocity(
            names=joint_names(role), velocity_rad_s=tuple(v.get(n, 0.0) for n in joint_names(role))
        )
        for role in ("cutter", "collector")
    }
    h = Header(stamp_ns=c.now_ns() if stamp is None else stamp, seq=seq, source="test")
    return JointVelocityCommand(header=h, arms=arms)


def tool(c: SimCore, action: str = "cut", role: str = "cutter", seq: int = 0) -> ToolCommand:
    h = Header(stamp_ns=c.now_ns(), seq=seq, source="test")
    return ToolCommand(header=h, tool=role, action=action)  # type: ignore[arg-type]


def run_ticks(c: SimCore, n: int, velocities: dict[str, float] | None = None) -> list[Any]:
    """n ticks, commanding ``velocities`` on each; returns every emitted (topic, msg)."""
    out: list[Any] = []
    for i in range(n):
        for group in c.emit():
            out += group
        if velocities is not None:
            out += c.handle("robot/command", command(c, velocities, seq=i))
        c.advance()
    return out


def events(outs: list[Any], kind: str | None = None) -> list[Any]:
    return [m for t, m in outs if t == "sim/events" and (kind is None or m.kind == kind)]


def q_of(c: SimCore) -> np.ndarray:
    return c.q.copy()
