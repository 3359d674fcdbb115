"""The reservation table against a naive reference model (hypothesis state machine)."""

import dataclasses
import math

import hypothesis.strategies as st
import pytest
from hypothesis import settings
from hypothesis.stateful import RuleBasedStateMachine, invariant, rule

from fleet.planning.reservations import Amendment, Interval, ReservationTable

INF = math.inf
CELLS = [(0, 0), (0, 1), (1, 0), (1, 1)]
VEHICLES = [1, 2, 3]
times = st.integers(0, 40).map(lambda q: q * 0.25)


@st.composite
def intervals(draw):
    cell = draw(st.sampled_from(CELLS))
    t0 = draw(times)
    t1 = draw(st.one_of(st.just(INF), times.filter(lambda t: t > t0)))
    if t1 <= t0:
        t1 = INF
    return Interval(cell, t0, t1)


class NaiveTable:
    """Every reservation as a loose (vehicle, cell, t0, t1) piece; nothing clever."""

    def __init__(self):
        self.pieces = []

    def overlaps_other(self, vehicle, iv):
        return any(v != vehicle and c == iv.cell and iv.t0 < t1 and t0 < iv.t1
                   for v, c, t0, t1 in self.pieces)

    def commit(self, vehicle, ivs, release_from):
        if any(self.overlaps_other(vehicle, iv) for iv in ivs):
            return False
        if release_from is not None:
            self.release(vehicle, release_from)
        self.pieces += [(vehicle, iv.cell, iv.t0, iv.t1) for iv in ivs]
        return True

    def release(self, vehicle, t):
        kept = []
        for v, c, t0, t1 in self.pieces:
            if v != vehicle:
                kept.append((v, c, t0, t1))
            elif t0 < t:
                kept.append((v, c, t0, min(t1, t)))
        self.pieces = kept

    def owner(self, cell, t):
        owners = {v for v, c, t0, t1 in self.pieces if c == cell and t0 <= t < t1}
        assert len(owners) <= 1
        return owners.pop() if owners else None


def owner_in_table(table, cell, t):
    found = {r.vehicle for r in table.reservations() if r.cell == cell and r.t0 <= t < r.t1}
    assert len(found) <= 1
    return found.pop() if found else None


class TableMatchesModel(RuleBasedStateMachine):
    def __init__(self):
        super().__init__()
        self.table = ReservationTable()
        self.model = NaiveTable()

    @rule(vehicle=st.sampled_from(VEHICLES), ivs=st.lists(intervals(), min_size=1, max_size=4),
          release_from=st.one_of(st.none(), times))
    def commit(self, vehicle, ivs, release_from):
        before = self.table.snapshot()
        written = self.table.commit(vehicle, ivs, release_from)
        accepted = self.model.commit(vehicle, ivs, release_from)
        assert written.ok == accepted
        if not written.ok:
            assert written.conflict_vehicle not in (None, vehicle)
            assert self.table.snapshot() == before  # all or nothing

    @rule(vehicle=st.sampled_from(VEHICLES), iv=intervals())
    def check(self, vehicle, iv):
        other = self.table.conflict(vehicle, iv.cell, iv.t0, iv.t1)
        assert (other is not None) == self.model.overlaps_other(vehicle, iv)

    @rule(vehicle=st.sampled_from(VEHICLES), t=times)
    def release(self, vehicle, t):
        self.table.release(vehicle, t)
        self.model.release(vehicle, t)

    @invariant()
    def same_owner_everywhere(self):
        for cell in CELLS:
            for q in range(0, 44):
                t = q * 0.25 - 0.125
                assert owner_in_table(self.table, cell, t) == self.model.owner(cell, t)
            assert owner_in_table(self.table, cell, 1e9) == self.model.owner(cell, 1e9)

    @invariant()
    def busy_is_what_the_others_hold(self):
        for vehicle in VEHICLES:
            for cell in CELLS:
                held = self.table.busy(vehicle, cell)
                for q in range(0, 44):
                    t = q * 0.25 - 0.125
                    owner = self.model.owner(cell, t)
                    assert any(t0 <= t < t1 for t0, t1 in held) == \
                        (owner not in (None, vehicle))
                for q in range(-1, 42):  # from `after` on: what ends later, on the grid too
                    after = q * 0.25
                    assert self.table.busy(vehicle, cell, after) == \
                        [(t0, t1) for t0, t1 in held if t1 > after]

    @invariant()
    def never_two_vehicles_overlap(self):
        rs = self.table.reservations()
        for a in rs:
            for b in rs:
                if a is not b and a.cell == b.cell:
                    assert not (a.t0 < b.t1 and b.t0 < a.t1), (a, b)

    @invariant()
    def mirror_follows_changes(self):
        mirror = ReservationTable()
        for change in self.table.diff(0):
            mirror.apply(change)
        assert mirror.snapshot() == self.table.snapshot()
        assert ReservationTable.from_snapshot(self.table.snapshot()).snapshot() == \
            self.table.snapshot()


