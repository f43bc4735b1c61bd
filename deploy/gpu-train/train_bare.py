"""`harvest train detector` on a machine with torch, OpenCV, numpy and rich but without the
rest of the stack (zenoh, pydantic-settings...): a rented GPU box, say.

    python deploy/gpu-train/train_bare.py [the options of harvest train detector]

The service packages' __init__ modules import the runtime and the bus (zenoh); training needs
none of it, so those packages are entered without running their __init__. pydantic and
pycocotools are still needed (the scripted scenes' schemas, the AP). Decoded images are kept in
memory in every batch worker (a GPU machine has the RAM; it saves the JPEG decoding).
"""

from __future__ import annotations

import sys
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
# Runs again in each spawned batch worker (it re-imports this file as __mp_main__).
for _name in ("services.detector", "services.testkit", "services.cli"):
    if _name not in sys.modules:
        _pkg = types.ModuleType(_name)
        _pkg.__path__ = [str(ROOT / _name.replace(".", "/"))]
        sys.modules[_name] = _pkg

from services.detector import data as _data  # noqa: E402

_load_rgb, _images = _data.Sample.load_rgb, {}


def _load_rgb_kept(self: _data.Sample) -> object:
    if self.path not in _images:
        _images[self.path] = _load_rgb(self)
    return _images[self.path]


_data.Sample.load_rgb = _load_rgb_kept  # type: ignore[method-assign]


def main(argv: list[str] | None = None) -> int:
    import argparse

    from services.cli import train

    parser = argparse.ArgumentParser(prog="train_bare.py")
    train.add_parsers(parser.add_subparsers(dest="cmd"))
    rest = sys.argv[1:] if argv is None else argv
    sys.argv = ["harvest", "train", "detector", *rest]  # what the weights' meta records
    args = parser.parse_args(sys.argv[1:])
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
