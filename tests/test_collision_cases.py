"""Seed 002's 26 collision cases (Figures 11-13, the figures lost; seed pack note A.7 item 8,
A-COL-1), each constructed as two timed routes on a micro layout that meet as the captions
and Section 5 describe.

For each case: the routes are legal moves on the lanes; `first_collision` fires the condition
the paper assigns (node (5)-(6), swap (7)-(9), crossing diagonals (10)-(11)), recomputed here
from the routes and arrival times with the code's δ of two cell-times; `settle` resolves it
without deadlock, whichever of the two plans last, by the rule of A.4.6 with the right AGV
waiting at the right node; and the settled schedules are apart, recomputed from
`Schedule.intervals()`. The table is docs/agv-002.md's "Collision cases"
(`test_the_docs_table_is_this_one` keeps the two the same).

The figures being lost, the geometry is a reconstruction from the captions: Figure 11 draws
AGV 1 coming east (from the west) and AGV 2 from the south, (a)-(e), or from the east,
(f)-(j), the order within each a guess save (d) and (j), which 5.2 fixes; Figure 12's T
is the one on micro-t's left edge, the transverse channel the horizontal one; Figure 13's
channel is micro-channel's bottom one, slots above it (the near lane westbound, the far one
eastbound). Every route ends where its scenario does (no dwell at its last node). Where the
code cannot fire the stated condition, the row says so ("DEVIATION") and tests what it does.
"""

from __future__ import annotations

import itertools
import re
from dataclasses import dataclass
from pathlib import Path

import pytest

from fleet.planning.lane_conflicts import Area, CollisionKind, first_collision, settle
from fleet.planning.lane_schedule import Schedule, timed
from fleet.world.lanes import (
    allowed_moves,
    collision_areas,
    diagonal_moves,
    direction_between,
    places,
)
from fleet.world.layout_file import load_layout

NODE, SWAP, DIAGONAL = CollisionKind.NODE, CollisionKind.SWAP, CollisionKind.DIAGONAL
SECONDS_PER_CELL = 1.0
DELTA = 2 * SECONDS_PER_CELL  # lane_conflicts: bodies touching, the note's δ = 2 cell-times

HORIZONTAL_WAITS = "horizontal waits"  # (13), and its T counterpart (CHOICE)
LATER_WAITS = "later clears, waits"  # (14), (16), and the channel's (17) without (18)
LEAVING_N = "channel: leaving N waits in N"  # (17)-(18)

# micro-cross: the crossroad is (4..5, 4..5); AGV 1 comes east on row 4, AGV 2 north on
# column 5 or west on row 5. S straight, L left, R right.
EB_S = ((2, 4), (3, 4), (4, 4), (5, 4), (6, 4), (7, 4))
EB_L = ((2, 4), (3, 4), (4, 4), (5, 5), (5, 6), (5, 7))  # NE across the crossroad
EB_R = ((2, 4), (3, 4), (4, 4), (4, 3), (4, 2))
NB_S = ((5, 2), (5, 3), (5, 4), (5, 5), (5, 6), (5, 7))
NB_L = ((5, 2), (5, 3), (5, 4), (4, 5), (3, 5), (2, 5))  # NW
NB_R = ((5, 2), (5, 3), (5, 4), (6, 4), (7, 4))
WB_S = ((7, 5), (6, 5), (5, 5), (4, 5), (3, 5), (2, 5))
WB_L = ((7, 5), (6, 5), (5, 5), (4, 4), (4, 3), (4, 2))  # SW
WB_R = ((7, 5), (6, 5), (5, 5), (5, 6), (5, 7))

# micro-t: the left-edge T is (1..2, 4..5): longitudinal lanes column 1 south and column 2
# north, the transverse channel's westbound row 5 comes in from the east (its eastbound row
# 4 leads out). No west arm: a northbound AGV onto the T's other diagonal turns back south.
T_NB_S = ((2, 2), (2, 3), (2, 4), (2, 5), (2, 6), (2, 7))
T_NB_U = ((2, 2), (2, 3), (2, 4), (1, 5), (1, 4), (1, 3), (1, 2))  # NW, back south
T_SB_S = ((1, 7), (1, 6), (1, 5), (1, 4), (1, 3), (1, 2))
T_SB_L = ((1, 7), (1, 6), (1, 5), (2, 4), (3, 4), (4, 4))  # SE, out east
T_WB_R = ((4, 5), (3, 5), (2, 5), (2, 6), (2, 7))  # north
T_WB_L = ((4, 5), (3, 5), (2, 5), (1, 4), (1, 3), (1, 2))  # SW, south

