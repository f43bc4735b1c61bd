"""`harvest eval detector`, `harvest eval tracker`, `harvest bench detector|tracker`: real runs,
--json."""

from __future__ import annotations

import json
from pathlib import Path

from tests.helpers import harvest
from tests.unit.test_detector import write_dataset


def test_eval_detector_json_keys_and_bad_data(tmp_path: Path) -> None:
    data = write_dataset(tmp_path, 3, 30)
    r = harvest("eval", "detector", "--data", str(data), "--backend", "hsv", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    for key in ("ap50", "ap50_95", "ap30", "precision", "recall", "ms_per_frame"):
        assert isinstance(out[key], float), key
    assert out["ap50"] > 0.8  # flat orange discs on leaves: the colour baseline's home ground
    assert out["ap30"] >= out["ap50"] and 0.8 < out["box_width_ratio"] < 1.25
    r = harvest("eval", "detector", "--data", str(data), "--backend", "hsv")
    assert r.returncode == 0 and "AP30" in r.stdout, r.stderr
    r = harvest("eval", "detector", "--data", str(tmp_path / "none.json"))
    assert r.returncode == 1 and "not found" in r.stderr


def test_eval_tracker_json_keys_and_unknown_scenario() -> None:
    r = harvest(
        "eval",
        "tracker",
        "--scenario",
        "scripted-sweep",
        "--seeds",
        "0",
        "--backend",
        "hsv",
        "--json",
    )
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    for key in ("id_correct_occluded", "id_correct_clear", "hota", "idf1", "mota"):
        assert 0.0 <= out[key] <= 1.0, key
    assert isinstance(out["id_switches"], int) and out["frames"] == 150
    r = harvest("eval", "tracker", "--scenario", "nowhere", "--seeds", "0")
    assert r.returncode == 1 and "scripted-sweep" in r.stderr


def test_bench_detector_names_the_cpu_kernels_it_ran_on() -> None:
    r = harvest("bench", "detector", "--frames", "3", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["detector"].startswith("net:v1-") and out["frames"] == 3
    import torch

    assert out["cpu"] == torch.backends.cpu.get_cpu_capability()  # e.g. AVX2, AVX512
    assert out["ms_median"] > 0.0
