"""Seed 004's rule verifier (fleet/analysis/traffic004.py), written apart from the planner's
rule module: both derivations of the note's Table 3 agree on every cell of paper004, and
the verifier names what breaks them."""

import pytest

from fleet.analysis.traffic004 import (
    DOWN,
    LEFT,
    RIGHT,
    UP,
    Drive,
    breaches,
    directions,
    yielding_breaches,
)
from fleet.analysis.verdicts004 import judge, rules_floor
from fleet.mission.tracking004 import Moved, Paused
from fleet.planning.rules004 import Kind, Task, allowed
from fleet.world.floor004 import Floor004Shape, build, paper004

FLOOR = paper004()
RULES = rules_floor(FLOOR)


@pytest.mark.parametrize("task", list(Task))
def test_the_verifier_and_the_planner_read_table_3_alike_on_every_cell(task):
    cells = [xy for xy, kind in FLOOR.kinds.items() if kind in (Kind.FLOOR, Kind.SLOT)]
    for xy in cells:
        home = xy if task.loaded and FLOOR.kind(xy) is Kind.SLOT else None
        assert directions(RULES, task.value, xy, home) == set(allowed(FLOOR.grid, task, xy, home))


def test_moves_against_the_rules_slots_and_lanes_are_named():
    # Row 4 runs right and column 10 (not an aisle, even) up: an empty AGV may go right or up.
    assert directions(RULES, "M1", (10, 4), None) == {RIGHT, UP}
    slot, home = FLOOR.slots[0].xy, FLOOR.slots[1].xy  # side by side in a block
    assert home == (slot[0] + 1, slot[1]) and FLOOR.kind((slot[0], slot[1] - 1)) is Kind.FLOOR
    lane = FLOOR.stations[0].waiting[0]
    drives = [
        Drive(1, 0.0, (10, 4), (9, 4), "M1", False, False, None),  # left on a right-hand row
        Drive(2, 0.0, (10, 4), (9, 4), "M1", False, True, None),  # relaxed: allowed
        Drive(3, 0.0, (slot[0], slot[1] - 1), slot, "M3", True, False, home),  # foreign slot
        Drive(4, 0.0, (10, 4), (10, 3), "M2", True, True, home),  # relaxed while loaded
        Drive(6, 0.0, (10, 4), (12, 4), "M1", False, False, None),  # two cells at once
        Drive(5, 0.0, FLOOR.stations[0].entrance, lane, "M1", False, False, None),
    ]
    found = {b.vehicle: b.what for b in breaches(RULES, drives)}
    assert set(found) == {1, 3, 4, 5, 6}
    assert "against the rules" in found[1] and "not its shelf's home" in found[3]
    assert "relaxed while loaded" in found[4] and "station lane" in found[5]
    assert found[6] == "(10, 4) -> (12, 4) is not one cell"
    assert DOWN not in directions(RULES, "M1", (0, 6), None) == {RIGHT}
    assert directions(RULES, "M4", (1, 6), None) == {LEFT, UP}


def test_a_loaded_agv_that_gives_way_to_an_empty_one_is_named():
    loads = {1: [(5.0, True)], 2: []}
    assert yielding_breaches([(9.0, 1, 2)], [(9.0, 1)], loads)[0].vehicle == 1
    assert yielding_breaches([(9.0, 2, 1)], [(9.0, 2)], loads) == []
    assert yielding_breaches([(4.0, 1, 2)], [(4.0, 1)], loads) == []  # not loaded yet


MICRO = build(Floor004Shape(blocks_across=2, double_rows=2, stations=1, piles_per_side=1,
                            block_width=3, transit_rows=2), "micro004")


@pytest.mark.parametrize("events, start, named", [
    ([Paused(1, 0.0, 2.0, (2, 7), "lift"),
      Moved(1, 1.0, 2.0, (2, 7), (2, 6), Task.DELIVER, True, False)], (2, 7),
     "drives while lift"),
    ([Moved(1, 0.0, 1.0, (5, 11), (5, 12), Task.FETCH, False, True)], (5, 11),
     "not a cell to drive on"),
    ([Moved(1, 0.0, 1.0, (2, 0), (2, -1), Task.FETCH, False, True)], (2, 0),
     "not a cell to drive on"),
    ([Paused(1, 0.0, 2.0, (6, 11), "lift"),
      Moved(1, 3.0, 4.0, (6, 11), (6, 12), Task.DELIVER, True, False)], (6, 11),
     "not along a station's route"),
    # Still carrying the shelf it lifted, though the moves say empty: into a foreign slot.
    ([Paused(1, 0.0, 2.0, (2, 7), "lift"),
      Moved(1, 2.0, 3.0, (2, 7), (2, 6), Task.DELIVER, True, False),
      Moved(1, 3.0, 4.0, (2, 6), (3, 6), Task.DELIVER, False, False),
      Moved(1, 4.0, 5.0, (3, 6), (3, 7), Task.DELIVER, False, False)], (2, 7),
     "loaded into slot (3, 7)"),
])
def test_the_judge_reads_what_the_agvs_did_not_what_their_moves_say(events, start, named):
    verdict = judge(MICRO, events, {1: start})
    said = [b.why for b in verdict.bad_moves] + [b.what for b in verdict.rule_breaches]
    assert any(named in s for s in said), said


def test_a_loaded_agv_stepping_aside_for_an_empty_one_is_named_whenever_it_replans():
    loads = {1: [(0.0, True)]}
    # Met at t=3, gave way at t=6 (two loaded wait first; one loaded must never).
    assert yielding_breaches([(3.0, 1, 2)], [(6.0, 1)], loads)[0].what == \
        "loaded, gave way to empty AGV 2"
