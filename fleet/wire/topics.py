"""The catalogue of topics: every key of a run under fleet/<run>/ (docs/protocol.md), what
travels on it, who alone may send it, and whether its publisher waits rather than drop.

The rows are the attributes of `Keys`, one per topic. Read from the class, an attribute is
its row (`Keys.vehicle_state`, a `Topic`); read from one run's `Keys(run)`, it is that run's
key (`keys.clock`) or the function that makes it (`keys.vehicle_state(3)`). Everything else
is derived from the rows: the recorder's schema per key, the one sender a recording (or a
process) believes on a key, the dispatcher's publishers and the in-process recording. A new
stream (another vehicle kind's message, say) is one more row.
"""

from __future__ import annotations

import functools
import re
import string
from collections.abc import Callable
from dataclasses import dataclass
from enum import Flag, auto

from fleet.wire.protocol import (
    AgvEvent,
    AgvHistory,
    AmendRequest,
    CellRequest,
    ClockAck,
    ClockTick,
    CommitRequest,
    DeadlockSeen,
    DecisionFailure,
    Envelope,
    Halt,
    HaltRequest,
    InjectFault,
    LegAmended,
    LegCommitted,
    Message,
    MissionDone,
    MissionInfo,
    MissionStopped,
    MqttTraffic,
    Progress,
    RecorderStatus,
    ReleaseRequest,
    Resume,
    ResumeRequest,
    RouteRequest,
    SnapshotRequest,
    StackDone,
    StackReopened,
    StatusRequest,
    SubtaskEvent,
    TaskRequest,
    VehicleClaim,
    VehicleFault,
    VehicleState,
    WireChange,
    ZoneClosed,
)

# Who sends: each process's name, in every envelope it sends (and its login, docs/secure-run).
DISPATCHER = "dispatcher"
RESERVATION = "reservation"
RECORDER = "recorder"
CLOCK = "clock"  # the dispatcher's clock
INJECTOR = "injector"  # the fault injector of `fleet run --faults`
VEHICLE = "vehicle-{vehicle}"  # forklift N's agent, on the keys of forklift N
GATEWAY = "vda5050"  # the VDA 5050 gateway (fleet run --dispatch external)
PRINCIPAL = "{principal}"  # whoever the key names (a request key names who asks)

# What a placeholder in a pattern (or a sender) stands for in a concrete key.
PLACEHOLDERS = {"vehicle": r"\d+", "principal": r"[^/]+", "host": r"[^/]+"}


class TopicKind(Flag):
    """What a topic's keys are for (one may be a publication and a queryable at once)."""

    PUBLICATION = auto()  # put by its sender, numbered 1, 2, ... (fleet.runtime.bus.Stream)
    QUERYABLE = auto()  # asked and answered; a publication that is one answers with its message
    TOKEN = auto()  # a liveliness token: its holder is up


def _regex(template: str) -> str:
    """A template as a regular expression: its placeholders as named groups."""
    parts = []
    for literal, name, _, _ in string.Formatter().parse(template):
        parts.append(re.escape(literal))
        if name:
            parts.append(f"(?P<{name}>{PLACEHOLDERS[name]})")
    return "".join(parts)


@dataclass(frozen=True)
class Topic:
    """One topic: a key pattern below fleet/<run>/ and what travels on its keys."""

    pattern: str  # e.g. "vehicle/{vehicle}/state" (placeholders: PLACEHOLDERS)
    kind: TopicKind
    messages: tuple[type[Message], ...] = ()  # a publication's one type; a queryable's requests
    sender: str | None = None  # who alone sends `messages` (with the key's fields); None: anyone
    reliable: bool = True  # a publication waits rather than drop (congestion control BLOCK)

    @functools.cached_property
    def fields(self) -> tuple[str, ...]:
        """The placeholders of the pattern, in order: what `key` is given."""
        return tuple(name for _, name, _, _ in string.Formatter().parse(self.pattern) if name)

    @functools.cached_property
    def _key_regex(self) -> re.Pattern:
        return re.compile(r"fleet/[^/]+/" + _regex(self.pattern))

    @property
    def message(self) -> type[Message]:
        """A publication's message type."""
        (cls,) = self.messages
        return cls

    def key(self, run: str, *values: int | str) -> str:
        """The key of this topic in `run`, its placeholders filled in order ("*": any)."""
        return f"fleet/{run}/" + self.pattern.format(
            **dict(zip(self.fields, values, strict=True)))

    def match(self, key: str) -> dict[str, str] | None:
        """The placeholders' values in a concrete key of this topic (of any run); None if
        the key is not this topic's."""
        found = self._key_regex.fullmatch(key)
        return None if found is None else found.groupdict()

    def sender_on(self, key: str) -> str | None:
        """Who alone sends on `key` (a key of this topic); None: anyone, or not its key."""
        fields = self.match(key)
        if fields is None or self.sender is None:
            return None
        return self.sender.format(**fields)

    def __get__(self, keys: Keys | None,
                owner: type | None = None) -> Topic | str | Callable[..., str]:
        """Read from a run's Keys: the key, or the function of the placeholders making it."""
        if keys is None:
            return self
        if not self.fields:
            return self.key(keys.run)
        return functools.partial(self.key, keys.run)


