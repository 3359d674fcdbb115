"""Where each forklift that went down stopped, as plain records in the dispatcher's journal
(docs/faults.md, "A restarted dispatcher picks the mission up").

Only the dispatcher knows a down forklift's freeze: its agent is dead, paused or cut off (a
restarted one knows nothing), and the store holds the frozen cells but not the maneuver in
progress nor the pose it ends at. So the engine journals each freeze of a forklift going
down once the store and the agents have it, and each resumption before it is told (a
dispatcher that dies in between leaves a forklift down that its journal has up: its
successor says so rather than resume it twice); a new dispatcher reads which forklifts are
still down, and where they stand, from the last of these records. They share the journal
with an order mission's book (fleet/mission/order_log.py), which replays the others.

`from_record` takes anything msgpack gives back and raises ValueError naming what is wrong.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from fleet.dispatching.decision import TaskKind
from fleet.mission.freeze import Freeze
from fleet.mission.order_log import cells_field, cells_out, time_field, vehicle_field
from fleet.planning.trajectory import Pose
from fleet.wire.convert import step_from_wire, step_to_wire
from fleet.wire.protocol import ProtocolError

HALTED, RESUMED = "halted", "resumed"  # the records' first field


@dataclass(frozen=True)
class Halted:
    """A forklift went down: where it stopped, why, what it does next once it moves, and
    its battery's charge then (None: no battery, or not known to this dispatcher: the agent
    keeps its own), which an agent restarted meanwhile is told."""

    freeze: Freeze
    cause: str
    next_task: TaskKind
    battery: float | None = None

    @property
    def vehicle(self) -> int:
        return self.freeze.vehicle

    def to_record(self) -> list:
        f = self.freeze
        return [HALTED, f.vehicle, f.t, self.cause, self.next_task.value, str(f.pose),
                f.t_stand, cells_out(f.cells),
                list(step_to_wire(f.step)) if f.step is not None else None, self.battery]


@dataclass(frozen=True)
class Resumed:
    """The forklift that was down moves again from t."""

    vehicle: int
    t: float

    def to_record(self) -> list:
        return [RESUMED, self.vehicle, self.t]


def is_halt_record(raw: object) -> bool:
    """Whether a journal record is one of these (the rest are an order mission's book)."""
    return isinstance(raw, list) and bool(raw) and raw[0] in (HALTED, RESUMED)


def from_record(raw: object) -> Halted | Resumed:
    if not is_halt_record(raw):
        raise ValueError(f"not a {HALTED} or {RESUMED} record: {raw!r:.80}")
    kind, fields = raw[0], raw[1:]
    if kind == RESUMED:
        if len(fields) != 2:
            raise ValueError(f"a {RESUMED} record has 2 fields, not {len(fields)}")
        return Resumed(vehicle_field(fields[0]), time_field(fields[1], "t"))
    if len(fields) != 9:
        raise ValueError(f"a {HALTED} record has 9 fields, not {len(fields)}")
    vehicle, t, cause, task, pose, t_stand, cells, step, battery = fields
    if not isinstance(cause, str) or not isinstance(pose, str):
        raise ValueError(f"cause and pose must be text, not {cause!r:.40} and {pose!r:.40}")
    try:
        next_task = TaskKind(task)
    except ValueError:
        raise ValueError(f"unknown task kind {task!r:.40}") from None
    try:
        in_progress = step_from_wire(step, f"{HALTED}.step") if step is not None else None
    except (ProtocolError, TypeError, ValueError) as exc:
        raise ValueError(f"the maneuver in progress is malformed: {exc}") from None
    freeze = Freeze(vehicle_field(vehicle), time_field(t, "t"), cells_field(cells),
                    in_progress, Pose.parse(pose), time_field(t_stand, "t_stand"))
    if battery is not None and not (isinstance(battery, int | float) and
                                    not isinstance(battery, bool) and 0 <= battery <= 100):
        raise ValueError(f"battery must be a charge within 0..100 % or nil, not "
                         f"{battery!r:.40}")
    return Halted(freeze, cause, next_task, None if battery is None else float(battery))

def standing(records: Iterable[object]) -> dict[int, Halted]:
    """The forklifts down after these records (the halt records among a journal's), by
    vehicle: each one's last freeze not followed by its resumption."""
    down: dict[int, Halted] = {}
    for raw in records:
        record = from_record(raw)
        if isinstance(record, Halted):
            down[record.vehicle] = record
        else:
            down.pop(record.vehicle, None)
    return down

