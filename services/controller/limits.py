"""The last gate before a command is published: finite, within the velocity limits, and not
driving any joint past a position limit within the coming control period."""

from __future__ import annotations

import numpy as np

VELOCITY_TOL = 1e-6  # relative, on |q̇| ≤ v_max (the QP's own round-off is far below)
POSITION_TOL_RAD = 1e-6  # on q + q̇ dt within [lower, upper]


def check_command(
    names: tuple[str, ...],
    q_rad: np.ndarray,
    qd_rad_s: np.ndarray,
    dt_s: float,
    lower_rad: np.ndarray,
    upper_rad: np.ndarray,
    vmax_rad_s: np.ndarray,
) -> str | None:
    """None when the command is safe to send, else the first problem in words.

    A joint already outside a position limit (a simulator overshoots by a hair) may hold or
    move back in, never further out.
    """
    if len(qd_rad_s) != len(names) or not np.isfinite(qd_rad_s).all():
        return "non-finite or mis-sized velocity command"
    over = np.abs(qd_rad_s) > vmax_rad_s * (1 + VELOCITY_TOL)
    if over.any():
        i = int(np.argmax(over))
        return f"{names[i]}: |{qd_rad_s[i]:.4f}| rad/s over its limit {vmax_rad_s[i]:.4f} rad/s"
    q_next = q_rad + qd_rad_s * dt_s
    up = (q_next > upper_rad + POSITION_TOL_RAD) & (qd_rad_s > 0)
    down = (q_next < lower_rad - POSITION_TOL_RAD) & (qd_rad_s < 0)
    if up.any() or down.any():
        i = int(np.argmax(up | down))
        return (
            f"{names[i]}: would reach {q_next[i]:.4f} rad, "
            f"outside [{lower_rad[i]:.4f}, {upper_rad[i]:.4f}]"
        )
    return None
