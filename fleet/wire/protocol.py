"""Every message on the wire, in one place: dataclasses encoded with msgpack (docs/protocol.md).

Each message travels in an envelope carrying the schema version, its type, the sender, the
sender's sequence number and the simulation time. `decode` validates everything it returns:
a malformed, truncated, unknown-type or wrong-version payload raises ProtocolError naming
what was wrong, so a process can log it and carry on.
"""

from __future__ import annotations

import functools
import math
import types
import typing
from dataclasses import MISSING, dataclass, field, fields
from typing import Annotated, Any, ClassVar

import msgpack

from fleet.params import LOOKAHEAD_S
from fleet.planning.rules004 import Direction
from fleet.planning.rules004 import Task as Task004
from fleet.planning.trajectory import Pose, step_manner

SCHEMA_VERSION = 1
MAX_PAYLOAD = 16 * 1024 * 1024  # no legitimate message comes near this


class ProtocolError(ValueError):
    """A payload that is not a valid message; the message says why."""


def _maneuver_label(text: str) -> None:
    step_manner(text)


def _maneuver_or_rest(text: str) -> None:
    if text:
        step_manner(text)


# Strings with a syntax of their own: `decode` checks them too (the validator raises
# ValueError), so a reader never meets a pose or maneuver it cannot interpret.
PoseText = Annotated[str, Pose.parse]  # "col,row,H"
ManeuverLabel = Annotated[str, _maneuver_label]
ManeuverOrRest = Annotated[str, _maneuver_or_rest]  # "" at rest

def _task004(text: str) -> None:
    Task004(text)


def _direction(code: int) -> None:
    Direction(code)


# Seed 004's task types (M1..M4) and direction code (1..4); its cells are (x, y) of its floor.
Task004Name = Annotated[str, _task004]
DirectionCode = Annotated[int, _direction]
XY004 = tuple[int, int]

# (col, row, t0, t1): one reserved cell over [t0, t1); t1 may be infinity.
WireInterval = tuple[int, int, float, float]
# (cells, arrivals, dwells): a vehicle's route in time (fleet/planning/reservations.py,
# TimedRoute), which seed 002's AGVs settle their collisions against.
WireRoute = tuple[list[tuple[int, int]], list[float], list[float]]
# (vehicle, release_from, intervals, route): another vehicle's holdings from release_from on,
# postponed to these, and the route they come from (a commit's `amends`; Amendment).
WireAmend = tuple[int, float, list[WireInterval], WireRoute | None]

# Reservation owners that are no forklift (forklifts are 1..N), in every commit and change.
GOODS = 0  # the goods on the stacks
ZONE = -1  # closed zones


@dataclass(frozen=True)
class Message:
    TYPE: ClassVar[str] = ""


@dataclass(frozen=True)
class VehicleState(Message):
    TYPE: ClassVar[str] = "vehicle.state"
    vehicle: int
    pose: PoseText
    speed: int  # 0 v_zero, 1 v_mid, 2 v_high
    maneuver: ManeuverOrRest  # label of the maneuver being driven
    loaded: bool
    x: float = 0.0  # world position of the rear axle point (metres) and heading (radians)
    y: float = 0.0
    theta: float = 0.0
    battery: float | None = None  # state of charge, % (None: no battery is modelled)


@dataclass(frozen=True)
class CommitRequest(Message):
    TYPE: ClassVar[str] = "reservation.commit"
    request_id: str
    vehicle: int
    intervals: list[WireInterval]
    release_from: float | None = None  # release the vehicle's reservations from here first
    # The table revision the dispatcher's task was issued at: refused if the dispatcher has
    # halted the vehicle since (a forklift cut off mid-task must not undo its freeze).
    based_on: int | None = None
    # Real time: the Unix time after which it is refused (the plan's start would be past,
    # and releasing from there would rewrite what was already driven).
    deadline: float | None = None
    # Other vehicles' holdings postponed in the same step, all or nothing (seed 002's
    # collision rules may make an AGV already under way wait).
    amends: list[WireAmend] = field(default_factory=list)
    route: WireRoute | None = None  # the route in time the intervals come from (seed 002)