@dataclass(frozen=True)
class Keys:
    """Every key of one run, under fleet/<run>/: the catalogue of topics, a row each."""

    run: str = "default"

    # The reservation service (docs/protocol.md: the key of a request names who asks, so a
    # forklift may ask only under its own name and change only its own reservations).
    reservation_request = Topic("reservation/request/{principal}", TopicKind.QUERYABLE,
                                (CommitRequest, ReleaseRequest, SnapshotRequest), PRINCIPAL)
    reservation_change = Topic("reservation/change", TopicKind.PUBLICATION, (WireChange,),
                               RESERVATION)
    reservation_alive = Topic("reservation/alive", TopicKind.TOKEN, sender=RESERVATION)
    # A forklift's agent.
    vehicle_state = Topic("vehicle/{vehicle}/state", TopicKind.PUBLICATION, (VehicleState,),
                          VEHICLE)
    vehicle_task = Topic("vehicle/{vehicle}/task", TopicKind.QUERYABLE,
                         (TaskRequest, HaltRequest, AmendRequest, ResumeRequest, StatusRequest,
                          CellRequest, RouteRequest), DISPATCHER)
    vehicle_inject = Topic("vehicle/{vehicle}/inject", TopicKind.QUERYABLE, (InjectFault,),
                           INJECTOR)
    vehicle_fault = Topic("vehicle/{vehicle}/fault", TopicKind.PUBLICATION, (VehicleFault,),
                          VEHICLE)
    vehicle_alive = Topic("vehicle/{vehicle}/alive", TopicKind.TOKEN, sender=VEHICLE)
    # The one clock and who follows it.
    clock = Topic("clock", TopicKind.PUBLICATION, (ClockTick,), CLOCK)
    clock_ack = Topic("clock/ack/{vehicle}", TopicKind.PUBLICATION, (ClockAck,), VEHICLE)
    injector_ack = Topic("clock/ack/injector", TopicKind.PUBLICATION, (ClockAck,), INJECTOR)
    # The dispatcher: what the run is, what it decides and how the mission ends.
    dispatch_mission = Topic("dispatch/mission", TopicKind.PUBLICATION | TopicKind.QUERYABLE,
                             (MissionInfo,), DISPATCHER)
    dispatch_progress = Topic("dispatch/progress", TopicKind.PUBLICATION, (Progress,), DISPATCHER)
    dispatch_subtask = Topic("dispatch/subtask", TopicKind.PUBLICATION, (SubtaskEvent,), DISPATCHER)
    dispatch_amended = Topic("dispatch/amended", TopicKind.PUBLICATION, (LegAmended,),
                             DISPATCHER)
    dispatch_stack = Topic("dispatch/stack", TopicKind.PUBLICATION, (StackDone,), DISPATCHER)
    dispatch_failure = Topic("dispatch/failure", TopicKind.PUBLICATION, (DecisionFailure,),
                             DISPATCHER)
    dispatch_deadlock = Topic("dispatch/deadlock", TopicKind.PUBLICATION, (DeadlockSeen,),
                              DISPATCHER)
    dispatch_halt = Topic("dispatch/halt", TopicKind.PUBLICATION, (Halt,), DISPATCHER)
    dispatch_resume = Topic("dispatch/resume", TopicKind.PUBLICATION, (Resume,), DISPATCHER)
    dispatch_reopen = Topic("dispatch/reopen", TopicKind.PUBLICATION, (StackReopened,), DISPATCHER)
    dispatch_zone = Topic("dispatch/zone", TopicKind.PUBLICATION, (ZoneClosed,), DISPATCHER)
    dispatch_stopped = Topic("dispatch/stopped", TopicKind.PUBLICATION, (MissionStopped,),
                             DISPATCHER)
    dispatch_agv = Topic("dispatch/agv", TopicKind.PUBLICATION, (AgvEvent,), DISPATCHER)
    # What a restarted recorder missed of them, asked of the dispatcher.
    dispatch_agv_history = Topic("dispatch/agv/history", TopicKind.QUERYABLE, (AgvHistory,),
                                 RECORDER)
    # Also answered, once the mission has ended: to a recorder restarted after it did.
    dispatch_done = Topic("dispatch/done", TopicKind.PUBLICATION | TopicKind.QUERYABLE,
                          (MissionDone,), DISPATCHER)
    dispatch_claim = Topic("dispatch/claim", TopicKind.QUERYABLE, (VehicleClaim,))  # any agent
    dispatcher_alive = Topic("dispatch/alive", TopicKind.TOKEN, sender=DISPATCHER)
    # The VDA 5050 gateway: each forklift's MQTT traffic, for the recording.
    vda5050_mqtt = Topic("vda5050/{vehicle}/mqtt", TopicKind.PUBLICATION, (MqttTraffic,), GATEWAY)
    vda5050_leg = Topic("vda5050/{vehicle}/leg", TopicKind.PUBLICATION, (LegCommitted,), GATEWAY)
    vda5050_alive = Topic("vda5050/alive", TopicKind.TOKEN, sender=GATEWAY)
    # The recorder.
    recorder_status = Topic("recorder/status", TopicKind.PUBLICATION | TopicKind.QUERYABLE,
                            (RecorderStatus,), RECORDER)
    recorder_alive = Topic("recorder/alive", TopicKind.TOKEN, sender=RECORDER)
    # Another host's router (fleet run --hosts), once linked to the first host's: held by
    # the router itself, so no login is granted it (the first host's router takes anything
    # of the run from the routers it links with, and from them alone).
    router_linked = Topic("router/{host}/linked", TopicKind.TOKEN)

    @property
    def root(self) -> str:
        return f"fleet/{self.run}"

    @property
    def everything(self) -> str:
        return f"{self.root}/**"

    @staticmethod
    def vehicle_in(key: str) -> int | None:
        """The forklift a concrete key (of any run) is of, if its topic names one."""
        topic = topic_of(key)
        fields = topic.match(key) if topic is not None else None
        return int(fields["vehicle"]) if fields and "vehicle" in fields else None


