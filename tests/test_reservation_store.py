"""The reservation service's state machine and journal (no network here; the process is tested
in test_reservation_service.py)."""

import dataclasses
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fleet.planning.reservations import ReservationTable
from fleet.wire.convert import change_from_wire, intervals_from_wire
from fleet.wire.protocol import (
    CommitRequest,
    ProtocolError,
    ReleaseRequest,
    Reply,
    SnapshotRequest,
    WireChange,
    body_of,
)
from fleet.wire.protocol import build_message as build
from reservation.journal import Journal, JournalError
from reservation.store import ReservationStore

INF = math.inf


def commit(rid, vehicle, cells, t0=0.0, t1=10.0, release_from=None):
    return CommitRequest(rid, vehicle, [(c, r, t0, t1) for c, r in cells], release_from)


def test_commit_is_atomic_and_a_conflict_names_the_holder():
    store = ReservationStore()
    assert store.handle(commit("a", 1, [(0, 0), (0, 1)])).reply == Reply("a", True, 1)
    out = store.handle(commit("b", 2, [(5, 5), (0, 1)], t0=5.0, t1=6.0))
    assert out.reply.ok is False and out.reply.conflict_vehicle == 1
    assert out.reply.conflict_cell == [0, 1] and "held by vehicle 1" in out.reply.reason
    assert out.published == [] and store.revision == 1
    assert store.table.conflict(9, (5, 5), 0, INF) is None  # nothing of b's commit applied


def test_a_retried_request_is_applied_once():
    store = ReservationStore()
    first = store.handle(commit("same", 1, [(0, 0)]))
    again = store.handle(commit("same", 1, [(0, 0)]))
    assert again.reply == first.reply and again.published == [] and store.revision == 1
    refused = store.handle(commit("x", 2, [(0, 0)]))
    assert store.handle(commit("x", 2, [(0, 0)])).reply == refused.reply


def test_bad_intervals_are_refused_with_a_reason():
    out = ReservationStore().handle(commit("bad", 1, [(0, 0)], t0=5.0, t1=5.0))
    assert out.reply.ok is False and "must have t0 < t1" in out.reply.reason


def test_snapshot_and_diff_let_a_mirror_follow(tmp_path):
    store = ReservationStore()
    store.handle(commit("a", 1, [(0, 0)]))
    mirror_rev = store.revision
    store.handle(commit("b", 2, [(1, 1)], t1=INF))
    store.handle(ReleaseRequest("c", 1, 3.0))
    diff = store.handle(SnapshotRequest(mirror_rev)).reply
    assert [c["revision"] for c in diff.changes] == [2, 3]
    mirror = ReservationTable()
    mirror.commit(1, intervals_from_wire([(0, 0, 0.0, 10.0)]))
    for body in diff.changes:
        mirror.apply(change_from_wire(build(WireChange, body)))
    assert mirror.reservations() == store.table.reservations()
    full = store.handle(SnapshotRequest()).reply
    assert full.revision == 3 and sorted(full.reservations) == sorted(
        (r.vehicle, *r.cell, r.t0, r.t1) for r in store.table.reservations())


def test_a_snapshot_after_an_instant_holds_only_what_holds_then():
    store = ReservationStore()
    store.handle(commit("a", 1, [(0, 0), (0, 1)], t0=0.0, t1=INF))
    store.handle(ReleaseRequest("b", 1, 4.0, [(0, 0)]))  # (0, 0) held [0, 4): past at 5
    store.handle(commit("c", 2, [(2, 2)], t0=1.0, t1=5.0))  # ends at 5: past at 5, not at 4.5
    store.handle(commit("d", 2, [(2, 2)], t0=8.0, t1=9.0))  # still to come at 5
    at5 = store.handle(SnapshotRequest(held_after=5.0)).reply
    assert at5.revision == store.revision and not at5.diff
    assert at5.reservations == [(1, 0, 1, 0.0, INF), (2, 2, 2, 8.0, 9.0)]
    at45 = store.handle(SnapshotRequest(held_after=4.5)).reply.reservations
    assert at45 == [(1, 0, 1, 0.0, INF), (2, 2, 2, 1.0, 5.0), (2, 2, 2, 8.0, 9.0)]
    # what a plan at 5 reads is the same in the small table as in the whole one
    small = ReservationTable()
    for vehicle, col, row, t0, t1 in at5.reservations:
        small.commit(vehicle, intervals_from_wire([(col, row, t0, t1)]))
    for cell in [(0, 0), (0, 1), (2, 2), (3, 3)]:
        for t in (5.0, 8.5, 100.0):
            assert small.conflict(7, cell, t, t + 0.5) == store.table.conflict(
                7, cell, t, t + 0.5)