@dataclass(frozen=True)
class ReleaseRequest(Message):
    TYPE: ClassVar[str] = "reservation.release"
    request_id: str
    vehicle: int
    from_t: float
    cells: list[tuple[int, int]] = field(default_factory=list)  # only these (empty: all)


@dataclass(frozen=True)
class Reply(Message):
    """The reservation service's answer to a commit or release."""

    TYPE: ClassVar[str] = "reservation.reply"
    request_id: str
    ok: bool
    revision: int
    conflict_vehicle: int | None = None
    conflict_cell: list[int] = field(default_factory=list)
    reason: str = ""


@dataclass(frozen=True)
class SnapshotRequest(Message):
    TYPE: ClassVar[str] = "reservation.snapshot_request"
    since_revision: int = -1  # -1: the whole table; otherwise the changes after it
    # With since_revision -1: only the reservations that hold after this instant (what a plan
    # made then reads), a table whose size does not grow with the run's past.
    held_after: float | None = None


@dataclass(frozen=True)
class WireChange(Message):
    """One accepted change of the table, published and journaled (the table's own `Change`
    in fleet/planning/reservations.py, on the wire; fleet/wire/convert.py converts)."""

    TYPE: ClassVar[str] = "reservation.change"
    revision: int
    op: str  # "commit" or "release"
    vehicle: int
    intervals: list[WireInterval] = field(default_factory=list)
    release_from: float | None = None
    request_id: str = ""
    release_cells: list[tuple[int, int]] | None = None  # release only these (None: all)
    # A step of an amending commit before its last (which carries `request_id`): the
    # request it is part of, so a journal cut short inside the steps replays none of them.
    part_of: str = ""
    route: WireRoute | None = None  # the vehicle's route in time from now on (seed 002)


WireHeld = tuple[int, int, int, float, float]  # one reservation: vehicle, col, row, t0, t1


@dataclass(frozen=True)
class WireSnapshot(Message):
    """The table, or the changes since a revision (the reply to a `SnapshotRequest`)."""

    TYPE: ClassVar[str] = "reservation.snapshot"
    revision: int
    reservations: list[WireHeld]
    changes: list[dict] = field(default_factory=list)  # encoded WireChange bodies, for diffs
    diff: bool = False  # `changes` since the revision asked for (maybe none), not a table
    routes: list[tuple[int, WireRoute]] = field(default_factory=list)  # vehicle, its route


# (manner label, start pose, end pose, t0, t1, v0, v1, swept cells): one maneuver.
WireStep = tuple[ManeuverLabel, PoseText, PoseText, float, float, int, int,
                 list[tuple[int, int]]]


# (vehicle, start, goal, t_start, steps, intervals): a committed leg.
WireLeg = tuple[int, PoseText, PoseText, float, list[WireStep], list[WireInterval]]


@dataclass(frozen=True)
class TaskRequest(Message):
    """The dispatcher asks a forklift's agent to plan and commit one subtask."""

    TYPE: ClassVar[str] = "dispatch.task"
    task_id: str
    vehicle: int
    kind: str  # "deliver", "return" or "aside" (out of another's way)
    start: str  # pose "col,row,H" where the dispatcher believes the forklift stands
    t_i: float
    goals: list[str]
    filled: list[tuple[int, int]]  # stacks holding goods: the static map to plan on
    loaded: bool
    revision: int  # plan on a table at least this recent
    after: bool | None = None  # loaded once arrived, if that changes then (Task.after)


@dataclass(frozen=True)
class TaskResult(Message):
    """The agent's answer: the committed trajectory, or why there is none."""

    TYPE: ClassVar[str] = "dispatch.task_result"
    task_id: str
    vehicle: int
    ok: bool
    revision: int  # the table revision that holds the committed trajectory
    start: str = ""
    goal: str = ""
    t_start: float = 0.0
    steps: list[WireStep] = field(default_factory=list)
    intervals: list[WireInterval] = field(default_factory=list)
    expansions: int = 0
    failure: str = ""  # a FailureReason value when not ok
    detail: str = ""
    rejections: list[str] = field(default_factory=list)  # commits the store refused first
    amended: list[WireLeg] = field(default_factory=list)  # others' legs it postponed


