"""Run metadata written into the MCAP: how the run was made (settings, stack, code, versions)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from importlib import metadata as importlib_metadata
from pathlib import Path

from services import __version__
from services.registry import service_def
from services.runtime.settings import ServiceSettings, config_hash
from services.supervisor.stack import Stack

PACKAGES = (
    "eclipse-zenoh",
    "mcap",
    "rerun-sdk",
    "torch",
    "opencv-python-headless",
    "placo",
    "python-fcl",
    "pybullet",
    "pydantic",
    "numpy",
)


def git_revision(cwd: Path | None = None) -> str:
    """HEAD's hash, with '+dirty' when the work tree has changes; 'unknown' outside git."""
    try:
        rev = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            cwd=cwd,
            check=True,
            timeout=5,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            cwd=cwd,
            timeout=5,
        ).stdout.strip()
        return rev + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def package_versions() -> dict[str, str]:
    out = {"python": sys.version.split()[0], "orange-harvest": __version__}
    for name in PACKAGES:
        try:
            out[name] = importlib_metadata.version(name)
        except importlib_metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def run_metadata(
    stack: Stack,
    stack_path: Path,
    profile: str | None,
    run_id: str,
    namespace: str,
    settings: dict[str, ServiceSettings],
) -> dict[str, str]:
    """MCAP metadata 'run': str → str; structured values are JSON."""
    specs = {n: service_def(n).spec.model().model_dump(mode="json") for n in settings}
    return {
        "run_id": run_id,
        "namespace": namespace,
        "stack_name": stack.name,
        "stack_file": str(stack_path),
        "profile": profile or "",
        "mode": stack.mode,
        "master": stack.master or "",
        "scenario": stack.scenario,
        "seed": "" if stack.seed is None else str(stack.seed),
        "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "git_revision": git_revision(),
        "versions": json.dumps(package_versions(), sort_keys=True),
        "stack": stack.model_dump_json(),
        "services": json.dumps(
            {n: s.model_dump(mode="json") for n, s in settings.items()}, sort_keys=True
        ),
        "config_hashes": json.dumps(
            {n: config_hash(s) for n, s in settings.items()}, sort_keys=True
        ),
        "specs": json.dumps(specs, sort_keys=True),
    }
