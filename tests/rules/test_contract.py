"""The Rule contract, checked on every rule the registry finds (built-ins and installed plugins)."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from sc2data.labels.registry import Registered, load_registry
from sc2data.rulebase import RULE_ID, blank_frame, is_schema_key, stack, synthetic_batch
from sc2data.schema import Schema, StackBatch

REGISTRY = load_registry()


def test_the_five_builtin_rules_are_registered() -> None:
    builtin = [e.id for e in REGISTRY if e.source.startswith("sc2data ")]
    assert builtin == ["build_scv", "collect_minerals", "build_supply_depot", "build_barracks",
                       "train_marine"]


@pytest.fixture(params=list(REGISTRY), ids=lambda e: e.id)
def entry(request: pytest.FixtureRequest) -> Registered:
    return request.param


def test_declaration(entry: Registered) -> None:
    r = entry.rule
    assert RULE_ID.match(r.id)
    assert isinstance(r.command, str) and r.command.strip() == r.command and r.command
    assert isinstance(r.version, int) and r.version >= 1
    assert r.requires and all(is_schema_key(k) for k in r.requires)
    assert r.__doc__ and sys.modules[r.__module__].__doc__, "a rule's meaning is written down"


@pytest.mark.parametrize("size", [1, 7, 64])
def test_answers_a_bool_per_stack(entry: Registered, size: int) -> None:
    out = entry.rule(synthetic_batch(entry.rule.requires, size, seed=size))
    assert isinstance(out, np.ndarray) and out.dtype == np.bool_ and out.shape == (size,)


def test_rows_are_independent_and_deterministic(entry: Registered) -> None:
    batch = synthetic_batch(entry.rule.requires, 12, seed=3)
    whole = entry.rule(batch)
    halves = [entry.rule(StackBatch({k: a[s] for k, a in batch.arrays.items()}, batch.schema))
              for s in (slice(0, 5), slice(5, 12))]
    assert np.array_equal(whole, np.concatenate(halves))
    assert np.array_equal(whole, entry.rule(batch))


def test_pure_does_not_modify_its_input(entry: Registered) -> None:
    batch = synthetic_batch(entry.rule.requires, 6, seed=1)
    before = {k: a.copy() for k, a in batch.arrays.items()}
    entry.rule(batch)
    assert all(np.array_equal(before[k], batch.arrays[k]) for k in before)


def test_reads_the_full_schema_and_ignores_extra_keys(entry: Registered) -> None:
    schema = Schema.full()
    out = entry.rule(stack([(blank_frame(schema), blank_frame(schema))] * 3, schema))
    assert out.shape == (3,)


def test_builtin_rules_fire_on_nothing_when_nothing_changes(entry: Registered) -> None:
    if not entry.source.startswith("sc2data "):
        pytest.skip("a property of the built-in commands, not of every rule")
    batch = synthetic_batch(entry.rule.requires, 9, seed=5)
    frozen = StackBatch({k: np.repeat(a[:, 1:], 2, axis=1) for k, a in batch.arrays.items()},
                        batch.schema)
    assert not entry.rule(frozen).any()
