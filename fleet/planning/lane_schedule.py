"""A one-cell AGV's route in time (seed 002, Section 5.2), and the cells its body touches.

The paper times a route by its arrival times: τ_{m+1} = τ_m + t_m + d(C_m, C_{m+1}) / v,
where t_m is how long the AGV stands at node m (a wait inserted by a collision rule, the
packing dwell). The store of reservations keeps bodies apart by cells, so a schedule also says
which cells its unit body touches when: the node it stands on while it stands; both cells of a
straight move while it is made (it leaves one as it enters the other); all four cells of the
2 x 2 block a diagonal move cuts across (the body's corners sweep the two cells beside the
diagonal). Two schedules whose touches never share a cell at one time never collide, which is
what the store promises and the recording's verifier checks apart from this code.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from functools import cached_property

from fleet.planning.geometry import Cell
from fleet.planning.lane_route import move_length
from fleet.planning.reservations import INF, Interval, TimedRoute
from fleet.planning.trajectory import merge_intervals


@dataclass(frozen=True)
class Touch:
    """Cells the body touches over [t0, t1): standing at node `node` (`moving` False) or
    moving from node `node` to the next."""

    t0: float
    t1: float
    cells: frozenset[Cell]
    node: int
    moving: bool


@dataclass(frozen=True)
class Schedule:
    """One AGV's route with its arrival time at each node and how long it stands there;
    the last node's dwell may be infinite (it stays)."""

    vehicle: int
    cells: tuple[Cell, ...]
    arrivals: tuple[float, ...]  # τ_m
    dwells: tuple[float, ...]  # t_m
    seconds_per_cell: float

    def __post_init__(self) -> None:
        if not (len(self.cells) == len(self.arrivals) == len(self.dwells) >= 1):
            raise ValueError("a schedule has one arrival time and one dwell per node")

    def departure(self, node: int) -> float:
        return self.arrivals[node] + self.dwells[node]

    @property
    def t_end(self) -> float:
        """When it arrives at its last node."""
        return self.arrivals[-1]

    def waited(self, node: int, seconds: float) -> Schedule:
        """The schedule with `seconds` more standing at `node`: every later arrival shifts."""
        if seconds < 0:
            raise ValueError(f"a wait lasts zero seconds or more, not {seconds}")
        dwells = list(self.dwells)
        dwells[node] += seconds
        arrivals = [*self.arrivals[:node + 1],
                    *(t + seconds for t in self.arrivals[node + 1:])]
        return Schedule(self.vehicle, self.cells, tuple(arrivals), tuple(dwells),
                        self.seconds_per_cell)

    def touches(self) -> list[Touch]:
        """Standing and moving, in time order (zero-length stands left out)."""
        return self._touches

    @cached_property
    def touched(self) -> frozenset[Cell]:
        """Every cell it touches at some time."""
        return frozenset().union(*(t.cells for t in self._touches))

    @cached_property
    def _touches(self) -> list[Touch]:  # a schedule is asked again and again while settled
        found = []
        for m, cell in enumerate(self.cells):
            if self.dwells[m] > 0:
                found.append(Touch(self.arrivals[m], self.departure(m), frozenset({cell}),
                                   m, False))
            if m + 1 < len(self.cells):
                nxt = self.cells[m + 1]
                block = {cell, nxt, (cell[0], nxt[1]), (nxt[0], cell[1])}
                found.append(Touch(self.departure(m), self.arrivals[m + 1], frozenset(block),
                                   m, True))
        return found

    def intervals(self) -> tuple[Interval, ...]:
        """The touches as reservations, merged per cell."""
        return merge_intervals((cell, t.t0, t.t1) for t in self.touches() for cell in t.cells)


def timed(vehicle: int, cells: tuple[Cell, ...], t_start: float, seconds_per_cell: float,
          dwell_at_end: float = INF) -> Schedule:
    """A route driven without stopping from `t_start` on, standing `dwell_at_end` at its
    last node (for good, by default)."""
    arrivals = [t_start]
    for a, b in itertools.pairwise(cells):
        arrivals.append(arrivals[-1] + move_length(a, b) * seconds_per_cell)
    dwells = [0.0] * (len(cells) - 1) + [dwell_at_end]
    return Schedule(vehicle, tuple(cells), tuple(arrivals), tuple(dwells), seconds_per_cell)


def as_route(schedule: Schedule) -> TimedRoute:
    """The schedule as the store shares it with other vehicles."""
    return TimedRoute(schedule.cells, schedule.arrivals, schedule.dwells)


def from_route(vehicle: int, route: TimedRoute, seconds_per_cell: float) -> Schedule:
    return Schedule(vehicle, route.cells, route.arrivals, route.dwells, seconds_per_cell)
