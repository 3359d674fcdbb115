"""The reservation service as a real process on real zenoh sessions over loopback."""

import threading
from concurrent.futures import ThreadPoolExecutor

import zenoh
from zenoh_helpers import client

from fleet.runtime.bus import Requester
from fleet.wire.protocol import (
    CommitRequest,
    Reply,
    SnapshotRequest,
    VehicleState,
    WireSnapshot,
    decode,
    encode,
)


def commit(rid, vehicle, cells, t0=0.0, t1=10.0):
    return CommitRequest(rid, vehicle, [(c, r, t0, t1) for c, r in cells])


def test_commit_conflict_and_published_changes(service):
    session = client(service)
    try:
        changes = []
        got = threading.Event()
        sub = session.declare_subscriber(service.keys.reservation_change,
                                         lambda s: (changes.append(decode(
                                             s.payload.to_bytes()).message), got.set()))
        req = Requester(session, "test")
        ok = req.request(service.keys.reservation_request("test"), commit("a", 1, [(0, 0)])).message
        assert ok == Reply("a", True, 1)
        no = req.request(service.keys.reservation_request("test"),
                         commit("b", 2, [(0, 0)], 5.0, 6.0)).message
        assert no.ok is False and no.conflict_vehicle == 1 and no.conflict_cell == [0, 0]
        assert got.wait(10)
        assert [c.revision for c in changes] == [1]
        sub.undeclare()
    finally:
        session.close()


def test_two_agents_commit_the_same_cells_at_once_one_wins(service):
    sessions = [client(service) for _ in range(2)]
    try:
        barrier = threading.Barrier(2)

        def agent(k):
            req = Requester(sessions[k], f"vehicle/{k + 1}")
            barrier.wait()
            return req.request(service.keys.reservation_request("test"),
                               commit(f"v{k}", k + 1, [(3, 3), (3, 4)])).message

        with ThreadPoolExecutor(2) as pool:
            replies = list(pool.map(agent, range(2)))
        assert sorted(r.ok for r in replies) == [False, True]
        loser = next(r for r in replies if not r.ok)
        winner = next(k + 1 for k, r in enumerate(replies) if r.ok)
        assert loser.conflict_vehicle == winner and "held by vehicle" in loser.reason
    finally:
        for s in sessions:
            s.close()


def test_restart_after_a_kill_serves_the_same_table(service):
    session = client(service)
    try:
        req = Requester(session, "test")
        key = service.keys.reservation_request("test")
        for k in range(20):
            assert req.request(key, commit(f"r{k}", k % 4 + 1, [(k, 1)], t1=float("inf"))
                               ).message.ok
        before = req.request(key, SnapshotRequest()).message
        gone, back = threading.Event(), threading.Event()

        def watch(sample):
            (gone if sample.kind == zenoh.SampleKind.DELETE else back).set()

        sub = session.liveliness().declare_subscriber(service.keys.reservation_alive, watch)
        service.kill()
        assert gone.wait(30), "the killed service's liveliness token did not go"
        service.start()
        assert back.wait(60), "the restarted service did not come back"
        sub.undeclare()
        after = req.request(key, SnapshotRequest()).message
        assert isinstance(after, WireSnapshot) and after == before
        retry = req.request(key, commit("r3", 4, [(3, 1)], t1=float("inf"))).message
        assert retry == Reply("r3", True, 4)  # applied once, answered the same
    finally:
        session.close()


def test_garbage_is_rejected_and_the_service_lives_on(service):
    session = client(service)
    try:
        key = service.keys.reservation_request("test")
        for payload in [b"", b"\xc1garbage", encode(VehicleState(1, "0,0,E", 0, "", False),
                                                     "x", 1, 0.0)[:-2],
                        encode(commit("z", 1, [(0, 0)]), "x", 1, 0.0).replace(b"\x01", b"\x07",
                                                                               1)]:
            replies = list(session.get(key, payload=payload, timeout=10))
            assert len(replies) == 1
            answer = decode(replies[0].ok.payload.to_bytes()).message
            assert answer.ok is False and answer.reason.startswith("malformed request")
        assert Requester(session, "t").request(key, commit("fine", 1, [(0, 0)])).message.ok
        assert service.stop() == 0
    finally:
        session.close()
    assert "rejected a request" in service.log.read_text()


def test_a_forklift_changes_only_its_own_reservations(service):
    """The request key names who asks: under vehicle-1's key, a commit or release for
    vehicle 2 is refused (access control keeps each forklift to its own key); the
    dispatcher's key may commit for anyone (goods, zones, freezes)."""
    from fleet.wire.protocol import ReleaseRequest

    session = client(service)
    try:
        req = Requester(session, "vehicle-1")
        keys = service.keys
        mine = req.request(keys.reservation_request("vehicle-1"),
                           commit("v1a", 1, [(3, 3)])).message
        theirs = req.request(keys.reservation_request("vehicle-1"),
                             commit("v1b", 2, [(4, 4)])).message
        release = req.request(keys.reservation_request("vehicle-1"),
                              ReleaseRequest("v1c", 2, 0.0)).message
        assert mine.ok and not theirs.ok and not release.ok
        assert "vehicle-1 may change only its own reservations" in theirs.reason
        assert theirs.revision == release.revision == mine.revision  # nothing applied
        anyone = Requester(session, "dispatcher")
        goods = anyone.request(keys.reservation_request("dispatcher"),
                               commit("d1", 0, [(5, 5)])).message
        assert goods.ok and goods.revision == mine.revision + 1
    finally:
        session.close()


def test_an_amending_commit_over_zenoh_postpones_the_other_and_a_mirror_follows(service):
    """Vehicle 1 commits through the service's client with vehicle 2's holdings postponed
    2 s (the wait a collision rule gave it); a mirror following the change stream ends
    with both, apart, at the service's revision."""
    from fleet.planning.reservations import INF, Amendment, Interval
    from fleet.wire.topics import Keys
    from reservation.client import ReservationClient
    from reservation.mirror import TableMirror

    session = client(service)
    try:
        keys = Keys(service.keys.run)
        mirror = TableMirror()
        writer = ReservationClient(session, keys, Requester(session, "vehicle-1"))
        sub = writer.follow(mirror)
        other = ReservationClient(session, keys, Requester(session, "vehicle-2"))

        def driving(t0):
            route = [(3, 0), (4, 0), (5, 0), (6, 0)]
            return [*(Interval(c, t0 + k, t0 + k + 2) for k, c in enumerate(route)),
                    Interval((7, 0), t0 + 3, INF)]

        assert other.commit(2, driving(0.0)).ok
        crossing = [Interval((5, 1), 0.0, 2.0), Interval((5, 0), 1.0, 4.0),
                    Interval((5, -1), 3.0, INF)]
        assert not writer.commit(1, crossing, 0.0).ok
        written = writer.commit(1, crossing, 0.0, [Amendment(2, 0.0, tuple(driving(2.0)))])
        assert written.ok and written.revision == 5
        assert mirror.wait_for(5, 10)
        with mirror.frozen() as table:
            assert table.conflict(9, (5, 0), 1.0, 4.0) == 1
            assert table.conflict(9, (5, 0), 4.0, 6.0) == 2
            assert table.conflict(9, (5, 0), 0.0, 0.9) is None
        sub.undeclare()
    finally:
        session.close()