# micro-channel: row 1 westbound (the near lane, slots (2..5, 2) above it), row 0 eastbound.
C_WB = ((5, 1), (4, 1), (3, 1), (2, 1), (1, 1))
C_EB = ((1, 0), (2, 0), (3, 0), (4, 0), (5, 0), (6, 0))
OUT_3_W = ((3, 2), (3, 1), (2, 1), (1, 1))  # out of slot (3, 2), west on the near lane
OUT_3_E = ((3, 2), (3, 1), (3, 0), (4, 0), (5, 0))  # across the near lane, east on the far
OUT_5_W = ((5, 2), (5, 1), (4, 1), (3, 1), (2, 1), (1, 1))
IN_3_ACROSS = ((2, 0), (3, 0), (3, 1), (3, 2))  # off the far lane, across the near, in


@dataclass(frozen=True)
class Case:
    id: str
    layout: str
    geometry: str  # one line: approaches, who goes straight or turns, where they meet
    first: tuple  # AGV 1's cells
    t1: float  # when AGV 1 starts
    second: tuple  # AGV 2's
    t2: float
    kind: CollisionKind  # the condition that fires here
    waiter: int  # the AGV that waits
    wait_at: tuple[int, int]  # and where
    rule: str  # the rule named (a part of WaitOrder.rule)
    paper: CollisionKind | None = None  # the paper's condition when it is not `kind`


