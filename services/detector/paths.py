"""Where the detector's files live: committed weights, and the shared real-photo data set."""

from __future__ import annotations

import os
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
REPO_ROOT = PACKAGE_DIR.parents[1]
DEFAULT_WEIGHTS = PACKAGE_DIR / "weights" / "orange_net.pt"


def real_data_dir() -> Path:
    """oranges_real: $HARVEST_REAL_DATA, else ../shared/data/oranges_real beside the repo."""
    env = os.environ.get("HARVEST_REAL_DATA")
    return Path(env) if env else REPO_ROOT.parent / "shared" / "data" / "oranges_real"
