"""Seed 004's safety from the moves alone (B-SAF-1), sharing nothing with the tracker or its
planner: an AGV holds a cell from the instant it starts into it until the instant it is in
the next one, one cell at rest and two while it moves. Two AGVs never hold one cell at
once (which also rules out swaps), and every move is one cell in one of four directions."""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

Cell = tuple[int, int]


@dataclass(frozen=True)
class Move:
    vehicle: int
    t0: float  # starts out of `origin`
    t1: float  # in `to`
    origin: Cell
    to: Cell


@dataclass(frozen=True)
class Clash:
    cell: Cell
    vehicles: tuple[int, int]
    t: float  # when both first held it


@dataclass(frozen=True)
class BadMove:
    move: Move
    why: str


def held(moves: Iterable[Move], starts: Mapping[int, Cell]
         ) -> tuple[list[tuple[int, Cell, float, float]], list[BadMove]]:
    """Each AGV's cells over time, (vehicle, cell, t0, t1), and the moves that cannot be
    driven (not from where it stood, not one cell of four directions, back in time)."""
    spans, bad = [], []
    by_vehicle: dict[int, list[Move]] = defaultdict(list)
    for m in moves:
        by_vehicle[m.vehicle].append(m)
    for v, start in sorted(starts.items()):
        cell, since, free_at = start, 0.0, 0.0  # free_at: when the last move ended
        for m in sorted(by_vehicle.pop(v, []), key=lambda m: m.t0):
            if m.origin != cell:
                bad.append(BadMove(m, f"starts at {m.origin}, but the AGV is at {cell}"))
            elif abs(m.to[0] - cell[0]) + abs(m.to[1] - cell[1]) != 1:
                bad.append(BadMove(m, f"{m.origin} -> {m.to} is not one cell in one of "
                                      f"four directions"))
            elif not free_at <= m.t0 < m.t1:
                bad.append(BadMove(m, f"starts at t={m.t0} before the last move ended or "
                                      f"ends before it starts"))
            spans.append((v, cell, since, m.t1))
            cell, since, free_at = m.to, m.t0, m.t1
        spans.append((v, cell, since, math.inf))
    bad += [BadMove(m, f"AGV {v} has no start") for v, ms in by_vehicle.items() for m in ms]
    return spans, bad


def clashes(spans: Iterable[tuple[int, Cell, float, float]]) -> list[Clash]:
    """Every cell two AGVs held over overlapping times."""
    by_cell: dict[Cell, list[tuple[float, float, int]]] = defaultdict(list)
    for v, cell, t0, t1 in spans:
        by_cell[cell].append((t0, t1, v))
    found = []
    for cell, spans_here in sorted(by_cell.items()):
        spans_here.sort()
        for k, (_, a1, a) in enumerate(spans_here):
            for b0, _, b in spans_here[k + 1:]:
                if b0 >= a1:
                    break  # sorted by start: none later overlaps this one
                if a != b:
                    found.append(Clash(cell, (min(a, b), max(a, b)), b0))
    return found
