"""A running mission under a stream of hostile messages on every key of its run: random
bytes, msgpack of the wrong shape, truncated and padded messages, and valid messages of
another key's type (some in the key's own sender's name), put on every key and sent as
queries to every key, several times while the mission runs. The mission must end as the
undisturbed in-process reference does, to the digest; no process may die; the recording must
hold every hostile message, counted as malformed or foreign, with its verdicts passing."""

from __future__ import annotations

import math
import queue
import random
import time
import types
import typing
from collections import Counter
from dataclasses import MISSING, fields
from pathlib import Path

import msgpack
import zenoh

from fleet.analysis.analyze import analyze
from fleet.dispatching.decision import Strategy
from fleet.mission.engine import engine_options, run_mission
from fleet.mission.record import digest
from fleet.mission.spec import Mission, MissionKind
from fleet.recording.reader import read_recording
from fleet.runtime.launcher import Launcher
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.wire.protocol import Message as WireMessage
from fleet.wire.protocol import (
    MissionInfo,
    Progress,
    ProtocolError,
    RecorderStatus,
    Reply,
    decode,
    encode,
)
from fleet.wire.topics import (
    PUBLICATIONS,
    TOPICS,
    Keys,
    TopicKind,
    expected_sender,
    message_type,
)
from fleet.world.layout_file import load_layout

MISSION = Mission("small", MissionKind.FILL, Strategy.ANN)
VEHICLES = 2
SEED = 20_240_611
ROUNDS_AT = (1, 3, 6, 9)  # a round of injections once this many subtasks are done (of 48)
WRONG_TYPES_PER_KEY = 3  # valid messages of another key's type, per key and round
PROGRESS_WAIT_S = 120.0
# Valid messages that travel on some key of a run: a wrong one on a key is another key's.
# (Requests and commands, which travel as queries, are not among them: sending a valid one
# is a forged command, which is not what this test is about.)
PUBLISHED = sorted({topic.message for topic in PUBLICATIONS}, key=lambda cls: cls.TYPE)


def run_keys(keys: Keys, vehicles: int) -> list[str]:
    """Every key of the run a message can be put on: each topic's (per vehicle for the
    per-vehicle ones; one principal's request key), but liveliness tokens."""
    out = []
    for topic in TOPICS:
        if TopicKind.TOKEN in topic.kind:
            continue
        if topic.fields == ("principal",):
            out.append(topic.key(keys.run, "test"))
        elif topic.fields == ("vehicle",):
            out += [topic.key(keys.run, v) for v in range(1, vehicles + 1)]
        else:
            out.append(topic.key(keys.run))
    assert all(k.startswith(keys.root + "/") for k in out)
    return out


def sample(hint: typing.Any, rng: random.Random) -> typing.Any:
    """A valid value of a message field's type."""
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return sample(rng.choice(args), rng)
    if hint is type(None):
        return None
    if hint is bool:
        return rng.random() < 0.5
    if hint is int:
        return rng.choice([0, 1, 2, 7, -1, 2**62])
    if hint is float:
        return rng.choice([0.0, 0.5, 12.25, -3.0, math.inf, 1e300])
    if hint is str:
        return rng.choice(["", "1,2,N", "s1", "intruder", "x" * 300])
    if hint is dict:
        return {"forged": True}
    if origin is list:
        return [sample(args[0], rng) for _ in range(rng.randint(0, 2))]
    if origin is tuple:
        return tuple(sample(h, rng) for h in args)
    raise AssertionError(f"no sample for {hint!r}")


def message_of(cls: type[WireMessage], rng: random.Random) -> WireMessage:
    hints = typing.get_type_hints(cls)
    return cls(**{f.name: sample(hints[f.name], rng) for f in fields(cls)
                  if (f.default is MISSING and f.default_factory is MISSING)
                  or rng.random() < 0.5})