@dataclass(frozen=True)
class ClockTick(Message):
    """The one source of "now". Fast mode: the clock stands at t until every agent acks this
    tick. Real time: sim time = t + speed * (wall clock - wall)."""

    TYPE: ClassVar[str] = "clock.tick"
    tick: int
    mode: str  # "fast" or "realtime"
    t: float
    speed: float = 1.0
    wall: float = 0.0  # Unix time at which sim time was t (real time only)
    down: list[int] = field(default_factory=list)  # forklifts the dispatcher holds as down


@dataclass(frozen=True)
class ClockAck(Message):
    TYPE: ClassVar[str] = "clock.ack"
    tick: int
    vehicle: int


@dataclass(frozen=True)
class Progress(Message):
    """After each committed subtask: stacks done of total, the decision failures so far and
    `t`, the sim time the mission has reached (the clock's instant of the decision)."""

    TYPE: ClassVar[str] = "dispatch.progress"
    done: int
    total: int
    t: float
    failures: int


@dataclass(frozen=True)
class MissionDone(Message):
    """The dispatcher's last word: the mission record (fleet.mission.record:
    MissionSummary.to_dict) or an error."""

    TYPE: ClassVar[str] = "dispatch.done"
    ok: bool
    error: str = ""
    record: dict = field(default_factory=dict)
    digest: str = ""
    wall_s: float = 0.0
    rejections: list[str] = field(default_factory=list)  # commits refused before a replan
    detections: list[dict] = field(default_factory=list)  # faults seen (dispatcher/clock.py)
    # A real-time seed-004 run: instants paced, how many were handled late, the latest
    # (dispatcher/remote004.py, RealtimePace.summary)
    timing: dict = field(default_factory=dict)


# One forklift where a mission that did not finish left it (fleet/mission/standstill.py):
# (vehicle, the pose it stands at once its committed legs are driven, from when, its next
# task "deliver" or "return", down (frozen by a fault), the targets it failed to reach since
# its last subtask, its last failure since then ("" none)).
WireStanding = tuple[int, PoseText, float, str, bool, list[str], str]


@dataclass(frozen=True)
class MissionStopped(Message):
    """How far a mission that did not finish got, published just before the dispatcher's
    result: why it stopped (`cause`: "stuck", "stopped" by a signal, "lost" a participant,
    "failed" otherwise; `reason` says it in words), the sim time it reached, the stacks done
    of the total, the decisions that failed in a row and in all (the dispatcher's count at
    its end, docs/metrics.md), and where each forklift stood."""

    TYPE: ClassVar[str] = "dispatch.stopped"
    cause: str
    reason: str
    t: float
    stacks_done: int
    stacks_total: int
    failures_in_a_row: int
    decision_failures: int
    vehicles: list[WireStanding]


# (manner label, start pose, end pose, t0, t1, v0, v1): one maneuver of a recorded subtask.
RecordStep = tuple[ManeuverLabel, PoseText, PoseText, float, float, int, int]


@dataclass(frozen=True)
class MissionInfo(Message):
    """What the run is: published by the dispatcher when the mission starts (and answered to
    late joiners), so a recorder needs no flags to describe the run it records."""

    TYPE: ClassVar[str] = "dispatch.mission"
    layout: str  # the layout's name
    layout_toml: str  # the layout itself, so a recording stands on its own
    kind: str  # "fill", "empty" or "orders"
    strategy: str
    vehicles: int
    seed: int
    clock: str  # "fast", "realtime" or "inprocess"
    speed: float
    starts: list[str]  # start pose of forklift 1..N
    command: str = ""
    versions: dict = field(default_factory=dict)
    orders: int = 0  # an order mission's orders (kind "orders")
    order_area: str = ""  # the shelf area its orders were drawn on ("": every shelf)
    released: list[str] = field(default_factory=list)  # the shelf of order 1, 2, ...
    # Seed 002's batteries (fleet/mission/battery.py): each AGV's charge at the start, in %
    # (empty: no battery is modelled), and the rates and the threshold they run with.
    soc_start: list[float] = field(default_factory=list)
    drain_per_s: float = 0.0  # % per second of driving
    charge_per_s: float = 0.0  # % per second parked on a pile
    charge_below: float = 0.0  # % below which an AGV goes to charge at a task's end
    # Seed 004's heat cost: w_heat (0: off) and T_value, [x, y, value] per cell with traffic,
    # from the mission's history run: every AGV plans with these very numbers.
    heat_w: float = 0.0
    heat: list[tuple[int, int, float]] = field(default_factory=list)
    # Who gives the work: "internal" (the dispatcher to the agents), "vda5050" (the dispatcher
    # as a VDA 5050 master, through the gateway) or "external" (a master of the user's)
    dispatch: str = "internal"
    # Algorithm 1's lookahead, s (fleet/params.py; None: none, inf having no JSON form).
    lookahead: float | None = LOOKAHEAD_S

    @property
    def lookahead_s(self) -> float:
        return math.inf if self.lookahead is None else self.lookahead


