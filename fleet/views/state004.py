"""Where a seed-004 run's lifting AGVs are, which way each faces and which shelf each
carries, at any instant, from the run's tracking events alone (fleet/mission/tracking004.py;
a recording's: fleet/analysis/analyze004.py `recorded_events`). The Foxglove scene
(scene004.py) follows each AGV event by event with `AgvTrack`; a snapshot (snapshot004.py)
asks `floor_at` for one instant. Both read the events by one rule:

- a move is under way over [t0, t1): the AGV is between its two cells, as far along as the
  time gone; from t1 it is in the next cell;
- a turn shows the new heading from its start;
- a lift puts its slot's shelf on the AGV at the lift's end, and a drop puts it home at the
  drop's end: in between the shelf is away and its slot empty;
- a breakdown holds from its instant until the repair it names, or an earlier `Repaired`;
  a zone is closed over [t0, t1).

Everything that has ended by an event's start is settled before the event applies. Cells
are the floor's (x = column, y = row from the top, as the seed writes them). Pure: events
in, no I/O.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from fleet.mission.tracking004 import (
    BrokeDown,
    Event,
    Moved,
    Paused,
    Picked,
    Repaired,
    Turned,
    ZoneClosed,
)
from fleet.planning.rules004 import XY, Direction

START_HEADING = Direction.DOWN  # how Mission004 places its AGVs (fleet/mission/orders004.py)


def event_start(e: Event) -> float:
    """The instant an event begins (a move, turn, pause or closed zone its t0)."""
    return e.t0 if isinstance(e, Moved | Turned | Paused | ZoneClosed) else e.t


@dataclass
class AgvTrack:
    """One AGV as its events have told so far."""

    cell: XY  # where it stands, or the cell it leaves while it moves
    heading: Direction = START_HEADING
    to: XY | None = None  # moving from `cell` to `to` over [t0, t1)
    t0: float = 0.0
    t1: float = 0.0
    shelf: XY | None = None  # the home of the shelf it carries (from the lift's end)
    lift_at: tuple[float, XY] | None = None  # a lift under way: it carries from then
    drop_at: float | None = None  # a drop under way: it carries until then
    down: tuple[float, float] = (0.0, 0.0)  # broken down over [t0, t1)

    def apply(self, e: Event) -> None:
        """One of this AGV's events (those that change nothing drawn are ignored)."""
        self.settle(event_start(e))
        if isinstance(e, Moved):
            self.cell, self.to, self.t0, self.t1 = e.origin, e.to, e.t0, e.t1
        elif isinstance(e, Turned):
            self.heading = e.heading
        elif isinstance(e, Paused) and e.label == "lift":
            self.lift_at = (e.t1, e.at)
        elif isinstance(e, Paused) and e.label == "drop":
            self.drop_at = e.t1
        elif isinstance(e, BrokeDown):
            self.down = (e.t, e.until)
        elif isinstance(e, Repaired) and self.down[0] <= e.t < self.down[1]:
            self.down = (self.down[0], e.t)  # back before the breakdown said

    def settle(self, t: float) -> None:
        """What has ended by `t`: a move, a lift, a drop."""
        if self.to is not None and self.t1 <= t:
            self.cell, self.to = self.to, None
        if self.lift_at is not None and self.lift_at[0] <= t:
            self.shelf, self.lift_at = self.lift_at[1], None
        if self.drop_at is not None and self.drop_at <= t:
            self.shelf, self.drop_at = None, None

    def share(self, t: float) -> float:
        """How far along its move it is at `t` (0 standing still)."""
        if self.to is None or self.t1 <= self.t0:
            return 0.0
        return min(max((t - self.t0) / (self.t1 - self.t0), 0.0), 1.0)

    def broken(self, t: float) -> bool:
        return self.down[0] <= t < self.down[1]


@dataclass(frozen=True)
class AgvAt:
    """An AGV at one instant."""

    vehicle: int
    cell: XY  # where it stands, or the cell it leaves
    to: XY | None  # the cell it is moving into
    x: float  # where it is, in cells: between `cell` and `to` while it moves
    y: float
    heading: Direction
    shelf: XY | None  # the home slot of the shelf it carries
    down: bool  # broken down


@dataclass(frozen=True)
class FloorAt:
    """The floor at one instant: every AGV, the shelves away from home, the closed cells."""

    t: float
    agvs: tuple[AgvAt, ...]  # by number
    away: frozenset[XY]  # slots whose shelf rides on an AGV
    closed: frozenset[XY]  # cells of zones closed at t
    picked: int  # orders picked by t


def closed_at(zones: Iterable[ZoneClosed], t: float) -> frozenset[XY]:
    """The cells of the zones closed at `t`."""
    return frozenset(xy for z in zones if z.t0 <= t < z.t1 for xy in z.cells)


def at(vehicle: int, track: AgvTrack, t: float) -> AgvAt:
    """A followed AGV as it is at `t` (settled to t)."""
    x, y = track.cell
    if track.to is not None:
        share = track.share(t)
        x, y = x + (track.to[0] - x) * share, y + (track.to[1] - y) * share
    return AgvAt(vehicle, track.cell, track.to, x, y, track.heading, track.shelf,
                 track.broken(t))


def floor_at(events: Iterable[Event], starts: Mapping[int, XY], t: float) -> FloorAt:
    """The floor at `t` from a run's events: the AGVs numbered as `starts` (each one's start
    cell) and the events begun by t, in order of their start (equal starts in the order
    given)."""
    tracks = {v: AgvTrack(xy) for v, xy in starts.items()}
    zones: list[ZoneClosed] = []
    picked = 0
    for e in sorted(events, key=event_start):
        if event_start(e) > t:
            break
        if isinstance(e, ZoneClosed):
            zones.append(e)
        elif isinstance(e, Picked):
            picked += 1
        elif e.vehicle in tracks:
            tracks[e.vehicle].apply(e)
    for track in tracks.values():
        track.settle(t)
    agvs = tuple(at(v, tracks[v], t) for v in sorted(tracks))
    return FloorAt(t, agvs, frozenset(a.shelf for a in agvs if a.shelf is not None),
                   closed_at(zones, t), picked)
