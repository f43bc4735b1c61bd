"""Golden JSON Schemas: a schema change without its golden file fails."""

from __future__ import annotations

from pathlib import Path

import pytest

from schemas import export


def test_schemas_match_their_golden_files() -> None:
    changed = export.diff_golden()
    assert not changed, (
        f"schemas changed without their golden files: {changed}; if deliberate "
        "run `python -m schemas.export --write` and commit schemas/golden/"
    )


def test_a_changed_schema_is_detected(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    export.write_golden(tmp_path)
    assert export.diff_golden(tmp_path) == []
    original = export.all_schemas

    def mutated() -> dict:
        s = original()
        s["JointState"]["properties"]["extra_field_m"] = {"type": "number"}
        return s

    monkeypatch.setattr(export, "all_schemas", mutated)
    assert export.diff_golden(tmp_path) == ["JointState.json"]


def test_missing_and_orphan_golden_files_are_reported(tmp_path: Path) -> None:
    export.write_golden(tmp_path)
    (tmp_path / "Detections.json").unlink()
    (tmp_path / "Gone.json").write_text("{}")
    assert export.diff_golden(tmp_path) == ["Detections.json", "Gone.json"]
