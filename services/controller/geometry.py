"""Rotation helpers for the task-space law: quaternions, log/exp on SO(3), saturation and the
error of an orientation with one rotation axis left free. Pure numpy; no placo."""

from __future__ import annotations

import math

import numpy as np

AXIS_INDEX = {"x": 0, "y": 1, "z": 2}


def quat_xyzw_to_matrix(q: tuple[float, float, float, float] | np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion (x, y, z, w); the caller checks the norm."""
    x, y, z, w = (float(v) for v in q)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quat_xyzw(R: np.ndarray) -> tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) of a rotation matrix, w ≥ 0 (Shepperd's method)."""
    t = float(np.trace(R))
    if t > 0:
        s = 2.0 * math.sqrt(t + 1.0)
        q = ((R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, s / 4)
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1e-300, 1.0 + R[i, i] - R[j, j] - R[k, k]))
        v = [0.0, 0.0, 0.0]
        v[i] = s / 4
        v[j] = (R[j, i] + R[i, j]) / s
        v[k] = (R[k, i] + R[i, k]) / s
        q = (v[0], v[1], v[2], (R[k, j] - R[j, k]) / s)
    sign = -1.0 if q[3] < 0 else 1.0
    return (sign * q[0], sign * q[1], sign * q[2], sign * q[3])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b for 3-vectors (np.cross costs ~18 µs a call; this ~1 µs)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def norm(v: np.ndarray) -> float:
    """Euclidean norm of a small vector (without np.linalg's overhead)."""
    return math.sqrt(float(v @ v))


def skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def exp3(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of the rotation vector ``w`` (axis × angle, rad), Rodrigues."""
    a = norm(w)
    if a < 1e-12:
        return np.eye(3) + skew(w)
    K = skew(w / a)
    return np.eye(3) + math.sin(a) * K + (1 - math.cos(a)) * (K @ K)


def log3(R: np.ndarray) -> np.ndarray:
    """Rotation vector (axis × angle, rad) of ``R``; robust near 0 and π."""
    c = max(-1.0, min(1.0, (float(np.trace(R)) - 1.0) / 2.0))
    a = math.acos(c)
    if a < 1e-9:
        return np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2.0
    if math.pi - a < 1e-6:
        # Near π the antisymmetric part vanishes: take the axis from the symmetric part.
        B = (R + np.eye(3)) / 2.0
        i = int(np.argmax(np.diag(B)))
        axis = B[:, i] / math.sqrt(max(B[i, i], 1e-300))
        return a * axis
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return a * w / (2.0 * math.sin(a))


def saturate(v: np.ndarray, limit: float) -> np.ndarray:
    """``v`` scaled down to norm ``limit`` when longer (direction kept)."""
    n = norm(v)
    return v if n <= limit or n == 0.0 else v * (limit / n)


def axis_alignment_error(axis: np.ndarray, goal_axis: np.ndarray) -> np.ndarray:
    """Smallest rotation vector (rad) turning unit vector ``axis`` onto ``goal_axis``.

    This is the orientation error when rotation about that axis is free: every orientation
    that shares the goal's axis is as good as the goal. Anti-parallel axes turn about any
    perpendicular (a deterministic one).
    """
    c = max(-1.0, min(1.0, float(axis @ goal_axis)))
    x = cross(axis, goal_axis)
    s = norm(x)
    angle = math.atan2(s, c)
    if s > 1e-12:
        return x * (angle / s)
    if c > 0:
        return np.zeros(3)
    perp = cross(axis, np.eye(3)[int(np.argmin(np.abs(axis)))])
    return perp / norm(perp) * math.pi


def orientation_error(R: np.ndarray, R_goal: np.ndarray, free_axis: str | None) -> np.ndarray:
    """World (or parent-frame) rotation vector, rad, from ``R`` towards ``R_goal``.

    With ``free_axis`` ('x', 'y' or 'z' of the goal frame) only the part that aligns that axis
    counts: rotation about it is free. ``exp3(e) @ R`` is then a goal-equivalent orientation.
    """
    if free_axis is None:
        return log3(R_goal @ R.T)
    k = AXIS_INDEX[free_axis]
    return axis_alignment_error(R[:, k], R_goal[:, k])
