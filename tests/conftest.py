"""Shared fixtures."""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest
from hypothesis import settings

from tests.helpers import BusEnv, make_bus_env, remove

# Hypothesis: the fuzz tests are small by default (tests/contract/test_fuzz.py), big on demand
# with `--hypothesis-profile=fuzz-big` or HARVEST_HYPOTHESIS_PROFILE=fuzz-big.
settings.register_profile("fuzz-big", max_examples=2000, deadline=None)
if os.environ.get("HARVEST_HYPOTHESIS_PROFILE"):
    settings.load_profile(os.environ["HARVEST_HYPOTHESIS_PROFILE"])


@pytest.fixture
def bus_env() -> Iterator[BusEnv]:
    """A private router (unix socket) and namespace; every child process is stopped after."""
    env = make_bus_env()
    try:
        yield env
    finally:
        remove(env)
