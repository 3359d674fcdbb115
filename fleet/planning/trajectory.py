"""Timed trajectories and planning outcomes (plain data)."""

from __future__ import annotations

import itertools
from collections.abc import Iterable
from dataclasses import dataclass
from enum import Enum

from fleet.planning.geometry import Cell
from fleet.planning.maneuvers import HEADINGS, Kind, Manner
from fleet.planning.reservations import Interval
from fleet.planning.velocity import Speed


@dataclass(frozen=True, order=True)
class Pose:
    """Cell of the rear-axle point and heading index (0 E, 1 N, 2 W, 3 S)."""

    cell: Cell
    heading: int

    def __str__(self) -> str:
        return f"{self.cell[0]},{self.cell[1]},{HEADINGS[self.heading]}"

    @classmethod
    def parse(cls, text: str) -> Pose:
        """'col,row,H' with H one of E N W S."""
        parts = [p.strip() for p in text.split(",")]
        if len(parts) != 3 or parts[2].upper() not in HEADINGS:
            raise ValueError(f"pose {text!r} must look like 'col,row,H' with H in E N W S")
        try:
            cell = (int(parts[0]), int(parts[1]))
        except ValueError:
            raise ValueError(f"pose {text!r}: column and row must be integers") from None
        return cls(cell, HEADINGS.index(parts[2].upper()))


class LaneMove(Enum):
    """The steps of seed 002's one-cell AGV: a move to one of the four neighbours (d = 1), a
    diagonal one (d = 1.4), and standing at a node (a wait a collision rule inserted). Kind
    and direction as a forklift manner has them, so a trajectory counts either the same."""

    MOVE = ("move", Kind.STRAIGHT, 1)
    DIAGONAL = ("diagonal", Kind.STRAIGHT, 1)
    WAIT = ("wait", Kind.STOP, 0)

    def __init__(self, label: str, kind: Kind, direction: int) -> None:
        self.label = label
        self.kind = kind
        self.direction = direction


StepManner = Manner | LaneMove


def step_manner(label: str) -> StepManner:
    """The manner or lane move a step label names (ValueError for none)."""
    for move in LaneMove:
        if move.label == label:
            return move
    return Manner.from_label(label)


@dataclass(frozen=True)
class Step:
    """One maneuver of a trajectory, over [t0, t1), sweeping `cells`."""

    manner: StepManner
    start: Pose
    end: Pose
    t0: float
    t1: float
    v0: Speed
    v1: Speed
    cells: frozenset[Cell]


@dataclass(frozen=True)
class Trajectory:
    vehicle: int
    start: Pose
    goal: Pose
    t_start: float
    steps: tuple[Step, ...]
    intervals: tuple[Interval, ...]  # merged per cell; the parking cells run to infinity
    expansions: int

    @property
    def t_end(self) -> float:
        return self.steps[-1].t1 if self.steps else self.t_start

    def counts(self) -> dict[str, int]:
        """Turns, lane changes and direction reversals (the penalised maneuvers)."""
        turns = sum(s.manner.kind.value == "turn" for s in self.steps)
        lanes = sum(s.manner.kind.value == "lane" for s in self.steps)
        dirs = [s.manner.direction for s in self.steps if s.manner.direction]
        reversals = sum(a != b for a, b in itertools.pairwise(dirs))
        return {"turns": turns, "lane_changes": lanes, "reversals": reversals}


class FailureReason(Enum):
    START_BLOCKED = "start blocked"
    GOAL_BLOCKED = "goal blocked"
    NO_PATH = "no path"
    ITERATION_CAP = "iteration cap"
    LATE = "late"  # real time: the plan was ready only after its own start instant
    REFUSED = "commit refused"  # the reservation store refused every replanned commit
    DEADLOCK = "deadlock"  # seed 002: the collision rules could not settle a collision


@dataclass(frozen=True)
class PlanFailure:
    reason: FailureReason
    detail: str
    expansions: int


def merge_intervals(pieces: Iterable[tuple[Cell, float, float]]) -> tuple[Interval, ...]:
    """Merge touching or overlapping pieces per cell; sorted by cell then time."""
    by_cell: dict[Cell, list[tuple[float, float]]] = {}
    for cell, t0, t1 in pieces:
        by_cell.setdefault(cell, []).append((t0, t1))
    out = []
    for cell in sorted(by_cell):
        spans = sorted(by_cell[cell])
        cur0, cur1 = spans[0]
        for t0, t1 in spans[1:]:
            if t0 <= cur1:
                cur1 = max(cur1, t1)
            else:
                out.append(Interval(cell, cur0, cur1))
                cur0, cur1 = t0, t1
        out.append(Interval(cell, cur0, cur1))
    return tuple(out)