CASES = (
    # Figure 11: crossroad; (a)-(e) perpendicular, (f)-(j) opposite. (13): the one from H
    # waits at its last node before R; (14): the later to clear waits there.
    Case("fig11-a", "micro-cross", "E straight x N straight, cross at (5,4)",
         EB_S, 0, NB_S, 1, NODE, 1, (3, 4), "R: " + HORIZONTAL_WAITS),
    Case("fig11-b", "micro-cross", "E straight x N turning right (east), merge at (5,4)",
         EB_S, 0, NB_R, 1, NODE, 1, (3, 4), "R: " + HORIZONTAL_WAITS),
    Case("fig11-c", "micro-cross", "E straight x N turning left (NW diagonal), meet at (5,4)",
         EB_S, 0, NB_L, 1, NODE, 1, (3, 4), "R: " + HORIZONTAL_WAITS),
    Case("fig11-d", "micro-cross",
         "E left (NE) x N left (NW), diagonals cross in R; read as 5.2 does (10)-(11), not "
         "5.1's 'only (j) between nodes'; simultaneous (else bodies touch earlier)",
         EB_L, 0, NB_L, 0, DIAGONAL, 1, (3, 4), "R: " + HORIZONTAL_WAITS),
    Case("fig11-e", "micro-cross", "E left (NE) x N straight, N ahead, meet at (5,5)",
         EB_L, 1, NB_S, 0, NODE, 1, (3, 4), "R: " + HORIZONTAL_WAITS),
    Case("fig11-f", "micro-cross", "E straight x W left (SW), meet at (4,4), W later",
         EB_S, 1, WB_L, 0, NODE, 2, (6, 5), "R: " + LATER_WAITS),
    Case("fig11-g", "micro-cross", "E left (NE) x W straight, meet at (5,5), E later",
         EB_L, 0, WB_S, 0.5, NODE, 1, (3, 4), "R: " + LATER_WAITS),
    Case("fig11-h", "micro-cross", "E left (NE) x W right (north), merge at (5,5), W later",
         EB_L, 0, WB_R, 1.5, NODE, 2, (6, 5), "R: " + LATER_WAITS),
    Case("fig11-i", "micro-cross", "E right (south) x W left (SW), merge at (4,4), W later",
         EB_R, 0, WB_L, 0, NODE, 2, (6, 5), "R: " + LATER_WAITS),
    Case("fig11-j", "micro-cross",
         "E left (NE) x W left (SW), swap along one diagonal; simultaneous (else bodies touch "
         "earlier), τ tie: the higher id waits",
         EB_L, 0, WB_L, 0, SWAP, 2, (6, 5), "R: " + LATER_WAITS),
    # Figure 12: T on the left edge; (a)-(e) transverse x longitudinal (longitudinal
    # priority, CHOICE), (f)-(h) both longitudinal (16): the later waits before T.
    Case("fig12-a", "micro-t", "N straight x W turning right (north), merge at (2,5)",
         T_NB_S, 0, T_WB_R, 1, NODE, 2, (3, 5), "T: " + HORIZONTAL_WAITS),
    Case("fig12-b", "micro-t", "N straight x W turning left (SW diagonal), meet at (2,5)",
         T_NB_S, 0, T_WB_L, 1, NODE, 2, (3, 5), "T: " + HORIZONTAL_WAITS),
    Case("fig12-c", "micro-t", "S straight x W turning left (SW diagonal), merge at (1,4)",
         T_SB_S, 0, T_WB_L, 0, NODE, 2, (3, 5), "T: " + HORIZONTAL_WAITS),
    Case("fig12-d", "micro-t",
         "S left (SE, out east) x W left (SW, south), diagonals cross in T; simultaneous",
         T_SB_L, 0, T_WB_L, 0, DIAGONAL, 2, (3, 5), "T: " + HORIZONTAL_WAITS),
    Case("fig12-e", "micro-t",
         "N turning back south (NW) x W left (SW), diagonals cross in T; simultaneous",
         T_NB_U, 0, T_WB_L, 0, DIAGONAL, 2, (3, 5), "T: " + HORIZONTAL_WAITS),
    Case("fig12-f", "micro-t", "N straight x S left (SE), meet at (2,4), S later",
         T_NB_S, 0.5, T_SB_L, 0, NODE, 2, (1, 6), "T: " + LATER_WAITS),
    Case("fig12-g", "micro-t", "S straight x N turning back south (NW), merge at (1,5), N later",
         T_SB_S, 0.5, T_NB_U, 0, NODE, 2, (2, 3), "T: " + LATER_WAITS),
    Case("fig12-h", "micro-t",
         "S left (SE) x N turning back south (NW), swap along one diagonal; simultaneous, "
         "τ tie: the higher id waits",
         T_SB_L, 0, T_NB_U, 0, SWAP, 2, (2, 3), "T: " + LATER_WAITS),
    # Figure 13: channel beside shelves. (17)-(18): the one coming out of N waits in N;
    # otherwise the later to clear waits at α-1.
    Case("fig13-a", "micro-channel",
         "W straight on the near lane x out of slot (3,2) turning west, meet at (3,1)",
         C_WB, 0, OUT_3_W, 1, NODE, 2, (3, 2), LEAVING_N),
    Case("fig13-b", "micro-channel",
         "W straight on the near lane x out of slot (3,2) across it to go east, meet at (3,1)",
         C_WB, 0, OUT_3_E, 1, NODE, 2, (3, 2), LEAVING_N),
    Case("fig13-c", "micro-channel",
         "E straight on the far lane x out of slot (3,2) across the near lane to go east, "
         "meet at (3,0), the leaver later (waits in N: fixed, see docs)",
         C_EB, 0, OUT_3_E, 0.5, NODE, 2, (3, 2), LEAVING_N),
    Case("fig13-d", "micro-channel",
         "off the far lane across the near one into slot (3,2) x W straight on the near "
         "lane, meet at (3,1), W later; node (5)-(6), 5.2's first list (a)-(d)",
         IN_3_ACROSS, 0, C_WB, 0.5, NODE, 2, (4, 1), LATER_WAITS),
    Case("fig13-e", "micro-channel",
         "out of slots (5,2) and (3,2), both turning west, meet at (3,1); DEVIATION: node, "
         "not (10)-(11): no diagonal move off a junction",
         OUT_5_W, 0, OUT_3_W, 2, NODE, 2, (3, 2), LEAVING_N, DIAGONAL),
    Case("fig13-f", "micro-channel",
         "out of slot (5,2) west x out of (3,2) across to go east, meet at (3,1); "
         "DEVIATION: node, not (10)-(11): no diagonal move off a junction",
         OUT_5_W, 0, OUT_3_E, 2, NODE, 2, (3, 2), LEAVING_N, DIAGONAL),
    Case("fig13-g", "micro-channel",
         "out of slots (2,2) and (4,2), both across to go east, meet at (4,0), the second "
         "later (waits in N: fixed, see docs)",
         ((2, 2), (2, 1), (2, 0), (3, 0), (4, 0), (5, 0), (6, 0)), 0,
         ((4, 2), (4, 1), (4, 0), (5, 0), (6, 0)), 2.5, NODE, 2, (4, 2), LEAVING_N),
    Case("fig13-h", "micro-t",
         "W into slot (4,3) across the eastbound lane x E into slot (4,6) across the "
         "westbound, swap on (4,5)-(4,4) (micro-t: slots both sides); τ tie: higher id",
         ((5, 5), (4, 5), (4, 4), (4, 3)), 0, ((3, 4), (4, 4), (4, 5), (4, 6)), 0,
         SWAP, 2, (3, 4), LATER_WAITS),
)


