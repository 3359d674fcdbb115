"""The `ReservationWriter` contract, run alike against the table in this process and against
the reservation service's zenoh client (reservation/client.py) with the service a real process:
the same writes get the same answers and leave the same table."""

import math
import random
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import pytest
from zenoh_helpers import client

from fleet.planning.reservations import (
    Interval,
    ReservationTable,
    ReservationWriter,
    WriteResult,
)
from fleet.runtime.bus import Requester, RequestFailed
from fleet.wire.protocol import VehicleState, encode
from fleet.wire.topics import Keys
from reservation.client import ReservationClient
from reservation.mirror import TableMirror

INF = math.inf


@dataclass
class Subject:
    writer: ReservationWriter
    table_at: Callable[[int], ReservationTable]  # the table once it holds this revision


@contextmanager
def following(service) -> Iterator[Subject]:
    """The service's client, and a mirror that shows what the service holds."""
    session = client(service)
    try:
        writer = ReservationClient(session, service.keys, Requester(session, "test"))
        mirror = TableMirror()
        follower = writer.follow(mirror)

        def table_at(revision: int) -> ReservationTable:
            assert mirror.wait_for(revision, 30)
            return mirror.table

        yield Subject(writer, table_at)
        follower.undeclare()
    finally:
        session.close()


def in_process() -> Subject:
    table = ReservationTable()
    return Subject(table, lambda revision: table)


@pytest.fixture(params=["table", "service"])
def subject(request):
    if request.param == "table":
        yield in_process()
        return
    with following(request.getfixturevalue("service")) as remote:
        yield remote


def held(subject: Subject, written: WriteResult, vehicle: int | None = None):
    return [(r.vehicle, r.cell, r.t0, r.t1)
            for r in subject.table_at(written.revision).reservations(vehicle)]


def test_a_commit_is_made_whole_and_counts_the_revision(subject):
    written = subject.writer.commit(1, [Interval((0, 0), 0.0, 5.0), Interval((0, 1), 2.0, INF)])
    assert written == WriteResult(True, 1)
    assert held(subject, written) == [(1, (0, 0), 0.0, 5.0), (1, (0, 1), 2.0, INF)]


def test_a_conflicting_commit_is_refused_whole_naming_the_holder_and_the_cell(subject):
    subject.writer.commit(1, [Interval((2, 3), 10.0, INF)])
    written = subject.writer.commit(2, [Interval((0, 0), 0.0, 5.0),
                                        Interval((2, 3), 20.0, 25.0)])
    assert written == WriteResult(False, 1, "cell (2, 3) is held by vehicle 1 over "
                                  "[20.0, 25.0)", 1, (2, 3))
    assert held(subject, written, 2) == []


def test_intervals_of_others_may_touch_but_not_overlap(subject):
    assert subject.writer.commit(1, [Interval((0, 0), 0.0, 5.0)]).ok
    assert subject.writer.commit(2, [Interval((0, 0), 5.0, 9.0)]).ok
    refused = subject.writer.commit(3, [Interval((0, 0), 4.75, 5.25)])
    assert not refused.ok and refused.conflict_vehicle in (1, 2) and refused.revision == 2


def test_a_commit_releases_the_vehicles_own_reservations_from_release_from_first(subject):
    subject.writer.commit(1, [Interval((4, 4), 0.0, INF)])  # parked
    written = subject.writer.commit(1, [Interval((4, 5), 3.0, 6.0)], release_from=3.0)
    assert written == WriteResult(True, 2)
    assert held(subject, written) == [(1, (4, 4), 0.0, 3.0), (1, (4, 5), 3.0, 6.0)]


def test_a_release_cuts_what_straddles_it_on_the_cells_given(subject):
    subject.writer.commit(1, [Interval((0, 0), 0.0, 10.0), Interval((1, 0), 0.0, 10.0),
                              Interval((2, 0), 6.0, 9.0)])
    written = subject.writer.release(1, 5.0, [(0, 0), (2, 0)])
    assert written == WriteResult(True, 2)
    assert held(subject, written) == [(1, (0, 0), 0.0, 5.0), (1, (1, 0), 0.0, 10.0)]
    everything = subject.writer.release(1)
    assert everything == WriteResult(True, 3) and held(subject, everything) == []


