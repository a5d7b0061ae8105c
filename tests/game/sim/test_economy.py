"""Mining against real-game traces of the same Terran start: first minerals and income per loop."""

from __future__ import annotations

import statistics

import pytest

from sc2data.game.sim import mapdata as md
from sc2data.game.sim.game import Game


def first_minerals(seed: int) -> int:
    g = Game(seed)
    loop = 0
    while g.collected == 0:
        loop += 1
        g.advance(loop)
    return loop


def income(workers: int, seed: int = 0, start: int = 1000, end: int = 4000) -> float:
    """Minerals per loop over [start, end) with ``workers`` SCVs mining from loop 0."""
    g = Game(seed)
    for _ in range(workers - md.START_WORKERS):
        g._spawn_scv(g.cc, 0.0)
    g.advance(start)
    c0 = g.collected
    g.advance(end)
    return (g.collected - c0) / (end - start)


def test_first_minerals_about_120_loops() -> None:
    loops = {first_minerals(seed) for seed in range(6)}
    assert min(loops) == pytest.approx(120, abs=12)  # SCVs on the mineral side
    assert max(loops) <= 180  # SCVs on the far side walk round the CC first


def test_income_with_12_to_14_scvs() -> None:
    mean = statistics.mean(income(n) for n in (12, 13, 14))
    assert mean == pytest.approx(0.52, abs=0.04)


def test_income_at_saturation() -> None:
    assert income(16) == pytest.approx(0.63, abs=0.04)
    assert income(24) < income(16) * 1.25  # a third worker per field adds little


def test_one_worker_per_field_at_a_time() -> None:
    g = Game(0)
    for _ in range(20):
        g._spawn_scv(g.cc, 0.0)
    for loop in range(1, 2000, 7):
        g.advance(loop)
        for p in g.patches:
            miners = [u for u in g.units.values() if u.patch is p and u.phase == 2]
            assert len(miners) <= 1


def test_minerals_come_in_fives_to_the_cc() -> None:
    g = Game(1)
    g.advance(2000)
    returned = [e for e in g.events if e.kind == "returned"]
    assert g.collected == 5 * len(returned)
    assert g.minerals == md.START_MINERALS + g.collected
    assert sum(md.MINERAL_AMOUNT - p.minerals for p in g.patches) == g.collected + \
        sum(u.cargo for u in g.units.values())
