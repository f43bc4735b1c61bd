"""JSON Schema export: one golden file per message model under schemas/golden/.

python -m schemas.export            # check: exit 1 and list what changed
python -m schemas.export --write    # regenerate the golden files after a deliberate change
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from schemas.codec import canonical_json
from schemas.topics import STATUS_MODEL, TOPICS

GOLDEN_DIR = Path(__file__).with_name("golden")


def all_schemas() -> dict[str, dict[str, Any]]:
    """Schema name → JSON Schema for every topic's message and for the status reply."""
    out = {t.schema_name: t.codec.json_schema() for t in TOPICS.values()}
    out[STATUS_MODEL.__name__] = STATUS_MODEL.model_json_schema()
    return dict(sorted(out.items()))


def diff_golden(golden_dir: Path = GOLDEN_DIR) -> list[str]:
    """Names of schemas whose golden file is missing, different or orphaned."""
    current = {f"{n}.json": canonical_json(s) for n, s in all_schemas().items()}
    on_disk = {p.name: p.read_text() for p in golden_dir.glob("*.json")}
    changed = [n for n, text in current.items() if on_disk.get(n) != text]
    orphans = [n for n in on_disk if n not in current]
    return sorted(changed + orphans)


def write_golden(golden_dir: Path = GOLDEN_DIR) -> None:
    golden_dir.mkdir(parents=True, exist_ok=True)
    current = {f"{n}.json": canonical_json(s) for n, s in all_schemas().items()}
    for p in golden_dir.glob("*.json"):
        if p.name not in current:
            p.unlink()
    for name, text in current.items():
        (golden_dir / name).write_text(text)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--write", action="store_true", help="rewrite the golden files")
    args = ap.parse_args(argv)
    if args.write:
        write_golden()
        print(f"wrote {len(all_schemas())} schemas to {GOLDEN_DIR}")
        return 0
    changed = diff_golden()
    if changed:
        print("schemas differ from their golden files: " + ", ".join(changed), file=sys.stderr)
        print("if the change is deliberate: python -m schemas.export --write", file=sys.stderr)
        return 1
    print(f"{len(all_schemas())} schemas match their golden files")
    return 0


if __name__ == "__main__":
    sys.exit(main())