@dataclass(frozen=True)
class SubtaskEvent(Message):
    """A subtask the dispatcher decided and a forklift committed (its whole trajectory)."""

    TYPE: ClassVar[str] = "dispatch.subtask"
    vehicle: int
    kind: str  # "deliver", "return" or "aside" (out of another's way)
    target: str  # cluster or station
    stack: int | None  # stack index in the cluster, for deliveries
    t_i: float
    t_end: float
    t_done: float  # after claiming / unloading
    postponed: bool
    steps: list[RecordStep]
    intervals: list[WireInterval]


@dataclass(frozen=True)
class LegAmended(Message):
    """A vehicle's last committed leg, postponed by another vehicle's commit (seed 002's
    collision rules): the subtask decided at t_i now drives these steps, and ends (and is
    done) that much later."""

    TYPE: ClassVar[str] = "dispatch.amended"
    vehicle: int
    t_i: float
    t_end: float
    t_done: float
    steps: list[RecordStep]
    intervals: list[WireInterval]


@dataclass(frozen=True)
class StackDone(Message):
    """A stack filled (or emptied): the goods are on it (or gone) from t."""

    TYPE: ClassVar[str] = "dispatch.stack"
    cluster: str
    index: int
    vehicle: int
    t: float


@dataclass(frozen=True)
class DecisionFailure(Message):
    """One decision failure the dispatcher counts (each is announced, docs/metrics.md): at
    t, the instant decided for, the vehicle chosen (stage "score": no target it accepts;
    "dispatch": the same, the last choice of a dispatch that ended without a decision) or
    decided for ("plan": no trajectory to its goal could be planned), and why."""

    TYPE: ClassVar[str] = "dispatch.failure"
    t: float
    vehicle: int
    stage: str  # "score", "dispatch" or "plan"
    reason: str


@dataclass(frozen=True)
class DeadlockSeen(Message):
    """The dispatcher found a vehicle whose way stuck vehicles close for good, and what it did
    (fleet/mission/deadlock.py): `moved` was sent aside to `siding` (None: none could go)."""

    TYPE: ClassVar[str] = "dispatch.deadlock"
    t: float
    waiting: int
    kind: str  # "cycle", "idle" or "walled"
    chain: list[int]  # waiting -> its blocker -> ... (a cycle repeats its head)
    moved: int | None
    siding: str | None
    for_vehicle: int | None  # whose way the move opens (a blocker that inherited, or waiting)


@dataclass(frozen=True)
class HaltRequest(Message):
    """The dispatcher freezes a forklift at t (docs/faults.md): it completes the maneuver in
    progress and drives nothing it committed after it; with `stand` (it broke down), it
    stands where it is at t instead, until resumed."""

    TYPE: ClassVar[str] = "dispatch.halt_request"
    request_id: str
    vehicle: int
    t: float
    stand: bool = False


@dataclass(frozen=True)
class AmendRequest(Message):
    """The dispatcher tells an AGV that another's commit postponed its last leg (seed 002's
    collision rules): it drives `leg` instead, the same leg with waits put in."""

    TYPE: ClassVar[str] = "dispatch.amend_request"
    request_id: str
    vehicle: int
    leg: WireLeg


