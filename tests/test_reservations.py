"""The reservation table against a naive reference model (hypothesis state machine)."""

import math

import hypothesis.strategies as st
import pytest
from hypothesis import settings
from hypothesis.stateful import RuleBasedStateMachine, invariant, rule

from fleet.planning.reservations import Interval, ReservationTable

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
