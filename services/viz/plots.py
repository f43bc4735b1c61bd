"""Time series: task errors, minimum distances against d_s, joint velocities against their
limits, active dampers, and the solve-time hook."""

from __future__ import annotations

from collections.abc import Mapping

from schemas.control import ControlStatus
from schemas.robot import JointState
from services.viz import paths
from services.viz.out import Out

ERROR_SERIES = (
    ("abs_position_m", "abs_position_error_m"),
    ("rel_position_m", "rel_position_error_m"),
    ("abs_orientation_rad", "abs_orientation_error_rad"),
    ("rel_orientation_rad", "rel_orientation_error_rad"),
)
DISTANCE_SERIES = (
    ("trunk_m", "min_distance_trunk_m"),
    ("fruit_m", "min_distance_fruit_m"),
    ("self_m", "min_distance_self_m"),
)
LIMIT_PATH = f"{paths.JOINT_VELOCITY}/limit"


def log_static(out: Out) -> None:
    """Series styles (static), so that the limit and d_s lines stand out."""
    rr = out.rr
    out.log(
        LIMIT_PATH,
        rr.SeriesLines(colors=[(255, 60, 60), (255, 60, 60)], names=["+limit", "-limit"]),
        static=True,
    )
    out.log(paths.D_S, rr.SeriesLines(colors=[(255, 60, 60)], names=["d_s"]), static=True)


def log_control_status(out: Out, msg: ControlStatus, d_s_m: float) -> None:
    """Errors, minimum distances (only those the controller computed) with d_s, dampers."""
    t = msg.header.stamp_ns
    for name, field in ERROR_SERIES:
        out.scalars(f"{paths.ERRORS}/{name}", t, (getattr(msg, field),))
    for name, field in DISTANCE_SERIES:
        v = getattr(msg, field)
        if v is not None:
            out.scalars(f"{paths.DISTANCES}/{name}", t, (v,))
    out.scalars(paths.D_S, t, (d_s_m,))
    out.scalars(paths.DAMPERS, t, (float(msg.active_dampers),))


def log_joint_velocities(
    out: Out, msg: JointState, limits_rad_s: Mapping[str, float], named: dict[str, tuple[str, ...]]
) -> None:
    """Per arm, each joint's velocity as a fraction of its limit (so the limit is ±1 for all),
    and the ±1 lines; a joint without a known limit is left out. ``named`` remembers the joint
    names each arm's series were given (static names, set again if they change)."""
    t = msg.header.stamp_ns
    for role, arm in msg.arms.items():
        pairs = [
            (n, v / limits_rad_s[n])
            for n, v in zip(arm.names, arm.velocity_rad_s, strict=True)
            if n in limits_rad_s
        ]
        path = f"{paths.JOINT_VELOCITY}/{role}"
        names = tuple(n for n, _ in pairs)
        if named.get(role) != names:
            named[role] = names
            out.log(path, out.rr.SeriesLines(names=[f"{n} q̇/q̇max" for n in names]), static=True)
        out.scalars(path, t, [r for _, r in pairs])
    out.scalars(LIMIT_PATH, t, (1.0, -1.0))


def log_solve_time(out: Out, stamp_ns: int, solve_time_ms: float) -> None:
    """Hook for the controller's QP solve time. Solve time is deliberately not in ControlStatus
    (payloads must be byte-identical between runs); when a diagnostics topic carries it, map
    that topic to this function in core.Converter.handlers."""
    out.scalars(paths.SOLVE_TIME, stamp_ns, (solve_time_ms,))