@dataclass(frozen=True)
class ResumeRequest(Message):
    """A forklift that was down moves again from t_resume: it stood since t_stop part-way
    through `step` (or at rest at `pose`, without one), and completes that maneuver first."""

    TYPE: ClassVar[str] = "dispatch.resume_request"
    request_id: str
    vehicle: int
    t_stop: float
    t_resume: float
    pose: PoseText  # where it stands once the maneuver is over
    loaded: bool
    step: WireStep | None = None
    battery: float | None = None  # its charge at t_stop, % (None: it keeps its own)


@dataclass(frozen=True)
class StatusRequest(Message):
    """A restarted dispatcher asks a forklift what it holds. The agent answers once the work
    it had in hand is done (its requests are served in order), so nothing is in flight."""

    TYPE: ClassVar[str] = "dispatch.status_request"
    request_id: str
    vehicle: int


@dataclass(frozen=True)
class VehicleStatus(Message):
    """What a forklift holds: its last committed leg (`steps`, from `start`; none: at rest
    at `pose`), what that leg was for, whether it is down, its breakdown as it reported it
    (perhaps while no dispatcher listened), and the last tick it heard."""

    TYPE: ClassVar[str] = "vehicle.status"
    vehicle: int
    pose: PoseText  # where it stands once everything committed is driven
    loaded: bool  # on its last leg (or at rest)
    kind: str  # "deliver", "return", "aside" or "" (no leg yet)
    start: str = ""
    steps: list[WireStep] = field(default_factory=list)
    down: bool = False
    tick: int = 0
    t: float = 0.0
    wall: float = 0.0  # real time: the last tick's wall anchor (Unix time at sim time t)
    breakdown: str = ""  # reported since it last moved: "broken", "repaired", or ""


@dataclass(frozen=True)
class Halt(Message):
    """A forklift frozen at t: it holds `cells` from t to infinity. A moving one completes
    its maneuver and stands at `pose` from t_stand; one that is down stands at (x, y, theta)
    (world, as in VehicleState) until it resumes."""

    TYPE: ClassVar[str] = "dispatch.halt"
    vehicle: int
    t: float
    cause: str
    moving: bool
    pose: PoseText
    t_stand: float
    cells: list[tuple[int, int]]
    x: float
    y: float
    theta: float


@dataclass(frozen=True)
class Resume(Message):
    """A forklift that was down moves again from t (it stands at its pose from t_stand)."""

    TYPE: ClassVar[str] = "dispatch.resume"
    vehicle: int
    t: float
    t_stand: float


@dataclass(frozen=True)
class StackReopened(Message):
    """A delivery cut short: the stack is not done after all and goes back to the queue."""

    TYPE: ClassVar[str] = "dispatch.reopen"
    cluster: str
    index: int
    vehicle: int
    t: float


@dataclass(frozen=True)
class ZoneClosed(Message):
    """Cells unusable over [t0, t1) (a spill), held by owner ZONE."""

    TYPE: ClassVar[str] = "dispatch.zone"
    cells: list[tuple[int, int]]
    t0: float
    t1: float


@dataclass(frozen=True)
class VehicleFault(Message):
    """A forklift reports a fault of its own ("broken") and its end ("repaired")."""

    TYPE: ClassVar[str] = "vehicle.fault"
    vehicle: int
    t: float
    state: str
    detail: str = ""


@dataclass(frozen=True)
class InjectFault(Message):
    """The fault injector to an agent: "breakdown", "repair", or "slow_planner" (planning
    takes `factor` times longer; 1 restores it)."""

    TYPE: ClassVar[str] = "inject.fault"
    request_id: str
    vehicle: int
    kind: str
    factor: float = 1.0


@dataclass(frozen=True)
class VehicleClaim(Message):
    """An agent started without an id (`fleet agent --id auto`, one replica of a compose
    service) asks the dispatcher for one. The same name gets the same forklift back."""

    TYPE: ClassVar[str] = "dispatch.claim"
    request_id: str
    name: str  # the claimant's host name, which a restarted container keeps


@dataclass(frozen=True)
class ClaimReply(Message):
    TYPE: ClassVar[str] = "dispatch.claim_reply"
    request_id: str
    ok: bool
    vehicle: int = 0
    reason: str = ""


