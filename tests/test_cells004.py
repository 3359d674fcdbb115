"""The seed-004 cell verifier (fleet/analysis/cells004.py) on moves made up by hand: what it
must catch and what it must let pass."""

from fleet.analysis.cells004 import Clash, Move, clashes, held


def _judge(moves, starts):
    spans, bad = held(moves, starts)
    return clashes(spans), [b.why for b in bad]


def test_following_one_cell_behind_is_safe_but_entering_before_the_other_is_out_is_not():
    lead = Move(1, 0.0, 1.0, (1, 0), (2, 0))
    assert _judge([lead, Move(2, 1.0, 2.0, (0, 0), (1, 0))], {1: (1, 0), 2: (0, 0)}) == ([], [])
    assert _judge([lead, Move(2, 0.5, 1.5, (0, 0), (1, 0))], {1: (1, 0), 2: (0, 0)}) == (
        [Clash((1, 0), (1, 2), 0.5)], [])


def test_a_swap_and_two_agvs_entering_one_cell_are_clashes():
    swap = [Move(1, 0.0, 1.0, (0, 0), (1, 0)), Move(2, 0.0, 1.0, (1, 0), (0, 0))]
    found, bad = _judge(swap, {1: (0, 0), 2: (1, 0)})
    assert bad == [] and {c.cell for c in found} == {(0, 0), (1, 0)}
    meet = [Move(1, 3.0, 4.0, (0, 0), (1, 0)), Move(2, 3.5, 4.5, (2, 0), (1, 0))]
    assert [c.cell for c in _judge(meet, {1: (0, 0), 2: (2, 0)})[0]] == [(1, 0)]


def test_moves_that_cannot_be_driven_are_named():
    _, bad = _judge([Move(1, 0.0, 1.0, (0, 0), (1, 1)), Move(1, 2.0, 3.0, (5, 5), (5, 6)),
                     Move(7, 0.0, 1.0, (9, 9), (9, 8))], {1: (0, 0)})
    assert bad == ["(0, 0) -> (1, 1) is not one cell in one of four directions",
                   "starts at (5, 5), but the AGV is at (1, 1)", "AGV 7 has no start"]


def test_a_move_begun_before_the_last_one_ended_is_named():
    _, bad = _judge([Move(1, 0.0, 1.0, (0, 0), (1, 0)), Move(1, 0.2, 1.2, (1, 0), (2, 0))],
                    {1: (0, 0)})
    assert bad == ["starts at t=0.2 before the last move ended or ends before it starts"]
