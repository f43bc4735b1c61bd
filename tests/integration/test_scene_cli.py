"""`harvest eval scene` end to end on a small scenario: the --json keys, figures that make
sense, and clear refusals."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.helpers import harvest
from tests.sim_helpers import scenario_file

pytestmark = pytest.mark.integration


def test_eval_scene_prints_the_goal_figures_as_json(tmp_path: Path) -> None:
    sc = scenario_file(
        tmp_path,
        fruits=[
            {"position_world_m": [0.6, -0.15, 1.35], "leaf_cover": "none"},
            {"position_world_m": [0.702, -0.25, 1.405], "leaf_cover": "light"},
        ],
    )
    r = harvest(
        "eval",
        "scene",
        "--scenario",
        str(sc),
        "--seeds",
        "0-1",
        "--seconds",
        "0.2",
        "--json",
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)  # nothing else on stdout (pybullet's banner goes to stderr)
    keys = ("center_err_median_m", "center_err_p95_m", "dv_err_median_m", "trunk_err_m")
    for key in (*keys, "range_bias_m", "dh_bias_m"):
        assert isinstance(out[key], float), key
    assert out["seeds"] == [0, 1] and out["frames"] == 2 * 4
    assert out["fruit_estimates"] >= 2 * 4  # fruit 1 at least, every frame
    assert out["center_err_median_m"] < 0.01 and out["trunk_err_m"] < 0.02
    assert abs(out["range_bias_m"]) < 0.01 and out["fruit_estimates_visible"] >= 4


def test_eval_scene_refuses_bad_arguments(tmp_path: Path) -> None:
    r = harvest("eval", "scene", "--scenario", "paper-exp1", "--seeds", "x-y")
    assert r.returncode == 2 and "seeds" in r.stderr
    r = harvest("eval", "scene", "--scenario", str(tmp_path / "none.yaml"), "--seeds", "0")
    assert r.returncode == 2 and "none.yaml" in r.stderr
    r = harvest("eval", "scene", "--scenario", "paper-exp1", "--set", "fruit_method=magic")
    assert r.returncode == 2 and "fruit_method" in r.stderr