@dataclass(frozen=True)
class RecorderStatus(Message):
    """The recorder's answer on fleet/<run>/recorder/status: how much it holds."""

    TYPE: ClassVar[str] = "recorder.status"
    path: str
    messages: int
    done_seen: bool  # the dispatcher's mission result is in the file


@dataclass(frozen=True)
class CellRequest(Message):
    """Seed 004, to a lifting AGV's agent: take `cell` for good from `t` before entering it
    (`take`), or let it go from `t` (the cell behind, on arrival)."""

    TYPE: ClassVar[str] = "agv004.cell"
    request_id: str
    vehicle: int
    cell: XY004
    t: float
    take: bool


@dataclass(frozen=True)
class CellReply(Message):
    """The agent's answer: whether the store gave it the cell, at which table revision."""

    TYPE: ClassVar[str] = "agv004.cell_reply"
    request_id: str
    ok: bool
    revision: int
    reason: str = ""


@dataclass(frozen=True)
class RouteRequest(Message):
    """Seed 004, to a lifting AGV's agent: plan the leg's path from `start` on the grid as it
    is at `t` (fleet/mission/tracking004.py, RouteQuery), on the table `held`: the
    reservations that hold after `t`, as the mission's table has them (the store's, once
    every request so far is answered; sent along, the plan waits for no answer and the
    agent asks nothing of its own)."""

    TYPE: ClassVar[str] = "agv004.route"
    request_id: str
    vehicle: int
    t: float
    task: Task004Name
    start: XY004
    goal: XY004
    heading: DirectionCode
    home: XY004 | None = None
    relaxed: bool = False
    blocked: list[XY004] = field(default_factory=list)
    moving: list[int] = field(default_factory=list)
    stagnant: list[int] = field(default_factory=list)
    held: list[WireHeld] = field(default_factory=list)


@dataclass(frozen=True)
class RouteReply(Message):
    TYPE: ClassVar[str] = "agv004.route_reply"
    request_id: str
    found: bool
    cells: list[XY004] = field(default_factory=list)  # start first
    planning_s: float = 0.0


@dataclass(frozen=True)
class AgvEvent(Message):
    """Seed 004: one event of the tracking (fleet/mission/record004.py converts): `kind` is
    moved, turned, paused, met, stagnant, replanned, made_way, picked, leg_done, or a fault:
    broke_down, repaired, zone_closed; the other fields are those the kind has
    (docs/protocol.md)."""

    TYPE: ClassVar[str] = "agv004.event"
    kind: str
    vehicle: int
    t0: float
    t1: float = 0.0
    at: XY004 = (0, 0)
    to: XY004 | None = None  # moved, made_way; leg_done: the leg's goal
    other: int = 0  # met: the holder; made_way: the idle AGV
    task: str = ""  # moved, leg_done: M1..M4
    loaded: bool = False
    relaxed: bool = False
    label: str = ""  # paused: lift..; met: head-on..; replanned: why; picked, leg_done: station
    found: bool = False  # replanned
    heading: int = 0  # turned
    home: XY004 | None = None  # leg_done
    make_way: bool = False  # leg_done
    charge_s: float = 0.0  # leg_done
    cells: list[XY004] = field(default_factory=list)  # zone_closed


@dataclass(frozen=True)
class AgvHistory(Message):
    """A restarted recorder asks the dispatcher for the seed-004 events numbered after
    `after` (what its predecessor did not write); each comes back as it was published."""

    TYPE: ClassVar[str] = "agv004.history"
    after: int


@dataclass(frozen=True)
class MqttTraffic(Message):
    """One VDA 5050 message the gateway sent (`received` False) or took from the broker
    (True) on a forklift's MQTT topic, as it was: the recording's copy of the MQTT traffic
    (docs/vda5050.md). `payload` is the message's text (bytes that are not UTF-8 replaced)."""

    TYPE: ClassVar[str] = "vda5050.mqtt"
    vehicle: int
    topic: str  # order, instantActions, state, visualization, connection, factsheet
    received: bool
    payload: str