def test_restart_from_the_journal_gives_the_same_table(tmp_path):
    path = tmp_path / "journal.msgpack"
    store = ReservationStore(path)
    store.handle(commit("a", 1, [(0, 0), (0, 1)], t1=INF))
    store.handle(commit("b", 2, [(3, 3)]))
    store.handle(commit("c", 3, [(0, 0)]))  # refused: not journaled
    store.handle(ReleaseRequest("d", 1, 4.0))
    store.close()
    again = ReservationStore(path)
    assert again.table.reservations() == store.table.reservations()
    assert again.revision == 3 and again.torn_bytes == 0
    assert again.handle(commit("b", 2, [(3, 3)])).reply == Reply("b", True, 2)  # remembered


def test_a_torn_last_record_is_cut_and_nothing_before_it_is_lost(tmp_path):
    path = tmp_path / "journal.msgpack"
    store = ReservationStore(path)
    for k in range(5):
        store.handle(commit(f"r{k}", k + 1, [(k, 0)]))
    store.close()
    whole = path.read_bytes()
    path.write_bytes(whole[:-3])  # killed in the middle of the last write
    again = ReservationStore(path)
    assert again.revision == 4 and again.torn_bytes > 0
    assert again.handle(commit("r5", 9, [(9, 9)])).reply.ok  # appends after the good records
    again.close()
    assert ReservationStore(path).revision == 5


def test_garbage_in_the_journal_names_the_record(tmp_path):
    path = tmp_path / "journal.msgpack"
    store = ReservationStore(path)
    store.handle(commit("a", 1, [(0, 0)]))
    store.close()
    with open(path, "ab") as f:
        f.write(b"\xc1\xc1\xc1")  # 0xc1 is never valid msgpack
    with pytest.raises(JournalError, match="record 2 at byte"):
        Journal(path).replay()


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.booleans(), st.integers(1, 3), st.integers(0, 3),
                          st.integers(0, 3), st.integers(0, 20), st.integers(1, 10)),
                max_size=25))
def test_journal_replay_matches_the_live_table(tmp_path_factory, ops):
    path = tmp_path_factory.mktemp("j") / "journal.msgpack"
    store = ReservationStore(path)
    for k, (is_commit, vehicle, c, r, t0, dt) in enumerate(ops):
        if is_commit:
            store.handle(CommitRequest(f"q{k}", vehicle, [(c, r, float(t0), float(t0 + dt))],
                                       float(t0) if k % 3 == 0 else None))
        else:
            store.handle(ReleaseRequest(f"q{k}", vehicle, float(t0)))
    store.close()
    again = ReservationStore(path)
    assert again.table.reservations() == store.table.reservations()
    assert [body_of(c) for c in again.log] == [body_of(c) for c in store.log]


def test_a_task_issued_before_the_vehicle_was_halted_cannot_commit(tmp_path):
    """A forklift cut off mid-task commits once its link is back: its freeze (a release by
    the dispatcher) came after the task was issued, so the commit must not undo it; a task
    issued after the halt commits as usual. A restarted store remembers the halt."""
    journal = tmp_path / "j"
    store = ReservationStore(journal)
    store.handle(commit("park", 1, [(0, 0)], t1=INF))
    issued = store.revision
    store.handle(ReleaseRequest("freeze", 1, 5.0))
    store.handle(commit("frozen", 1, [(0, 0)], t0=5.0, t1=INF))
    late = CommitRequest("late", 1, [(1, 0, 6.0, 8.0)], 6.0, based_on=issued)
    out = store.handle(late)
    assert not out.reply.ok and out.reply.conflict_vehicle is None and out.published == []
    assert "halted at revision 2" in out.reply.reason
    store.close()
    again = ReservationStore(journal)
    assert not again.handle(CommitRequest("late2", 1, [(1, 0, 6.0, 8.0)], 6.0,
                                          based_on=issued)).reply.ok
    resumed = CommitRequest("after", 1, [(1, 0, 9.0, 10.0)], 9.0, based_on=again.revision)
    assert again.handle(resumed).reply.ok
    again.close()


