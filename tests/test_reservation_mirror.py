"""A local copy of the table that follows the service: in memory, and over real zenoh."""

from zenoh_helpers import client

from fleet.runtime.bus import BusConfig, Requester, open_session
from fleet.wire.protocol import CommitRequest, ReleaseRequest, SnapshotRequest, WireSnapshot
from reservation.client import ReservationClient
from reservation.mirror import TableMirror
from reservation.store import ReservationStore


def commits(store, n, start=0):
    changes = []
    for k in range(start, start + n):
        out = store.handle(CommitRequest(f"r{k}", k % 3 + 1, [(k, k % 5, 0.0, 10.0 + k)],
                                         0.0 if k % 2 else None))
        changes += out.published
    return changes


def test_snapshot_then_changes_in_order():
    store = ReservationStore()
    commits(store, 5)
    mirror = TableMirror()
    mirror.load(store.snapshot())
    for change in commits(store, 5, 5):
        mirror.on_change(change)
    assert mirror.revision == 10 and not mirror.needs_resync
    assert mirror.table.reservations() == store.table.reservations()


def test_changes_before_the_snapshot_wait_and_old_ones_are_dropped():
    store = ReservationStore()
    early = commits(store, 4)
    snap = store.snapshot()
    late = commits(store, 3, 4)
    mirror = TableMirror()
    for change in early[2:] + late:  # heard while the snapshot was on its way
        mirror.on_change(change)
    assert not mirror.synced and mirror.revision == 0
    mirror.load(snap)
    assert mirror.revision == 7 and mirror.table.reservations() == store.table.reservations()


def test_a_lost_change_asks_for_a_resync_and_a_diff_repairs_it():
    store = ReservationStore()
    mirror = TableMirror()
    mirror.load(store.snapshot())
    changes = commits(store, 4)
    for change in changes[:1] + changes[2:]:  # change 2 lost
        mirror.on_change(change)
    assert mirror.revision == 1 and mirror.needs_resync
    mirror.load(store.snapshot(since=mirror.revision))
    assert mirror.revision == 4 and not mirror.needs_resync
    assert mirror.table.reservations() == store.table.reservations()
    assert isinstance(store.snapshot(since=1), WireSnapshot)


def test_a_mirror_follows_the_service_over_zenoh(service):
    writer = client(service)
    reader = open_session(BusConfig("peer", (service.endpoint,), ()))
    try:
        put = Requester(writer, "writer")
        key = service.keys.reservation_request("test")
        for k in range(10):
            assert put.request(key, CommitRequest(put.next_id(), k % 3 + 1,
                                                  [(k, 0, 0.0, 5.0 + k)])).message.ok
        mirror = TableMirror()
        sub = ReservationClient(reader, service.keys, Requester(reader, "reader")).follow(mirror)
        assert mirror.revision == 10
        for k in range(10, 30):
            assert put.request(key, CommitRequest(put.next_id(), k % 3 + 1,
                                                  [(k, 1, 0.0, 5.0 + k)])).message.ok
        last = put.request(key, ReleaseRequest(put.next_id(), 2, 3.0)).message
        assert mirror.wait_for(last.revision, timeout=30)
        snap = put.request(key, SnapshotRequest()).message
        assert sorted((r.vehicle, *r.cell, r.t0, r.t1) for r in mirror.table.reservations()) \
            == sorted(snap.reservations)
        sub.undeclare()
    finally:
        reader.close()
        writer.close()


def test_fleet_table_shows_the_services_table(service, capsys):
    from fleet.cli import main

    writer = client(service)
    try:
        put = Requester(writer, "writer")
        for k in range(3):
            assert put.request(service.keys.reservation_request("test"), CommitRequest(
                put.next_id(), 7, [(k, 2, 0.0, 9.0)])).message.ok
    finally:
        writer.close()
    assert main(["table", "--run", service.keys.run, "--mode", "peer",
                 "--connect", service.endpoint]) == 0
    out = capsys.readouterr().out
    assert f"fleet/{service.keys.run}: revision 3, 3 reserved intervals" in out
    assert "vehicle 7: 3" in out


def test_a_frozen_mirror_holds_changes_back_until_thawed():
    store = ReservationStore()
    commits(store, 2)
    mirror = TableMirror()
    mirror.load(store.snapshot())
    table = mirror.table
    with mirror.frozen():
        for change in commits(store, 3, 2):
            mirror.on_change(change)
        assert mirror.revision == 2  # a planner reading now sees one consistent table
    assert mirror.revision == 5 and mirror.table is table
    assert mirror.table.reservations() == store.table.reservations()


def test_an_empty_diff_keeps_the_copy():
    """Resyncing a copy that is already current asks for the changes since its revision:
    none. That is nothing new, not an empty table (a resumed forklift once planned on one)."""
    store = ReservationStore()
    commits(store, 4)
    mirror = TableMirror()
    mirror.load(store.snapshot())
    before = mirror.table.reservations()
    mirror.load(store.snapshot(mirror.revision))
    assert mirror.revision == 4 and mirror.table.reservations() == before != []