@pytest.fixture(scope="module")
def layouts():
    return {name: load_layout(name) for name in ("micro-cross", "micro-t", "micro-channel")}


def lane_legal(layout, cells) -> bool:
    """Every move one the lanes allow: along a lane (orthogonal moves in its direction,
    turning only on junction cells; diagonals cutting an allowed turn), out of a place at the
    start and into one at the end through its access cell, straight across one cell more."""
    at = {place.cell: place for _, place in places(layout)}
    last = len(cells) - 2
    for k, (p, q) in enumerate(itertools.pairwise(cells)):
        if p in at or q in at:
            if not (k == 0 and q in at[p].access if p in at
                    else k == last and p in at[q].access):
                return False
            continue
        across = ((k == 1 and cells[0] in at and _in_line(cells[0], p, q))  # out, far lane
                  or (k == last - 1 and cells[-1] in at and _in_line(p, q, cells[-1])))  # in
        if across and {p, q} <= layout.lane_directions.keys():
            continue
        if p[0] != q[0] and p[1] != q[1]:
            name = ("N" if q[1] > p[1] else "S") + ("E" if q[0] > p[0] else "W")
            if name not in diagonal_moves(layout, p):
                return False
        elif direction_between(p, q) not in allowed_moves(layout, p):
            return False
    return True


def _in_line(a, b, c) -> bool:
    return (b[0] - a[0], b[1] - a[1]) == (c[0] - b[0], c[1] - b[1])


def paper_condition(kind: CollisionKind, a: Schedule, alpha: int, b: Schedule, beta: int
                    ) -> bool:
    """The paper's condition of that kind, recomputed at nodes α, β with δ = 2 cell-times."""
    if abs(a.arrivals[alpha] - b.arrivals[beta]) > DELTA:  # (5), (7), (10)
        return False
    if kind is NODE:  # (6)
        return a.cells[alpha] == b.cells[beta]
    a0, a1, b0, b1 = a.cells[alpha], a.cells[alpha + 1], b.cells[beta], b.cells[beta + 1]
    if kind is SWAP:  # (8), (9)
        return a1 == b0 and a0 == b1
    return ((a0[0] + a1[0], a0[1] + a1[1]) == (b0[0] + b1[0], b0[1] + b1[1])  # (11)
            and not (a1 == b0 and a0 == b1))


def apart(a: Schedule, b: Schedule) -> bool:
    """No cell held by both over overlapping times, from the reservations."""
    return not any(p.cell == q.cell and max(p.t0, q.t0) < min(p.t1, q.t1)
                   for p, q in itertools.product(a.intervals(), b.intervals()))


