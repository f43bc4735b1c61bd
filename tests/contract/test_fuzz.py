"""Bad input at scale: every registered service fed malformed payloads and adversarial but
schema-valid messages (NaN and inf, extreme and negated numbers, inverted and huge boxes, lists
of 10,000 entries, stamps going backwards, duplicated seq). No crash; every case is rejected by
the codec, dropped by the order check, or handled by the core with valid outputs, and counted.

The default run is small (SMALL examples per service, about 300 cases in all); a big run:
``pytest tests/contract/test_fuzz.py --hypothesis-profile=fuzz-big`` (or
HARVEST_HYPOTHESIS_PROFILE=fuzz-big). Targets keep their state across examples (a sim world is
too slow to build per example), which is also more adversarial: a crash message names the input.
"""

from __future__ import annotations

import json
import random
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from services.registry import SERVICE_MODULES
from services.runtime.node import Output
from services.testkit.fuzz import MANY, FuzzTarget, adversarial_doc, fuzz_step, malformed
from services.testkit.fuzz_targets import NO_INPUTS, make_target, seed_pool

STEPS = 6  # fuzz cases per hypothesis example
SMALL = 8  # examples per service in the default run: 8 x 6 cases x 6 services ~ 300 cases


def examples() -> int:
    """The big profile's count when one was chosen, else the small default."""
    n = settings.default.max_examples
    return n if n >= 1000 else SMALL


@pytest.fixture(scope="module")
def pool() -> list[Output]:
    return seed_pool()


@pytest.fixture(scope="module")
def workdir() -> Iterator[Path]:
    with tempfile.TemporaryDirectory(prefix="fuzz-") as d:
        yield Path(d)


@pytest.mark.parametrize("name", list(SERVICE_MODULES))
def test_service_survives_malformed_and_adversarial_input(
    name: str, pool: list[Output], workdir: Path
) -> None:
    target = make_target(name, workdir)
    if isinstance(target, str):
        assert target == NO_INPUTS
        pytest.skip(f"{name}: {target}")
    assert any(t in target.inputs or "**" in target.inputs for t, _ in pool), (
        f"{name}: no seed message of its inputs {target.inputs} (add one to seed_pool)"
    )
    run_cases(target, pool)
    o = target.outcome
    assert o.cases == o.rejected_decode + o.dropped_order + o.handled + len(o.crashes)
    assert o.rejected_decode > 0 and o.handled > 0, o  # both sides were exercised


def run_cases(target: FuzzTarget, pool: list[Output]) -> None:
    @settings(
        max_examples=examples(),
        deadline=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
    )
    @given(rng=st.randoms(use_true_random=False))
    def cases(rng: random.Random) -> None:
        for _ in range(STEPS):
            fuzz_step(target, pool, rng)
        assert not target.outcome.crashes, target.outcome.crashes[:3]

    cases()


def longest_list(doc: object) -> int:
    if isinstance(doc, dict):
        return max((longest_list(v) for v in doc.values()), default=0)
    if isinstance(doc, list | tuple):
        return max([len(doc), *(longest_list(v) for v in doc)])
    return 0


def test_mutations_reach_every_kind_of_bad_input(pool: list[Output]) -> None:
    """The mutators do produce what the issue lists (checked once, seeded)."""
    rng = random.Random(1)
    scene = next(m for t, m in pool if t == "scene/state").model_dump(mode="python")
    kinds: set[str] = set()
    for _ in range(400):
        doc = adversarial_doc(scene, rng)
        if longest_list(doc) == MANY:
            kinds.add("10,000 entries")
        if doc["header"]["stamp_ns"] < scene["header"]["stamp_ns"] or (
            doc["header"]["seq"] != scene["header"]["seq"]
        ):
            kinds.add("header moved")
        if "nan" in repr(doc) or "inf" in repr(doc):
            kinds.add("non-finite")
    assert {"10,000 entries", "non-finite"} <= kinds, kinds
    payload = b'{"header": {"stamp_ns": 5, "seq": 1}, "x": 1.5}'
    broken = {malformed(payload, rng) for _ in range(100)}
    assert b"" in broken or any(len(b) < len(payload) for b in broken)
    assert any(b"NaN" in b for b in broken)


def test_stamps_and_seqs_beyond_64_bits_are_rejected_by_every_codec(pool: list[Output]) -> None:
    """They once validated and crashed the recorder's MCAP writer (found by the fuzz)."""
    from schemas import TOPICS
    from schemas.codec import DecodeError

    seen: set[str] = set()
    for topic, msg in pool:
        if topic in seen or not TOPICS[topic].codec.zenoh_encoding.startswith("application/json"):
            continue
        seen.add(topic)
        for field, value in (("stamp_ns", 10**30), ("seq", 2**64)):
            doc = msg.model_dump(mode="json")
            doc["header"][field] = value
            with pytest.raises(DecodeError):
                TOPICS[topic].codec.decode(json.dumps(doc).encode())
    assert len(seen) >= 8