def test_a_release_of_no_cells_is_an_error_not_a_release_of_all(subject):
    subject.writer.commit(1, [Interval((0, 0), 0.0, 10.0)])
    with pytest.raises(ValueError, match="no cells"):
        subject.writer.release(1, 0.0, [])
    assert subject.writer.commit(1, [Interval((9, 9), 0.0, 1.0)]).revision == 2


def random_writes(subject: Subject, rng: random.Random) -> list[WriteResult]:
    answers = []
    for _ in range(150):
        vehicle = rng.randint(0, 3)
        if rng.random() < 0.75:
            intervals = []
            for _ in range(rng.randint(1, 3)):
                t0 = float(rng.randint(0, 40))
                t1 = rng.choice([t0 + rng.randint(1, 10), INF])
                intervals.append(Interval((rng.randint(0, 4), rng.randint(0, 4)), t0, t1))
            release_from = rng.choice([None, float(rng.randint(0, 40))])
            answers.append(subject.writer.commit(vehicle, intervals, release_from))
        else:
            cells = rng.choice([None, [(rng.randint(0, 4), rng.randint(0, 4))]])
            answers.append(subject.writer.release(vehicle, float(rng.randint(0, 40)), cells))
    return answers


def test_the_same_writes_get_the_same_answers_and_leave_the_same_table(service):
    table = in_process()
    expected = random_writes(table, random.Random(18))
    accepted = [a for a in expected if a.ok]
    assert 40 < len(accepted) < len(expected)  # both kinds of answer were given
    assert [a.revision for a in accepted] == list(range(1, len(accepted) + 1))
    with following(service) as remote:
        assert random_writes(remote, random.Random(18)) == expected
        assert held(remote, expected[-1]) == held(table, expected[-1])


# -- what only the service can refuse ---------------------------------------------------------
@pytest.fixture
def remote(service):
    session = client(service)
    yield ReservationClient(session, service.keys, Requester(session, "test"))
    session.close()


def test_the_service_refuses_a_commit_of_a_vehicle_halted_since_its_task(remote):
    assert remote.commit(1, [Interval((0, 0), 0.0, INF)]).ok
    assert remote.release(1, 5.0).ok  # the dispatcher halts the forklift at revision 2
    late = remote.commit(1, [Interval((0, 1), 6.0, 8.0)], 6.0, based_on=1)
    assert not late.ok and late.conflict_vehicle is None and "halted at revision 2" in late.reason
    assert remote.commit(1, [Interval((0, 1), 6.0, 8.0)], 6.0, based_on=2).ok


def test_the_service_refuses_a_commit_past_its_deadline(remote):
    late = remote.commit(1, [Interval((0, 0), 0.0, 1.0)], deadline=time.time() - 10.0)
    assert not late.ok and late.conflict_vehicle is None and "after its deadline" in late.reason


def test_a_repeated_request_id_is_answered_as_before_and_applied_once(remote):
    first = remote.commit(1, [Interval((0, 0), 0.0, 1.0)], request_id="vehicle-1:park")
    again = remote.commit(1, [Interval((0, 0), 0.0, 1.0)], request_id="vehicle-1:park")
    assert first == again == WriteResult(True, 1)


def test_an_answer_of_another_kind_is_a_failed_request(service):
    session = client(service)
    keys = Keys(f"{service.keys.run}-impostor")  # a run the real service does not serve
    try:
        impostor = session.declare_queryable(
            keys.reservation_request("test"),
            lambda query: query.reply(query.key_expr, encode(
                VehicleState(1, "0,0,E", 0, "", False), "reservation", 1, 0.0)))
        writer = ReservationClient(session, keys, Requester(session, "test", retry_s=0.0))
        with pytest.raises(RequestFailed, match=r"answered a vehicle\.state to a "
                                                r"reservation\.commit"):
            writer.commit(1, [Interval((0, 0), 0.0, 1.0)])
        impostor.undeclare()
    finally:
        session.close()
