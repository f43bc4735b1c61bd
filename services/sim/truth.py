"""Ground truth of a frame from the renderer's labels: per-fruit visibility, boxes, occluders."""

from __future__ import annotations

import numpy as np

from schemas.sim import FruitTruth, FruitTruthState
from services.sim.render.renderer import FruitMask, RenderOutput
from services.sim.render.scene import KINDS

BoxT = tuple[float, float, float, float]


def _box(mask: np.ndarray, v0: int, u0: int) -> BoxT | None:
    """Box around the true pixels (pixel centres at integer coordinates)."""
    rows = np.nonzero(mask.any(axis=1))[0]
    if len(rows) == 0:
        return None
    cols = np.nonzero(mask.any(axis=0))[0]
    return (
        float(u0 + cols[0] - 0.5),
        float(v0 + rows[0] - 0.5),
        float(u0 + cols[-1] + 0.5),
        float(v0 + rows[-1] + 0.5),
    )


def fruit_pixels(
    out: RenderOutput, fm: FruitMask | None
) -> tuple[float, BoxT | None, BoxT | None, dict[str, float]]:
    """(visible fraction, visible box, amodal box, hidden-by shares) of one fruit."""
    if fm is None or fm.mask.size == 0 or not fm.mask.any():
        return 0.0, None, None, {}
    v0, v1, u0, u1 = fm.rect
    lab = out.label[v0:v1, u0:u1]
    visible = (lab == fm.obj) & fm.mask
    n_all = int(fm.mask.sum())
    n_vis = int(visible.sum())
    hidden = lab[fm.mask & ~visible]
    shares: dict[str, float] = {}
    if len(hidden):
        kinds = np.bincount(out.kind_of[hidden], minlength=len(KINDS))
        for k in np.nonzero(kinds)[0]:
            shares[KINDS[int(k)]] = round(float(kinds[k]) / n_all, 6)
    return round(n_vis / n_all, 6), _box(visible, v0, u0), _box(fm.mask, v0, u0), shares


def fruit_truth(
    fruit_id: int,
    pos: np.ndarray,
    quat: tuple,
    semi_axes: tuple[float, float, float],
    peduncle: np.ndarray,
    state: FruitTruthState,
    pixels: tuple[float, BoxT | None, BoxT | None, dict[str, float]],
) -> FruitTruth:
    vf, box, amodal, hidden = pixels
    return FruitTruth(
        fruit_id=fruit_id,
        position_world_m=_v3(pos),
        orientation_xyzw=(float(quat[0]), float(quat[1]), float(quat[2]), float(quat[3])),
        semi_axes_m=semi_axes,
        peduncle_world_m=_v3(peduncle),
        visible_fraction=vf,
        box_xyxy_px=box,
        amodal_box_xyxy_px=amodal,
        hidden_by=hidden,  # type: ignore[arg-type]
        state=state,
    )


def _v3(p: np.ndarray) -> tuple[float, float, float]:
    return (float(p[0]), float(p[1]), float(p[2]))