def malformed(key: str, rng: random.Random) -> list[bytes]:
    """Payloads that are no valid message: random bytes, msgpack of the wrong shape, a
    message cut short or padded, another schema version, a body of the wrong type."""
    own = message_type(key) or RecorderStatus
    good = encode(message_of(own, rng), "intruder", rng.randint(1, 9), 1.0)
    return [
        rng.randbytes(rng.randint(1, 64)),
        b"\xc1" + rng.randbytes(rng.randint(0, 16)),  # 0xc1 is never msgpack
        msgpack.packb(rng.choice([[1, 2, 3], "vehicle.state", 42, None, 2.5, b"\x00"])),
        msgpack.packb({"v": 1, "type": own.TYPE, "sender": "intruder", "seq": 1, "t": 0.0,
                       "body": rng.choice([[], "body", {"no such field": 1}, None])}),
        msgpack.packb({"v": 99, "type": own.TYPE, "body": {}}),
        msgpack.packb({"v": 1, "type": own.TYPE, "sender": "intruder", "seq": 1,
                       "t": math.nan, "body": {}}),
        good[:rng.randint(0, len(good) - 1)],
        good + rng.randbytes(rng.randint(1, 8)),
    ]


def wrong_type(key: str, keys: Keys, rng: random.Random) -> list[bytes]:
    """Valid messages of other keys' types, from an intruder or in the key's own sender's
    name."""
    own = message_type(key)
    candidates = [cls for cls in PUBLISHED if cls is not own]
    sender = expected_sender(key) or "intruder"
    return [encode(message_of(cls, rng), rng.choice([sender, "intruder"]), rng.randint(0, 99),
                   rng.choice([0.0, 3.5, 1e9]))
            for cls in rng.sample(candidates, WRONG_TYPES_PER_KEY)]


def decodes(payload: bytes) -> bool:
    try:
        decode(payload)
    except ProtocolError:
        return False
    return True


class Intruder:
    """From on_ready: waits for the mission's progress and, at each of ROUNDS_AT, puts
    hostile payloads on every key of the run and sends them as queries to every key."""

    def __init__(self) -> None:
        self.rng = random.Random(SEED)
        self.put: Counter[tuple[str, bool]] = Counter()  # (key, decodes) -> payloads put
        self.first_round: Counter[str] = Counter()  # key -> payloads put in the first round
        self.queries: dict[str, list[tuple[bytes, list[zenoh.Reply]]]] = {}
        self.rounds = 0
        self.launcher: Launcher | None = None

    def on_ready(self, session: zenoh.Session, keys: Keys, launcher: Launcher) -> None:
        self.keys, self.launcher = keys, launcher
        progress: queue.Queue[bytes] = queue.Queue()
        subscriber = session.declare_subscriber(
            keys.dispatch_progress, lambda sample: progress.put(sample.payload.to_bytes()))
        try:
            for done in ROUNDS_AT:
                self._wait_for_progress(progress, done)
                self._inject(session, keys)
                self.rounds += 1
                assert launcher.exited() == [], [c.name for c in launcher.exited()]
        finally:
            subscriber.undeclare()

    def _wait_for_progress(self, progress: queue.Queue, done: int) -> None:
        """Until the dispatcher says `done` subtasks are done (our own garbage on the same key
        is passed over); a child that dies meanwhile fails the test at once."""
        deadline = time.monotonic() + PROGRESS_WAIT_S
        while time.monotonic() < deadline:
            try:
                payload = progress.get(timeout=0.5)  # the timeout only paces the exit check
            except queue.Empty:
                assert self.launcher.exited() == [], [c.name for c in self.launcher.exited()]
                continue
            try:
                envelope = decode(payload)
            except ProtocolError:
                continue
            if envelope.sender == "dispatcher" and isinstance(envelope.message, Progress) \
                    and envelope.message.done >= done:
                return
        raise AssertionError(f"the mission did not reach {done} subtasks")

    def _inject(self, session: zenoh.Session, keys: Keys) -> None:
        for key in run_keys(keys, VEHICLES):
            payloads = malformed(key, self.rng) + wrong_type(key, keys, self.rng)
            for payload in payloads:  # reliably: the recording must hold every one
                session.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)
                self.put[key, decodes(payload)] += 1
                if self.rounds == 0:
                    self.first_round[key] += 1
            for payload in payloads:  # and as a query (most keys have nobody to answer)
                answers = list(session.get(key, payload=payload, timeout=10.0))
                self.queries.setdefault(key, []).append((payload, answers))

    def expected(self, decoding: bool) -> int:
        return sum(n for (_, d), n in self.put.items() if d == decoding)

    def check_replies(self, keys: Keys) -> None:
        """The services answered every hostile query with a refusal; whoever answers any
        query answered with a valid message."""
        def only(key: str) -> list[tuple[bytes, zenoh.Reply]]:
            """Each query to `key` and its one answer."""
            assert all(len(answers) == 1 for _, answers in self.queries[key]), key
            return [(payload, answers[0]) for payload, answers in self.queries[key]]

        for payload, answer in only(keys.reservation_request("test")):
            reply = decode(answer.ok.payload.to_bytes()).message
            assert isinstance(reply, Reply) and not reply.ok
            if decodes(payload):
                assert "is not a request the store answers" in reply.reason, reply.reason
            else:
                assert reply.reason.startswith("malformed request: "), reply.reason
        for v in range(1, VEHICLES + 1):
            assert all(answer.err.payload.to_bytes().startswith(b"rejected: ")
                       for _, answer in only(keys.vehicle_task(v)))
        assert all(isinstance(decode(a.ok.payload.to_bytes()).message, MissionInfo)
                   for _, a in only(keys.dispatch_mission))
        assert all(isinstance(decode(a.ok.payload.to_bytes()).message, RecorderStatus)
                   for _, a in only(keys.recorder_status))
        for answers in self.queries.values():
            for answer in (a for _, group in answers for a in group):
                if answer.ok is not None:
                    decode(answer.ok.payload.to_bytes())  # never garbage back

    def check_logs(self, run_dir: Path, keys: Keys) -> None:
        """Each listener logged every hostile message on its keys as rejected. (The
        dispatcher listens to acknowledgements and table changes only until its mission
        ends, which may come before the last round: all of the first round, at least.)"""
        logs = {p.stem: p.read_text() for p in (run_dir / "logs").glob("*.log")}

        def rejected(name: str, key: str) -> int:
            return sum(f"rejected a message on {key}:" in line
                       for line in logs[name].splitlines())

        def put_on(key: str) -> int:
            return self.put[key, True] + self.put[key, False]

        for v in range(1, VEHICLES + 1):
            agent = f"agent-{v}"
            assert rejected(agent, keys.clock) == put_on(keys.clock)
            assert rejected(agent, keys.reservation_change) == put_on(keys.reservation_change)
            assert rejected(agent, keys.vehicle_task(v)) == len(
                self.queries[keys.vehicle_task(v)])
            assert self.first_round[keys.clock_ack(v)] <= \
                rejected("dispatcher", keys.clock_ack(v)) <= put_on(keys.clock_ack(v))
        assert self.first_round[keys.reservation_change] <= \
            rejected("dispatcher", keys.reservation_change) <= put_on(keys.reservation_change)
        assert sum(f"rejected a request on {keys.reservation_request('test')}:" in line
                   for line in logs["reservation"].splitlines()) == \
            sum(not decodes(p) for p, _ in self.queries[keys.reservation_request("test")])