TableMatchesModel.TestCase.settings = settings(max_examples=150, stateful_step_count=30,
                                               deadline=None, derandomize=True)
test_table_matches_model = TableMatchesModel.TestCase


def test_commit_rejects_with_the_conflicting_vehicle_and_cell():
    table = ReservationTable()
    assert table.park(1, [(2, 3)], 10.0).ok
    written = table.commit(2, [Interval((0, 0), 0, 5), Interval((2, 3), 20, 25)])
    assert not written.ok and written.revision == 1
    assert (written.conflict_vehicle, written.conflict_cell) == (1, (2, 3))
    assert written.reason == "cell (2, 3) is held by vehicle 1 over [20, 25)"
    assert table.reservations(2) == []


def test_touching_intervals_of_different_vehicles_are_allowed():
    table = ReservationTable()
    assert table.commit(1, [Interval((0, 0), 0, 5)]).ok
    assert table.commit(2, [Interval((0, 0), 5, 9)]).ok
    assert not table.commit(3, [Interval((0, 0), 4.75, 5.25)]).ok


def test_own_intervals_merge_and_release_cuts():
    table = ReservationTable()
    table.commit(1, [Interval((0, 0), 0, 2), Interval((0, 0), 2, 4), Interval((0, 0), 3, INF)])
    assert [(r.t0, r.t1) for r in table.reservations(1)] == [(0, INF)]
    table.release(1, 2.5)
    assert [(r.t0, r.t1) for r in table.reservations(1)] == [(0, 2.5)]


def test_apply_refuses_out_of_order_change():
    source = ReservationTable()
    source.park(1, [(0, 0)], 0)
    source.park(2, [(1, 1)], 0)
    mirror = ReservationTable()
    with pytest.raises(ValueError, match="revision 2 does not follow"):
        mirror.apply(source.changes[1])


def test_bad_interval_is_named():
    with pytest.raises(ValueError, match=r"cell \(1, 2\)"):
        Interval((1, 2), 5.0, 5.0)


# -- amending: a commit that postpones other vehicles' holdings (seed 002) ---------------------

def overlapping(table: ReservationTable) -> list:
    """Pairs of reservations of different vehicles on one cell over overlapping times,
    recomputed from the table's contents."""
    found = []
    rows = table.reservations()
    for i, a in enumerate(rows):
        for b in rows[i + 1:]:
            if a.cell == b.cell and a.vehicle != b.vehicle and max(a.t0, b.t0) < min(a.t1, b.t1):
                found.append((a, b))
    return found


def crossing_tables():
    """Vehicle 2 crosses cell (5, 0) over [2, 4) and parks at (7, 0); vehicle 1 wants
    (5, 0) over [2, 4) too. Postponed by 2 s, vehicle 2 takes it over [4, 6)."""
    table = ReservationTable()
    route = [(3, 0), (4, 0), (5, 0), (6, 0), (7, 0)]

    def driving(t0):
        ivs = [Interval(c, t0 + k, t0 + k + 2) for k, c in enumerate(route[:-1])]
        return [*ivs, Interval(route[-1], t0 + len(route) - 2, INF)]
    assert table.commit(2, driving(0.0)).ok
    mine = [Interval((5, 1), 0.0, 2.0), Interval((5, 0), 1.0, 4.0), Interval((5, -1), 3.0, INF)]
    return table, mine, Amendment(2, 0.0, tuple(driving(2.0)))