TOPICS: tuple[Topic, ...] = tuple(t for t in vars(Keys).values() if isinstance(t, Topic))
PUBLICATIONS: tuple[Topic, ...] = tuple(t for t in TOPICS if TopicKind.PUBLICATION in t.kind)

_VEHICLE_SENDER = re.compile(_regex(VEHICLE))


def vehicle_sender(vehicle: int) -> str:
    """Forklift `vehicle`'s name as a sender (and as a login): vehicle-N."""
    return VEHICLE.format(vehicle=vehicle)


def vehicle_of(sender: str) -> int | None:
    """The forklift a sender name is (vehicle-N: N); None for any other sender."""
    found = _VEHICLE_SENDER.fullmatch(sender)
    return None if found is None else int(found["vehicle"])


@functools.lru_cache(maxsize=4096)
def topic_of(key: str) -> Topic | None:
    """The topic a concrete key (of any run) is of; None for a key of no topic."""
    return next((t for t in TOPICS if t.match(key) is not None), None)


@functools.lru_cache(maxsize=4096)
def _published(key: str) -> tuple[type[Message], str] | None:
    topic = topic_of(key)
    if topic is None or TopicKind.PUBLICATION not in topic.kind:
        return None
    return topic.message, topic.sender_on(key)


def message_type(key: str) -> type[Message] | None:
    """The message a key's publication carries (the recorder's schema for it); None for a
    key nobody publishes on. Chosen by key, not by content: a hostile payload is recorded
    on the channel it arrived on, as it was."""
    found = _published(key)
    return found[0] if found else None


def expected_sender(key: str) -> str | None:
    """The one sender of a key's publication; None for a key nobody publishes on."""
    found = _published(key)
    return found[1] if found else None


def genuine(key: str, envelope: Envelope) -> bool:
    """Whether to believe a message: of the type its key carries, from the key's own sender
    (anyone on the network could put a forged one)."""
    found = _published(key)
    return (found is not None and type(envelope.message) is found[0]
            and envelope.sender == found[1])


def published_by(sender: str) -> dict[type[Message], Topic]:
    """A sender's publications by the message each carries (`sender` as the rows write it:
    VEHICLE for a forklift's)."""
    return {t.message: t for t in PUBLICATIONS if t.sender == sender}
