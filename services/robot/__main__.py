"""python -m services.robot [--write]: check or regenerate deploy/robot/ from the generator."""

from __future__ import annotations

import argparse
import sys

from services.robot.model import COLLISIONS_PATH, URDF_PATH
from services.robot.urdf import collisions_json, generate


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m services.robot", description=__doc__)
    ap.add_argument("--write", action="store_true", help="rewrite deploy/robot/")
    args = ap.parse_args(argv)
    files = {URDF_PATH: generate(), COLLISIONS_PATH: collisions_json()}
    if args.write:
        URDF_PATH.parent.mkdir(parents=True, exist_ok=True)
        for path, text in files.items():
            path.write_text(text)
        print(f"wrote {', '.join(str(p) for p in files)}")
        return 0
    stale = [str(p) for p, text in files.items() if not p.exists() or p.read_text() != text]
    if stale:
        print(
            f"out of date: {', '.join(stale)}; run python -m services.robot --write",
            file=sys.stderr,
        )
        return 1
    print("deploy/robot matches the generator")
    return 0


if __name__ == "__main__":
    sys.exit(main())
