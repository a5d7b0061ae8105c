"""build_supply_depot on hand-built frames: new depots fire; walking, dying, lowering don't."""

from __future__ import annotations

import numpy as np

from sc2data._pysc2 import units
from sc2data.rulebase import SCREEN_PX_PER_UNIT as K
from sc2data.rulebase import blank_frame, paint_disk, pixel_count, stack
from sc2data.rules.build_supply_depot import BuildSupplyDepot

UT = "screen/unit_type"
DEPOT, LOWERED = int(units.Terran.SupplyDepot), int(units.Terran.SupplyDepotLowered)
MARINE, SCV, BARRACKS = int(units.Terran.Marine), int(units.Terran.SCV), int(units.Terran.Barracks)
DEPOT_R, BARRACKS_R, SMALL_R = 1.125 * K, 1.8125 * K, 0.375 * K
rule = BuildSupplyDepot()


def fires(prev: dict, cur: dict) -> bool:
    return bool(rule(stack([(prev, cur)]))[0])


def with_depot(center: tuple[float, float] = (30, 20), value: int = DEPOT) -> dict:
    f = blank_frame()
    paint_disk(f, UT, center, DEPOT_R, value)
    return f


def test_new_depot_on_empty_ground_fires() -> None:
    assert fires(blank_frame(), with_depot())


def test_new_lowered_depot_fires() -> None:
    assert fires(blank_frame(), with_depot(value=LOWERED))


def test_new_depot_under_its_builder_fires() -> None:
    prev = blank_frame()
    paint_disk(prev, UT, (30, 20), SMALL_R, SCV)
    cur = with_depot()
    paint_disk(cur, UT, (31, 20), SMALL_R, SCV)
    assert fires(prev, cur)


def test_depot_clipped_at_screen_edge_fires() -> None:
    cur = with_depot(center=(0.5, 20))
    assert pixel_count(stack([(blank_frame(), cur)]).layer(UT), [DEPOT])[0, 1] < 20
    assert fires(blank_frame(), cur)


def test_nothing_happening_does_not_fire() -> None:
    assert not fires(blank_frame(), blank_frame())
    assert not fires(with_depot(), with_depot())


def test_depot_cancelled_or_finished_does_not_fire() -> None:
    assert not fires(with_depot(), blank_frame())  # cancelled: pixels vanish
    done = with_depot()
    done["screen/unit_hit_points"][10:30, 20:40] = 400  # finishing changes hit points, not type
    assert not fires(with_depot(), done)


def test_lowering_a_depot_does_not_fire() -> None:
    assert not fires(with_depot(value=DEPOT), with_depot(value=LOWERED))


def test_units_walking_off_a_depot_do_not_fire() -> None:
    prev = with_depot()
    for c in [(28, 18), (31, 18), (28, 21), (31, 21)]:  # four units standing on it
        paint_disk(prev, UT, c, SMALL_R, MARINE if c[0] < 30 else SCV)
    cur = with_depot()
    counts = pixel_count(stack([(prev, cur)]).layer(UT), [DEPOT])[0]
    assert counts[1] - counts[0] >= 8  # the paper's literal "depot pixels rose" would fire here
    assert not fires(prev, cur)


def test_unit_dying_on_a_depot_does_not_fire() -> None:
    prev = with_depot()
    paint_disk(prev, UT, (30, 20), SMALL_R, MARINE)
    assert not fires(prev, with_depot())


def test_new_barracks_is_not_a_depot() -> None:
    cur = blank_frame()
    paint_disk(cur, UT, (30, 20), BARRACKS_R, BARRACKS)
    assert not fires(blank_frame(), cur)


def test_two_events_in_one_stack() -> None:
    # A second depot is placed while a marine steps onto the first one.
    prev = with_depot((15, 20))
    cur = with_depot((15, 20))
    paint_disk(cur, UT, (40, 30), DEPOT_R, DEPOT)
    paint_disk(cur, UT, (15, 20), SMALL_R, MARINE)
    assert fires(prev, cur)
    # Two depots placed at once: still one answer, yes.
    two = with_depot((15, 20))
    paint_disk(two, UT, (40, 30), DEPOT_R, DEPOT)
    assert fires(blank_frame(), two)


def test_vectorised_over_a_batch() -> None:
    pairs = [(blank_frame(), with_depot()), (blank_frame(), blank_frame()),
             (with_depot(), blank_frame()), (blank_frame(), with_depot((50, 40)))]
    out = rule(stack(pairs))
    assert out.dtype == np.bool_ and out.tolist() == [True, False, False, True]