@dataclass(frozen=True)
class LegCommitted(Message):
    """The leg a forklift's agent committed for an order's edge, as the VDA 5050 gateway
    had it planned: what a master cannot learn over MQTT (VDA 5050 states carry no times),
    for the recording and for the dispatcher of `fleet run --dispatch vda5050`, whose engine
    goes on from the trajectory the forklift really drives."""

    TYPE: ClassVar[str] = "vda5050.leg"
    vehicle: int
    order_id: str
    sequence_id: int  # the order's edge
    revision: int  # the table revision that holds it
    leg: WireLeg


@dataclass(frozen=True)
class Envelope:
    message: Message
    sender: str
    seq: int
    sim_time: float


TYPES: dict[str, type[Message]] = {
    cls.TYPE: cls for cls in (VehicleState, CommitRequest, ReleaseRequest, Reply,
                              SnapshotRequest, WireChange, WireSnapshot, TaskRequest, TaskResult,
                              ClockTick, ClockAck, Progress, MissionDone, MissionStopped,
                              MissionInfo, SubtaskEvent, LegAmended, StackDone, DecisionFailure,
                              DeadlockSeen, RecorderStatus, HaltRequest, AmendRequest,
                              ResumeRequest, Halt, Resume, StackReopened, ZoneClosed,
                              VehicleFault, InjectFault, StatusRequest, VehicleStatus,
                              VehicleClaim, ClaimReply, CellRequest, CellReply, RouteRequest,
                              RouteReply, AgvEvent, AgvHistory, MqttTraffic, LegCommitted)
}


def body_of(message: Message) -> dict:
    return {f.name: getattr(message, f.name) for f in fields(message)}


def encode(message: Message, sender: str, seq: int, sim_time: float) -> bytes:
    body = body_of(message)
    return msgpack.packb({"v": SCHEMA_VERSION, "type": message.TYPE, "sender": sender,
                          "seq": seq, "t": sim_time, "body": body}, use_bin_type=True)


def decode(payload: bytes) -> Envelope:
    if not isinstance(payload, bytes | bytearray | memoryview):
        raise ProtocolError(f"payload must be bytes, not {type(payload).__name__}")
    if len(payload) > MAX_PAYLOAD:
        raise ProtocolError(f"payload of {len(payload)} bytes exceeds {MAX_PAYLOAD}")
    try:
        raw = msgpack.unpackb(bytes(payload), raw=False, strict_map_key=True,
                              use_list=True)
    except Exception as exc:  # msgpack raises several unrelated types for bad input
        raise ProtocolError(f"not msgpack: {type(exc).__name__}: {exc}") from None
    if not isinstance(raw, dict):
        raise ProtocolError(f"envelope must be a map, not {type(raw).__name__}")
    version = raw.get("v")
    if version != SCHEMA_VERSION:
        raise ProtocolError(f"schema version {version!r} is not {SCHEMA_VERSION}")
    kind = raw.get("type")
    cls = TYPES.get(kind) if isinstance(kind, str) else None
    if cls is None:
        raise ProtocolError(f"unknown message type {kind!r}")
    sender = _check(raw.get("sender"), str, "sender")
    seq = _check(raw.get("seq"), int, "seq")
    sim_time = _check(raw.get("t"), float, "t")
    body = raw.get("body")
    if not isinstance(body, dict):
        raise ProtocolError(f"{kind}: body must be a map")
    return Envelope(build_message(cls, body), sender, seq, sim_time)


def build_message(cls: type[Message], body: dict) -> Message:
    """A message of type `cls` from its body map, validated (ProtocolError otherwise)."""
    checkers, known, required = _fields(cls)
    if not body.keys() <= known:
        unknown = sorted(body.keys() - known, key=str)[0]
        raise ProtocolError(f"{cls.TYPE}: unknown field {unknown!r}")
    values = {}
    for name, check in checkers:
        if name in body:
            values[name] = _checked(check, body[name], f"{cls.TYPE}.{name}")
        elif name in required:
            raise ProtocolError(f"{cls.TYPE}: missing field {name!r}")
    return cls(**values)


Checker = typing.Callable[[Any], Any]


