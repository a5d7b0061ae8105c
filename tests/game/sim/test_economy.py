"""Mining against the real game: first minerals, income by workers on BuildMarines' 8 fields."""

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
    loops = {seed: first_minerals(seed) for seed in range(6)}
    # Real traces of the same start: first minerals ≈120 loops in. SCVs that start on the
    # mineral side come in first, those on the far side walk round the CC.
    assert all(100 <= n <= 150 for n in loops.values()), loops
    assert min(loops.values()) < max(loops.values())


def per_minute(workers: int) -> float:
    """Steady income per real minute (1,344 loops), over 3 seeds."""
    return statistics.mean(income(workers, seed, 1500, 4500) for seed in range(3)) * 1344


def test_twelve_workers_as_the_real_game() -> None:
    # Real replays: 713 a minute, median of 12-worker windows (32 LotV games, IQR 678-734).
    assert per_minute(12) == pytest.approx(713, rel=0.05)


def test_two_workers_a_field_at_full_rate() -> None:
    # LotV: the first two workers on a field bring 55-63 a minute each; 944 for 16 on 8 fields.
    assert per_minute(16) == pytest.approx(944, rel=0.05)
    assert 55 <= per_minute(16) / 16 <= 63


def test_a_third_worker_adds_little() -> None:
    # A field gives at most ≈143 a minute: 1,144 for 24 workers, and no more beyond.
    full = per_minute(24)
    assert full == pytest.approx(1144, rel=0.05)
    assert 15 <= (full - per_minute(16)) / 8 <= 35  # ≈25 a third worker
    assert per_minute(28) <= full * 1.01


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
