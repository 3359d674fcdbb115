"""Paired conversions between core objects and wire messages (fleet/wire/protocol.py), each
written once. Every `*_from_wire` validates what `decode` does not (pose syntax of the
free-text fields, enum values, time order) and raises ProtocolError naming the field; the
interval and change conversions raise the interval's own ValueError (their callers know the
field, and the reservation store answers with that text as it is)."""

from __future__ import annotations

from collections.abc import Iterable

from fleet.planning.reservations import (
    Amendment,
    Change,
    Interval,
    Reservation,
    Snapshot,
    TimedRoute,
)
from fleet.planning.trajectory import Pose, Step, Trajectory, step_manner
from fleet.planning.velocity import Speed
from fleet.wire.protocol import (
    ProtocolError,
    WireAmend,
    WireChange,
    WireHeld,
    WireInterval,
    WireLeg,
    WireRoute,
    WireSnapshot,
    WireStep,
)


def pose_from_wire(text: str, where: str) -> Pose:
    try:
        return Pose.parse(text)
    except ValueError as exc:
        raise ProtocolError(f"{where}: {exc}") from None


def step_to_wire(s: Step) -> WireStep:
    return (s.manner.label, str(s.start), str(s.end), s.t0, s.t1, int(s.v0), int(s.v1),
            sorted(s.cells))


def step_from_wire(step: WireStep, where: str) -> Step:
    label, start, end, t0, t1, v0, v1, cells = step
    try:
        manner, s0, s1 = step_manner(label), Speed(v0), Speed(v1)
    except ValueError as exc:
        raise ProtocolError(f"{where}: {exc}") from None
    if not t0 < t1:
        raise ProtocolError(f"{where}: a maneuver must end after it starts, not [{t0}, {t1})")
    return Step(manner, pose_from_wire(start, where), pose_from_wire(end, where), t0, t1, s0, s1,
                frozenset((c, r) for c, r in cells))


def intervals_to_wire(intervals: Iterable[Interval]) -> list[WireInterval]:
    return [(iv.cell[0], iv.cell[1], iv.t0, iv.t1) for iv in intervals]


def intervals_from_wire(wire: Iterable[WireInterval]) -> tuple[Interval, ...]:
    """ValueError for an interval that does not end after it starts."""
    return tuple(Interval((c, r), t0, t1) for c, r, t0, t1 in wire)


def route_to_wire(route: TimedRoute | None) -> WireRoute | None:
    if route is None:
        return None
    return [list(c) for c in route.cells], list(route.arrivals), list(route.dwells)


def route_from_wire(wire: WireRoute | None) -> TimedRoute | None:
    """ValueError for a route whose lists do not match."""
    if wire is None:
        return None
    cells, arrivals, dwells = wire
    return TimedRoute(tuple((c, r) for c, r in cells), tuple(arrivals), tuple(dwells))


def held_to_wire(held: Iterable[Reservation]) -> list[WireHeld]:
    return [(r.vehicle, r.cell[0], r.cell[1], r.t0, r.t1) for r in held]


def held_from_wire(wire: Iterable[WireHeld]) -> tuple[Reservation, ...]:
    return tuple(Reservation(v, (c, r), t0, t1) for v, c, r, t0, t1 in wire)


def snapshot_from_wire(wire: WireSnapshot) -> Snapshot:
    """A whole table as the service sends it (not a diff: that is `changes`)."""
    return Snapshot(wire.revision, held_from_wire(wire.reservations),
                    tuple((v, route) for v, w in wire.routes
                          if (route := route_from_wire(w)) is not None))


def change_to_wire(change: Change) -> WireChange:
    """A table change as the reservation service publishes it (no request id: made in this
    process). Release cells go in sorted order."""
    cells = None if change.release_cells is None else sorted(change.release_cells)
    return WireChange(change.revision, change.op, change.vehicle,
                      intervals_to_wire(change.intervals), change.release_from,
                      release_cells=cells, route=route_to_wire(change.route))


def change_from_wire(change: WireChange) -> Change:
    """A published change as the table applies it (ValueError for a bad interval or
    route)."""
    cells = None if change.release_cells is None else \
        frozenset((c, r) for c, r in change.release_cells)
    return Change(change.revision, change.vehicle, change.release_from,
                  intervals_from_wire(change.intervals), cells, change.op,
                  route_from_wire(change.route))


def amends_to_wire(amends: Iterable[Amendment]) -> list[WireAmend]:
    return [(a.vehicle, a.release_from, intervals_to_wire(a.intervals),
             route_to_wire(a.route)) for a in amends]


def amends_from_wire(wire: Iterable[WireAmend]) -> tuple[Amendment, ...]:
    """ValueError for an interval that does not end after it starts, or a bad route."""
    return tuple(Amendment(v, release_from, intervals_from_wire(ivs), route_from_wire(route))
                 for v, release_from, ivs, route in wire)


def leg_to_wire(leg: Trajectory) -> WireLeg:
    return (leg.vehicle, str(leg.start), str(leg.goal), leg.t_start,
            [step_to_wire(s) for s in leg.steps], intervals_to_wire(leg.intervals))


def leg_from_wire(wire: WireLeg, where: str) -> Trajectory:
    """ProtocolError naming `where` for a bad step or interval."""
    vehicle, start, goal, t_start, steps, intervals = wire
    try:
        held = intervals_from_wire(intervals)
    except ValueError as exc:
        raise ProtocolError(f"{where}: {exc}") from None
    return Trajectory(vehicle, pose_from_wire(start, where), pose_from_wire(goal, where),
                      t_start, tuple(step_from_wire(s, where) for s in steps), held, 0)


def change_time(change: WireChange) -> float:
    """The sim time a change is about (its publish time in a recording): where it releases
    from, else where its first interval starts."""
    if change.release_from is not None:
        return change.release_from
    return min((iv[2] for iv in change.intervals), default=0.0)