class _Invalid(Exception):
    """A value a checker refuses: what is wrong, and where below the checked value
    ("[2][0]"); made a ProtocolError naming the whole place by `_check`."""

    def __init__(self, what: str, below: str = "") -> None:
        self.what, self.below = what, below


@functools.cache
def _fields(cls: type[Message]) -> tuple[tuple[tuple[str, Checker], ...], frozenset[str],
                                         frozenset[str]]:
    """Each field's checker in order, the fields' names, and those without a default."""
    hints = typing.get_type_hints(cls, include_extras=True)
    return (tuple((f.name, _checker(hints[f.name])) for f in fields(cls)),
            frozenset(f.name for f in fields(cls)),
            frozenset(f.name for f in fields(cls)
                      if f.default is MISSING and f.default_factory is MISSING))


def _check(value: Any, hint: Any, where: str) -> Any:
    """`value` converted to the type `hint` describes, or ProtocolError naming `where`."""
    return _checked(_checker(hint), value, where)


def _checked(check: Checker, value: Any, where: str) -> Any:
    try:
        return check(value)
    except _Invalid as exc:
        raise ProtocolError(f"{where}{exc.below}: {exc.what}") from None


def _checker(hint: Any) -> Checker:
    """A function converting a value to the type `hint` describes, or raising _Invalid:
    the hint is read once, not at every value (every message every process receives is
    checked). Keyed by its text too: `int | float` equals `float | int`, but converts
    otherwise."""
    return _compiled(hint, repr(hint))


@functools.cache
def _compiled(hint: Any, text: str) -> Checker:
    origin = typing.get_origin(hint)
    if origin is Annotated:
        base, *validators = typing.get_args(hint)
        check_base = _checker(base)

        def annotated(value: Any) -> Any:
            value = check_base(value)
            for validate in validators:
                try:
                    validate(value)
                except ValueError as exc:
                    raise _Invalid(str(exc)) from None
            return value
        return annotated
    if origin in (types.UnionType, typing.Union):
        options = [_checker(o) for o in typing.get_args(hint) if o is not type(None)]
        nullable = type(None) in typing.get_args(hint)

        def union(value: Any) -> Any:
            if nullable and value is None:
                return None
            first = None
            for option in options:
                try:
                    return option(value)
                except _Invalid as exc:
                    first = first or exc
            raise first or _Invalid("must be null")
        return union
    if hint in _SCALARS:
        return _SCALARS[hint]
    if origin is list:
        (item,) = typing.get_args(hint)
        check_item = _checker(item)

        def listed(value: Any) -> list:
            if not isinstance(value, list | tuple):
                raise _Invalid("must be a list")
            return [_item(check_item, v, i) for i, v in enumerate(value)]
        return listed
    if origin is tuple:
        items = tuple(_checker(h) for h in typing.get_args(hint))

        def tupled(value: Any) -> tuple:
            if not isinstance(value, list | tuple) or len(value) != len(items):
                raise _Invalid(f"must be a list of {len(items)} items")
            return tuple(_item(check, v, i) for i, (v, check) in
                         enumerate(zip(value, items, strict=True)))
        return tupled
    raise TypeError(f"unsupported type {hint!r} in a message")  # pragma: no cover


def _item(check: Checker, value: Any, index: int) -> Any:
    try:
        return check(value)
    except _Invalid as exc:
        raise _Invalid(exc.what, f"[{index}]{exc.below}") from None


def _bool(value: Any) -> bool:
    if not isinstance(value, bool):
        raise _Invalid(f"must be true or false, not {value!r}")
    return value


def _int(value: Any) -> int:
    if not isinstance(value, int) or isinstance(value, bool):
        raise _Invalid(f"must be an integer, not {value!r}")
    return value


def _float(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _Invalid(f"must be a number, not {value!r}")
    value = float(value)
    if math.isnan(value):
        raise _Invalid("must not be NaN")
    return value


def _str(value: Any) -> str:
    if not isinstance(value, str):
        raise _Invalid(f"must be a string, not {value!r}")
    return value


def _dict(value: Any) -> dict:
    if not isinstance(value, dict):
        raise _Invalid("must be a map")
    return value


_SCALARS: dict[Any, Checker] = {bool: _bool, int: _int, float: _float, str: _str, dict: _dict}
