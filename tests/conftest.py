"""Shared fixtures."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.helpers import BusEnv, make_bus_env, remove


@pytest.fixture
def bus_env() -> Iterator[BusEnv]:
    """A private router (unix socket) and namespace; every child process is stopped after."""
    env = make_bus_env()
    try:
        yield env
    finally:
        remove(env)
