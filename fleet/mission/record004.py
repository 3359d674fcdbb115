"""A seed-004 mission on the wire and in a recording: each tracking event as an `AgvEvent`
and back (the dispatcher publishes them, `fleet analyze` reads them), and the mission's
result as the record whose digest says whether two runs are one bit for bit."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from fleet.mission.faults import Fault
from fleet.mission.freeze import BREAKDOWN
from fleet.mission.orders004 import Mission004, Result004, generate_orders
from fleet.mission.record import digest_of
from fleet.mission.spec import Mission
from fleet.mission.tracking004 import (
    BrokeDown,
    Conflict,
    Event,
    Leg,
    LegDone,
    MadeWay,
    Met,
    Moved,
    Paused,
    Picked,
    Repaired,
    Replanned,
    Stagnant,
    TrackingParams,
    Turned,
    Vehicles,
    ZoneClosed,
)
from fleet.planning.astar004 import Costs
from fleet.planning.rules004 import Direction, Task
from fleet.wire.protocol import AgvEvent, Message, MissionDone, MissionInfo, Progress
from fleet.world.floor004 import Floor004


def event_to_wire(e: Event) -> AgvEvent:
    match e:
        case Moved():
            return AgvEvent("moved", e.vehicle, e.t0, e.t1, e.origin, e.to, task=e.task.value,
                            loaded=e.loaded, relaxed=e.relaxed)
        case Turned():
            return AgvEvent("turned", e.vehicle, e.t0, e.t1, e.at, heading=int(e.heading))
        case Paused():
            return AgvEvent("paused", e.vehicle, e.t0, e.t1, e.at, label=e.label)
        case Met():
            return AgvEvent("met", e.vehicle, e.t, e.t, e.at, e.cell, other=e.other,
                            label=e.kind.value)
        case Stagnant():
            return AgvEvent("stagnant", e.vehicle, e.t, e.t, e.at)
        case Replanned():
            return AgvEvent("replanned", e.vehicle, e.t, e.t, label=e.why, relaxed=e.relaxed,
                            found=e.found)
        case MadeWay():
            return AgvEvent("made_way", e.vehicle, e.t, e.t, e.at, e.to, other=e.idle)
        case Picked():
            return AgvEvent("picked", e.vehicle, e.t, e.t, label=e.station)
        case BrokeDown():  # a breakdown's label stays empty, as before causes were told
            return AgvEvent("broke_down", e.vehicle, e.t, e.until, e.at,
                            label="" if e.cause == BREAKDOWN else e.cause)
        case Repaired():
            return AgvEvent("repaired", e.vehicle, e.t, e.t, e.at)
        case ZoneClosed():
            return AgvEvent("zone_closed", 0, e.t0, e.t1, cells=list(e.cells))
        case LegDone():
            leg = e.leg
            return AgvEvent("leg_done", e.vehicle, e.t, e.t, to=leg.goal, task=leg.task.value,
                            label=leg.station.name if leg.station is not None else "",
                            home=leg.home, make_way=leg.make_way, charge_s=leg.charge_s)
    raise TypeError(f"not a tracking event: {e!r}")


class NotAnEvent(ValueError):
    """An AgvEvent that names no event of this floor (its kind, task or station)."""


def event_from_wire(m: AgvEvent, floor: Floor004) -> Event:
    """The event an AgvEvent carries; NotAnEvent names what does not fit."""
    try:
        return _event(m, floor)
    except (ValueError, KeyError, TypeError) as exc:
        raise NotAnEvent(f"{m.kind} event of AGV {m.vehicle} at t={m.t0}: {exc}") from None


def _event(m: AgvEvent, floor: Floor004) -> Event:
    match m.kind:
        case "moved":
            if m.to is None:
                raise ValueError("a move names where it goes")
            return Moved(m.vehicle, m.t0, m.t1, m.at, m.to, Task(m.task), m.loaded, m.relaxed)
        case "turned":
            return Turned(m.vehicle, m.t0, m.t1, m.at, Direction(m.heading))
        case "paused":
            return Paused(m.vehicle, m.t0, m.t1, m.at, m.label)
        case "met":
            if m.to is None:
                raise ValueError("a meeting names the cell wanted")
            return Met(m.t0, m.vehicle, m.other, m.at, m.to, Conflict(m.label))
        case "stagnant":
            return Stagnant(m.t0, m.vehicle, m.at)
        case "replanned":
            return Replanned(m.t0, m.vehicle, m.label, m.relaxed, m.found)
        case "made_way":
            if m.to is None:
                raise ValueError("an AGV sent out of the way is sent somewhere")
            return MadeWay(m.t0, m.vehicle, m.other, m.at, m.to)
        case "picked":
            return Picked(m.t0, m.vehicle, m.label)
        case "broke_down":
            return BrokeDown(m.t0, m.vehicle, m.at, m.t1, m.label or BREAKDOWN)
        case "repaired":
            return Repaired(m.t0, m.vehicle, m.at)
        case "zone_closed":
            return ZoneClosed(m.t0, m.t1, tuple(m.cells))
        case "leg_done":
            if m.to is None:
                raise ValueError("a leg has a goal")
            stations = {s.name: s for s in floor.stations}
            station = stations[m.label] if m.label else None
            return LegDone(m.t0, m.vehicle, Leg(Task(m.task), m.to, m.home, station,
                                                 m.make_way, m.charge_s))
    raise ValueError(f"unknown kind {m.kind!r}")


def record_of(result: Result004) -> dict[str, Any]:
    """The mission's result as plain data: what `fleet run` reports and digests (the events
    whole, so equal digests mean the same mission move for move)."""
    return {
        "completion_s": result.completion_s,
        "end_time_s": max(result.completion_s, result.shelves_home_s),
        "shelves_home_s": result.shelves_home_s,
        "orders_picked": len(result.picked),
        "recalled": sum(p.recalled for p in result.picked),
        "charges": result.charges,
        "lowest_soc": result.lowest_soc,
        "counts": dict(sorted(result.counts.items())),
        "events": len(result.events),
        "events_digest": digest_of({"events": [repr(e) for e in result.events]}),
    }


Publish = Callable[[Message, float], None]


def tracking_params(info: MissionInfo) -> TrackingParams:
    """The tracker's settings as the run's description gives them, so the dispatcher and
    every agent plan with the very same costs (the heat's T_value included)."""
    return TrackingParams(costs=Costs(heat=info.heat_w,
                                      t_value={(x, y): v for x, y, v in info.heat}))


def run_mission004(mission: Mission, floor: Floor004, vehicles: int, fleet: Vehicles | None,
                   publish: Publish, pace: Callable[[float], None] | None = None,
                   tracking: TrackingParams | None = None, faults: tuple[Fault, ...] = ()
                   ) -> MissionDone:
    """Run the order mission (its orders drawn with its seed) through `fleet` (None: in this
    process), publishing each event and each picked order as it happens; `pace` holds each
    instant until its time comes (a real-time clock); `faults` strike at their instants."""
    t0 = time.perf_counter()
    orders = generate_orders(floor, mission.orders, mission.seed)
    picked = 0

    def on_event(e: Event) -> None:
        nonlocal picked
        wire = event_to_wire(e)
        publish(wire, wire.t0)
        if isinstance(e, Picked):
            picked += 1
            publish(Progress(picked, len(orders), e.t, 0), e.t)

    result = Mission004(floor, vehicles, orders, tracking or TrackingParams(), fleet=fleet,
                        on_event=on_event, pace=pace, faults=faults).run()
    record = record_of(result)
    return MissionDone(True, record=record, digest=digest_of(record),
                       wall_s=time.perf_counter() - t0)
