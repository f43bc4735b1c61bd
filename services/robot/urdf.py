"""Generates the robot's URDF and self-collision pairs from services.robot.model.

Only cylinders, boxes and spheres (pinocchio's URDF parser drops capsules), a small inertial on
every link (pybullet would give frame-only links 1 kg), joint names carrying the arm role.

    python -m services.robot            # check that deploy/robot/ matches this generator
    python -m services.robot --write    # regenerate deploy/robot/
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from schemas.base import ARM_ROLES, ArmRole
from services.robot.model import (
    CAMERA_FRAME,
    LWR_AXES,
    LWR_LINK_RADIUS_M,
    LWR_OFFSETS_M,
    LWR_POS_LIMIT_DEG,
    LWR_VEL_LIMIT_DEG_S,
    MOUNT,
    SIDE,
    TOOLS,
    Mount,
    ToolGeometry,
)

COLOURS = {
    "body": (0.75, 0.75, 0.78, 1),
    "arm": (0.95, 0.55, 0.1, 1),
    "dark": (0.2, 0.2, 0.22, 1),
    "tool": (0.1, 0.1, 0.1, 1),
    "basket": (0.95, 0.85, 0.2, 1),
    "camera": (0.1, 0.1, 0.3, 1),
}


def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def rpy_of(R: np.ndarray) -> tuple[float, float, float]:
    """URDF roll-pitch-yaw (R = Rz(yaw) Ry(pitch) Rx(roll))."""
    pitch = math.asin(-max(-1.0, min(1.0, R[2, 0])))
    if abs(math.cos(pitch)) > 1e-9:
        roll = math.atan2(R[2, 1], R[2, 2])
        yaw = math.atan2(R[1, 0], R[0, 0])
    else:  # gimbal lock: put everything in yaw
        roll, yaw = 0.0, math.atan2(-R[0, 1], R[1, 1])
    return roll, pitch, yaw


def shoulder_rotation(role: ArmRole, m: Mount) -> np.ndarray:
    """Arm base orientation: its z axis points sideways (left arm +y, right arm -y), turned
    forward by ``shoulder_tilt_deg``."""
    side = SIDE[role]
    droop = rot_x(side * math.radians(m.shoulder_droop_deg))
    return rot_z(-side * math.radians(m.shoulder_tilt_deg)) @ droop @ rot_x(-side * math.pi / 2)


def camera_optical_rotation(m: Mount) -> np.ndarray:
    """Optical frame (z forward, x right, y down) pitched down by ``camera_pitch_down_deg``."""
    optical = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]], dtype=float)  # columns: x, y, z
    return rot_y(math.radians(m.camera_pitch_down_deg)) @ optical


def _f(v: float) -> str:
    return f"{v:.6g}" if abs(v) > 1e-12 else "0"


def _xyz(v: tuple[float, ...] | np.ndarray) -> str:
    return " ".join(_f(float(x)) for x in v)


@dataclass
class _Urdf:
    lines: list[str] = field(default_factory=list)

    def link(
        self,
        name: str,
        mass: float = 0.001,
        shapes: list[str] | None = None,
        colour: str = "body",
        collide: bool = True,
        visual: bool = True,
    ) -> None:
        i = max(mass * 1e-2, 1e-6)
        self.lines.append(f'  <link name="{name}">')
        self.lines.append(
            f'    <inertial><mass value="{_f(mass)}"/><inertia ixx="{_f(i)}" '
            f'ixy="0" ixz="0" iyy="{_f(i)}" iyz="0" izz="{_f(i)}"/></inertial>'
        )
        for shape in shapes or []:
            if visual:
                self.lines.append(f'    <visual>{shape}<material name="{colour}"/></visual>')
            if collide:
                self.lines.append(f"    <collision>{shape}</collision>")
        self.lines.append("  </link>")

    def fixed(
        self,
        name: str,
        parent: str,
        child: str,
        xyz: tuple[float, ...] | np.ndarray,
        rpy: tuple[float, ...] = (0, 0, 0),
    ) -> None:
        self.lines.append(
            f'  <joint name="{name}" type="fixed"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{_xyz(xyz)}" '
            f'rpy="{_xyz(rpy)}"/></joint>'
        )


def cylinder(
    r: float, length: float, xyz: tuple[float, ...] = (0, 0, 0), rpy: tuple[float, ...] = (0, 0, 0)
) -> str:
    return (
        f'<origin xyz="{_xyz(xyz)}" rpy="{_xyz(rpy)}"/><geometry><cylinder '
        f'radius="{_f(r)}" length="{_f(length)}"/></geometry>'
    )


def box(
    size: tuple[float, ...], xyz: tuple[float, ...] = (0, 0, 0), rpy: tuple[float, ...] = (0, 0, 0)
) -> str:
    return (
        f'<origin xyz="{_xyz(xyz)}" rpy="{_xyz(rpy)}"/><geometry><box size="{_xyz(size)}"/>'
        f"</geometry>"
    )


def sphere(r: float, xyz: tuple[float, ...] = (0, 0, 0)) -> str:
    return f'<origin xyz="{_xyz(xyz)}"/><geometry><sphere radius="{_f(r)}"/></geometry>'


def _body(u: _Urdf, m: Mount) -> None:
    u.link("base_link", 60.0, [box((0.6, 0.55, 0.7), (0, 0, 0.35))], "dark")
    u.link("torso", 20.0, [box((0.26, 0.34, 0.55), (0, 0, 0.275))])
    u.fixed("torso_fix", "base_link", "torso", (-0.05, 0, 0.7))
    u.link("shoulders", 5.0, [box((0.16, 2 * m.shoulder_y_m - 0.1, 0.14))])
    u.fixed("shoulders_fix", "torso", "shoulders", (m.shoulder_x_m + 0.05, 0, m.shoulder_z_m - 0.7))
    u.link("head", 2.0, [sphere(0.09)])
    cx, cy, cz = m.camera_xyz_m
    u.fixed("head_fix", "torso", "head", (cx - 0.06 + 0.05, cy, cz - 0.7))
    u.link("camera_link", 0.07, [box((0.025, 0.09, 0.025))], "camera", collide=False)
    u.fixed("camera_fix", "head", "camera_link", (0.06, 0, 0))
    u.link(CAMERA_FRAME)
    u.fixed(
        "camera_optical_fix",
        "camera_link",
        CAMERA_FRAME,
        (0, 0, 0),
        rpy_of(camera_optical_rotation(m)),
    )


def _arm(u: _Urdf, role: ArmRole, m: Mount, t: ToolGeometry) -> None:
    side = SIDE[role]
    base = f"{role}_base"
    r0 = LWR_LINK_RADIUS_M[0]
    u.link(base, 2.0, [cylinder(r0, LWR_OFFSETS_M[0], (0, 0, LWR_OFFSETS_M[0] / 2))], "arm")
    u.fixed(
        f"{role}_mount",
        "shoulders",
        base,
        (0.0, side * m.shoulder_y_m, 0.0),
        rpy_of(shoulder_rotation(role, m)),
    )
    parent = base
    for i in range(7):
        name, link = f"{role}_j{i + 1}", f"{role}_link{i + 1}"
        length = LWR_OFFSETS_M[i + 1] if i < 6 else 0.02
        shapes = [cylinder(LWR_LINK_RADIUS_M[i], length, (0, 0, length / 2))]
        u.link(link, 2.5 if i < 6 else 0.3, shapes, "arm")
        lim, vel = math.radians(LWR_POS_LIMIT_DEG[i]), math.radians(LWR_VEL_LIMIT_DEG_S[i])
        u.lines.append(
            f'  <joint name="{name}" type="revolute"><parent link="{parent}"/>'
            f'<child link="{link}"/><origin xyz="0 0 {_f(LWR_OFFSETS_M[i])}" rpy="0 0 0"/>'
            f'<axis xyz="{_xyz(LWR_AXES[i])}"/><limit lower="{_f(-lim)}" upper="{_f(lim)}" '
            f'effort="176" velocity="{_f(vel)}"/><dynamics damping="0.5"/></joint>'
        )
        parent = link
    if role == "cutter":
        _cutter_tool(u, t)
    else:
        _collector_tool(u, t)


def _cutter_tool(u: _Urdf, t: ToolGeometry) -> None:
    L, r = t.cutter_shaft_length_m, t.cutter_shaft_radius_m
    u.link(
        "cutter_tool",
        0.4,
        [cylinder(r, L, (0, 0, L / 2)), box((0.006, 0.03, 0.04), (0, 0, L - 0.02))],
        "tool",
    )
    u.fixed("cutter_tool_fix", "cutter_link7", "cutter_tool", (0, 0, t.flange_gap_m))
    u.link("cutter_tip")
    u.fixed("cutter_tip_fix", "cutter_tool", "cutter_tip", (0, 0, L))


def _collector_tool(u: _Urdf, t: ToolGeometry) -> None:
    """A shaft along the flange axis, then a dish whose normal is the tool's -x axis: with the
    tool pointing forward the dish opens upwards (the paper's θ_r = π/2 between the tools)."""
    L, r, R = t.collector_shaft_length_m, t.collector_shaft_radius_m, t.basket_radius_m
    u.link("collector_tool", 0.3, [cylinder(r, L, (0, 0, L / 2))], "tool")
    u.fixed("collector_tool_fix", "collector_link7", "collector_tool", (0, 0, t.flange_gap_m))
    shapes = [cylinder(R, t.basket_floor_m, (0, 0, -t.basket_floor_m / 2))]
    h, n = t.basket_rim_height_m, t.basket_rim_segments
    seg = 2 * R * math.tan(math.pi / n)
    for k in range(n):
        a = 2 * math.pi * k / n
        shapes.append(box((0.006, seg, h), (R * math.cos(a), R * math.sin(a), h / 2), (0, 0, a)))
    u.link("basket", 0.3, shapes, "basket")
    # Dish frame: z = dish normal = tool -x, x = tool z (forward), centre R past the shaft.
    u.fixed("basket_fix", "collector_tool", "basket", (0, 0, L + R), (0, -math.pi / 2, 0))
    u.link("basket_center")
    u.fixed("basket_center_fix", "basket", "basket_center", (0, 0, 0))
    # One solid cylinder around the dish for the controller's collision model (13 shapes would
    # mean 13x the distance pairs). The sim turns its collisions off: fruit must fall *into*
    # the dish, whose floor and rim segments are what pybullet collides with.
    u.link(
        BASKET_HULL,
        0.001,
        [cylinder(R + 0.005, h + t.basket_floor_m, (0, 0, (h - t.basket_floor_m) / 2))],
        "basket",
        visual=False,
    )
    u.fixed("basket_hull_fix", "basket", BASKET_HULL, (0, 0, 0))


BASKET_HULL = "basket_hull"


def generate(m: Mount = MOUNT, t: ToolGeometry = TOOLS) -> str:
    u = _Urdf()
    _body(u, m)
    for role in ARM_ROLES:
        _arm(u, role, m, t)
    colours = "\n".join(
        f'  <material name="{k}"><color rgba="{_xyz(v)}"/></material>' for k, v in COLOURS.items()
    )
    return (
        '<?xml version="1.0"?>\n'
        "<!-- Generated by services/robot/urdf.py (python -m services.robot, write option); "
        'do not edit. -->\n<robot name="bazar">\n'
        + colours
        + "\n"
        + "\n".join(u.lines)
        + "\n</robot>\n"
    )


def collision_pairs() -> list[list[str]]:
    """Arm–arm pairs (forearm, wrist, tool, basket) and arm–body pairs (upper arm and beyond
    against torso, head and base). Adjacent links are never paired."""
    far = {r: [f"{r}_link{i}" for i in (4, 5, 6, 7)] + [f"{r}_tool"] for r in ARM_ROLES}
    far["collector"].append(BASKET_HULL)
    body = ["torso", "head", "base_link"]
    pairs = [[a, b] for a in far["cutter"] for b in far["collector"]]
    for r in ARM_ROLES:
        pairs += [[a, b] for a in [f"{r}_link3", *far[r]] for b in body]
    return pairs


def collisions_json() -> str:
    return json.dumps(collision_pairs(), indent=1) + "\n"