def test_the_table_has_the_26_cases():
    assert [c.id for c in CASES] == ([f"fig11-{x}" for x in "abcdefghij"]
                                     + [f"fig12-{x}" for x in "abcdefgh"]
                                     + [f"fig13-{x}" for x in "abcdefgh"])
    deviating = [c.id for c in CASES if c.paper is not None]
    assert deviating == ["fig13-e", "fig13-f"]
    assert all("DEVIATION" in c.geometry for c in CASES if c.paper is not None)


def test_lane_legal_refuses_what_the_lanes_do_not_allow(layouts):
    cross, channel = layouts["micro-cross"], layouts["micro-channel"]
    assert lane_legal(cross, EB_S) and not lane_legal(cross, tuple(reversed(EB_S)))
    assert not lane_legal(cross, ((2, 4), (3, 4), (4, 4), (4, 5)))  # north on a south lane
    assert not lane_legal(cross, ((2, 4), (3, 5)))  # a lane change off a junction
    assert not lane_legal(channel, ((3, 1), (3, 2), (4, 2)))  # a slot only at the ends
    assert not lane_legal(channel, ((3, 2), (4, 1)))  # out of a slot diagonally
    assert not lane_legal(channel, ((3, 2), (3, 1), (3, 0), (2, 0)))  # west on an east lane
    assert lane_legal(channel, OUT_3_E) and lane_legal(channel, IN_3_ACROSS)


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_collision_case(case: Case, layouts):
    layout = layouts[case.layout]
    cell_areas = collision_areas(layout)
    assert lane_legal(layout, case.first) and lane_legal(layout, case.second)
    one = timed(1, case.first, case.t1, SECONDS_PER_CELL, dwell_at_end=0.0)
    two = timed(2, case.second, case.t2, SECONDS_PER_CELL, dwell_at_end=0.0)

    # (1) the condition fires, with the kind the paper assigns (or the row's deviation)
    c = first_collision(one, two)
    assert c is not None and c.kind is case.kind
    assert paper_condition(case.kind, one, c.alpha, two, c.beta)
    assert first_collision(two, one).kind is case.kind  # either way round

    # (2) settled by the rule, whichever plans last: the right AGV waits at the right node
    schedules = {1: one, 2: two}
    for own, other in ((one, two), (two, one)):
        settled = settle(own, {other.vehicle: other}, cell_areas, now=0.0)
        assert settled.deadlock is None and settled.waits
        assert case.rule in settled.waits[0].rule
        for wait in settled.waits:
            assert wait.vehicle == case.waiter
            assert schedules[case.waiter].cells[wait.node] == case.wait_at
        after = {**schedules, **settled.schedules}
        assert after[3 - case.waiter] == schedules[3 - case.waiter]  # the other drives on
        assert after[case.waiter].cells == schedules[case.waiter].cells

        # (3) apart once settled
        assert apart(after[1], after[2])

    waited_in = cell_areas[case.wait_at]
    if HORIZONTAL_WAITS in case.rule:  # never inside the junction: on its horizontal lane
        assert waited_in is Area.HORIZONTAL
        assert cell_areas[schedules[case.waiter].cells[0]] is Area.HORIZONTAL  # came from H
    elif case.rule == LEAVING_N:
        assert waited_in is Area.OFF_CHANNEL and schedules[case.waiter].cells[0] == case.wait_at
    else:  # the one that clears its collision node later waits (ties: the higher id)
        i = {1: c.alpha, 2: c.beta}
        clears = {v: (schedules[v].arrivals[i[v] + 1], v) for v in (1, 2)}
        assert max(clears, key=clears.get) == case.waiter
        assert waited_in not in (Area.CROSSROAD, Area.T_CROSSROAD)


def test_the_docs_table_is_this_one():
    text = (Path(__file__).parent.parent / "docs" / "agv-002.md").read_text()
    rows = {m.group(1): m.group(0) for m in re.finditer(r"^\| (fig1[123]-[a-j]) \|.*$", text,
                                                        re.M)}
    assert sorted(rows) == sorted(c.id for c in CASES)
    for c in CASES:
        row = rows[c.id]
        assert f"AGV {c.waiter} at ({c.wait_at[0]}, {c.wait_at[1]})" in row, c.id
        assert c.kind.value in row, c.id
        assert ("DEVIATION" in row) == (c.paper is not None), c.id