def test_hostile_messages_on_every_key_change_nothing(tmp_path):
    layout = load_layout(MISSION.layout)
    reference = run_mission(MISSION, engine_options(MISSION, layout, None), layout)
    intruder = Intruder()
    outcome = run_processes(RunSpec(MISSION, VEHICLES, tmp_path), on_ready=intruder.on_ready)

    # The mission ran to its end exactly as the undisturbed in-process reference did.
    assert outcome.error == "" and outcome.done is not None and outcome.done.ok
    assert intruder.rounds == len(ROUNDS_AT)
    assert outcome.done.digest == digest(reference)
    assert outcome.done.record["end_time_s"] == reference.end_time

    # No process died: each one ran until it was told to stop, and stopped cleanly.
    codes = {c.name: c.proc.returncode for c in intruder.launcher.children}
    assert codes == dict.fromkeys(codes, 0)
    assert {"router", "recorder", "reservation", "dispatcher",
            *(f"agent-{v}" for v in range(1, VEHICLES + 1))} <= set(codes)

    keys = intruder.keys
    intruder.check_replies(keys)
    intruder.check_logs(tmp_path, keys)

    # The recording holds every hostile message as it came, counted, and believes none.
    recording = read_recording(tmp_path / "run.mcap")
    report = analyze(recording)
    assert intruder.expected(decoding=False) > 0 and intruder.expected(decoding=True) > 0
    assert report.malformed == intruder.expected(decoding=False)
    assert report.foreign == intruder.expected(decoding=True)
    assert report.safe and report.work_done and report.messages_lost == 0, report.lines()
    assert report.passed and report.complete and report.finished
    assert report.stacks_done == len(layout.stacks) and report.end_time_s == reference.end_time
    hostile_keys = {key for key, _ in intruder.put}
    assert hostile_keys <= {r.key for r in recording.messages}  # every key, on record
