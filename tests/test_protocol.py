"""Wire messages: round trips, and hostile payloads that must be rejected with a reason."""

import contextlib
import math

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fleet.wire.protocol import (
    SCHEMA_VERSION,
    TYPES,
    CommitRequest,
    ProtocolError,
    Reply,
    VehicleState,
    WireChange,
    decode,
    encode,
)

times = st.floats(min_value=0, max_value=1e6, allow_nan=False) | st.just(math.inf)
intervals = st.lists(st.tuples(st.integers(-5, 200), st.integers(-5, 200), times, times),
                     max_size=20)


@given(st.text(max_size=12), st.integers(0, 10**6), intervals,
       st.none() | st.floats(0, 1e5, allow_nan=False))
def test_commit_round_trip(request_id, vehicle, ivs, release_from):
    msg = CommitRequest(request_id, vehicle, [tuple(i) for i in ivs], release_from)
    env = decode(encode(msg, "vehicle/1", 42, 3.25))
    assert env.message == msg and (env.sender, env.seq, env.sim_time) == ("vehicle/1", 42, 3.25)


def test_every_type_round_trips():
    samples = [VehicleState(3, "1,2,N", 1, "forward", True, 1.0, 2.0, 0.5),
               Reply("r", False, 9, 4, [3, 5], "held"), WireChange(4, "release", 2, [], 7.5, "q")]
    for msg in samples:
        assert decode(encode(msg, "s", 1, 0.0)).message == msg
    assert {type(m).TYPE for m in samples} <= set(TYPES)


@settings(max_examples=300)
@given(st.binary(max_size=200))
def test_random_bytes_are_rejected_or_valid_never_crash(payload):
    with contextlib.suppress(ProtocolError):
        decode(payload)


def envelope(**overrides):
    raw = {"v": SCHEMA_VERSION, "type": "reservation.reply", "sender": "s", "seq": 1, "t": 0.0,
           "body": {"request_id": "r", "ok": True, "revision": 3}}
    raw.update(overrides)
    return msgpack.packb(raw)


@pytest.mark.parametrize("raw, reason", [
    (envelope(v=2), "schema version 2 is not 1"),
    (envelope(type="nope"), "unknown message type 'nope'"),
    (envelope(seq="1"), "seq: must be an integer"),
    (envelope(body=[1]), "body must be a map"),
    (envelope(body={"request_id": "r", "ok": 1, "revision": 3}), "ok: must be true or false"),
    (envelope(body={"request_id": "r", "ok": True}), "missing field 'revision'"),
    (envelope(body={"request_id": "r", "ok": True, "revision": 3, "x": 1}),
     "unknown field 'x'"),
    (envelope(t=float("nan")), "t: must not be NaN"),
    (msgpack.packb([1, 2]), "envelope must be a map"),
    (envelope()[:-4], "not msgpack"),
])
def test_malformed_messages_name_what_is_wrong(raw, reason):
    with pytest.raises(ProtocolError, match=reason):
        decode(raw)


@given(st.dictionaries(st.sampled_from(["v", "type", "sender", "seq", "t", "body"]),
                       st.none() | st.integers(-2**63, 2**63 - 1) | st.text(max_size=5)
                       | st.floats()
                       | st.lists(st.integers(0, 9), max_size=3)))
def test_mangled_envelopes_never_crash(fields):
    raw = {"v": SCHEMA_VERSION, "type": "vehicle.state", "sender": "s", "seq": 1, "t": 0.0,
           "body": {"vehicle": 1, "pose": "0,0,E", "speed": 0, "maneuver": "",
                    "loaded": False}}
    raw.update(fields)
    with contextlib.suppress(ProtocolError):
        decode(msgpack.packb(raw))