def test_a_commit_that_postpones_another_vehicle_is_taken_whole():
    table, mine, later = crossing_tables()
    assert not table.commit(1, mine).ok  # without the amendment vehicle 2 is in the way
    result = table.commit(1, mine, 0.0, [later])
    assert result.ok and result.revision == 5  # two releases, the amendment, the commit
    assert [(c.op, c.vehicle) for c in table.changes[1:]] == [
        ("commit", 1), ("commit", 2), ("commit", 2), ("commit", 1)]
    assert table.conflict(9, (5, 0), 4.0, 6.0) == 2 and table.conflict(9, (5, 0), 1.0, 4.0) == 1
    assert overlapping(table) == []
    replayed = ReservationTable()
    for change in table.changes:  # no revision between holds two overlapping reservations
        replayed.apply(change)
        assert overlapping(replayed) == []


def test_an_amendment_that_does_not_only_postpone_is_refused_and_nothing_changes():
    table, mine, later = crossing_tables()
    before = table.reservations()
    earlier = Amendment(2, 0.0, tuple(Interval(iv.cell, iv.t0 - 2.5, iv.t1)
                                      for iv in later.intervals))
    elsewhere = Amendment(2, 0.0, (*later.intervals, Interval((9, 9), 5.0, 6.0)))
    cases = {
        "taken earlier": earlier,
        "holds cells": elsewhere,
    }
    for reason, amendment in cases.items():
        result = table.commit(1, mine, 0.0, [amendment])
        assert not result.ok and reason in result.reason
    assert "names the committing vehicle" in table.commit(1, mine, 0.0, [
        Amendment(1, 0.0, ())]).reason
    assert "before the commit's own release" in table.commit(1, mine, 1.0, [
        dataclasses.replace(later, release_from=0.5)]).reason
    assert table.reservations() == before and table.revision == 1


def test_an_amended_schedule_may_not_run_into_a_third_vehicle_or_the_committer():
    table, mine, later = crossing_tables()
    assert table.commit(3, [Interval((6, 0), 5.0, 5.5)]).ok  # in the postponed way
    result = table.commit(1, mine, 0.0, [later])
    assert not result.ok and result.conflict_vehicle == 3 and result.conflict_cell == (6, 0)
    table, mine, later = crossing_tables()
    late_mine = [*mine, Interval((4, 0), 3.0, 3.5)]  # where vehicle 2 now waits
    result = table.commit(1, late_mine, 0.0, [later])
    assert not result.ok and result.conflict_cell == (4, 0)
    assert table.revision == 1


def test_no_revision_between_the_steps_of_an_amend_holds_an_overlap():
    """Two vehicles postponed one after the other on one cell: each new hold overlaps the
    other's old one, so both are released before either takes its new one."""
    table = ReservationTable()
    x = (0, 0)
    assert table.commit(2, [Interval(x, 0.0, 10.0)]).ok
    assert table.commit(3, [Interval(x, 10.0, 20.0)]).ok
    result = table.commit(1, [], None, [Amendment(2, 0.0, (Interval(x, 0.0, 15.0),)),
                                        Amendment(3, 0.0, (Interval(x, 15.0, 25.0),))])
    assert result.ok
    replayed = ReservationTable()
    for change in table.changes:
        replayed.apply(change)
        assert overlapping(replayed) == []
    assert table.changes[-1].vehicle == 1  # the committer's step comes last, even empty


def test_an_amendment_may_not_open_a_gap_where_the_vehicle_stands_nor_move_goods():
    table = ReservationTable()
    x = (0, 0)
    assert table.commit(2, [Interval(x, 0.0, 10.0), Interval((0, 1), 10.0, 20.0)]).ok
    gap = Amendment(2, 5.0, (Interval(x, 9.0, 10.0), Interval((0, 1), 10.0, 20.0)))
    result = table.commit(1, [Interval(x, 5.0, 9.0)], 5.0, [gap])
    assert not result.ok and "left for a while" in result.reason
    assert table.commit(0, [Interval((4, 4), 0.0, INF)]).ok  # goods on a stack
    goods = Amendment(0, 1.0, (Interval((4, 4), 3.0, INF),))
    assert "is no vehicle" in table.commit(1, [Interval((4, 4), 1.0, 2.0)], 1.0, [goods]).reason
    whole = Amendment(2, 5.0, (Interval(x, 0.0, 12.0), Interval((0, 1), 12.0, 22.0)))
    assert table.commit(1, [Interval((9, 9), 5.0, 6.0)], 5.0, [whole]).ok  # the past too