def test_a_commit_after_its_deadline_is_refused_and_answered_the_same_when_retried():
    store = ReservationStore()
    request = CommitRequest("rt", 1, [(0, 0, 4.0, 6.0)], 4.0, deadline=1000.0)
    out = store.handle(request, wall=1000.5)
    assert not out.reply.ok and "0.500 s after its deadline" in out.reply.reason
    assert store.handle(request, wall=999.0).reply == out.reply  # a retry: the same answer
    assert store.handle(CommitRequest("rt2", 1, [(0, 0, 4.0, 6.0)], 4.0, deadline=1000.0),
                        wall=999.0).reply.ok


def crossing(store):
    """Vehicle 2 drives east along row 0 from t = 0 and parks at (7, 0); vehicle 1 crosses
    (5, 0) over [1, 4): only if vehicle 2 waits 2 s. The amending commit, and vehicle 2's
    postponed holdings."""
    def driving(t0):
        route = [(3, 0), (4, 0), (5, 0), (6, 0)]
        return [(c, r, t0 + k, t0 + k + 2) for k, (c, r) in enumerate(route)] + \
            [(7, 0, t0 + 3, INF)]
    assert store.handle(CommitRequest("v2", 2, driving(0.0))).reply.ok
    request = CommitRequest("v1", 1, [(5, 1, 0.0, 2.0), (5, 0, 1.0, 4.0), (5, -1, 3.0, INF)],
                            0.0, amends=[(2, 0.0, driving(2.0), None)])
    return request, driving(2.0)


def test_an_amending_commit_is_journaled_published_and_answered_once(tmp_path):
    path = tmp_path / "journal.msgpack"
    store = ReservationStore(path)
    request, postponed = crossing(store)
    out = store.handle(request)
    assert out.reply == Reply("v1", True, 5)
    assert [(c.op, c.vehicle, c.request_id, c.part_of) for c in out.published] == [
        ("commit", 1, "", "v1"), ("commit", 2, "", "v1"), ("commit", 2, "", "v1"),
        ("commit", 1, "v1", "")]
    assert out.published[2].intervals == [tuple(iv) for iv in postponed]
    again = store.handle(request)  # the reply was lost: the same answer, nothing applied
    assert again.reply == out.reply and again.published == [] and store.revision == 5
    table = store.table.reservations()
    store.close()
    restarted = ReservationStore(path)
    assert restarted.table.reservations() == table and restarted.revision == 5
    assert restarted.handle(request).reply == out.reply  # known after a restart too


def test_a_journal_cut_short_inside_an_amend_replays_none_of_it(tmp_path):
    """Killed while writing an amend's steps: the whole records before the last step are
    cut off with the torn one, so neither the committer's release nor the other vehicle's
    postponement comes back without the commit that needed them."""
    path = tmp_path / "journal.msgpack"
    store = ReservationStore(path)
    request, _ = crossing(store)
    before = store.table.reservations()
    size = path.stat().st_size
    store.handle(request)
    store.close()
    data = path.read_bytes()
    path.write_bytes(data[:len(data) - 3])  # the last step's record torn
    restarted = ReservationStore(path)
    assert restarted.revision == 1 and restarted.table.reservations() == before
    assert restarted.torn_bytes == len(data) - 3 - size and path.stat().st_size == size
    assert restarted.handle(request).reply == Reply("v1", True, 5)  # the retry goes through


def test_an_amendment_of_a_vehicle_halted_since_is_refused():
    store = ReservationStore()
    request, _ = crossing(store)
    store.handle(ReleaseRequest("halt", 2, 0.5))  # the dispatcher froze vehicle 2
    out = store.handle(dataclasses.replace(request, based_on=1))
    assert not out.reply.ok and "vehicle 2 was halted at revision 2" in out.reply.reason
    assert store.revision == 2 and out.published == []


def test_malformed_amendments_are_refused_with_a_reason():
    store = ReservationStore()
    request, _ = crossing(store)
    bad = dataclasses.replace(request, amends=[(2, 0.0, [(3, 0, 5.0, 5.0)], None)])
    assert "must have t0 < t1" in store.handle(bad).reply.reason
    with pytest.raises(ProtocolError, match="amends"):
        build(CommitRequest, {**body_of(request), "amends": [[2, "soon", []]]})
    assert store.revision == 1
