"""What an order mission's work is fed (fleet/mission/order_work.py), one input at a time, as
plain records: its dispatcher journals them, and a new dispatcher replays them to have the
order book as the dead one left it (docs/faults.md, "A restarted dispatcher picks the mission
up"). The book is a function of its inputs, so the replay is exact.

A record is a list: its kind's name, then its fields. `from_record` takes anything msgpack
gives back and raises ValueError naming what is wrong.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from fleet.dispatching.decision import TaskKind
from fleet.planning.geometry import Cell


@dataclass(frozen=True)
class Advance:
    """What happens by itself up to t (arrivals, dwells ending, batteries full, zones open)."""

    t: float


@dataclass(frozen=True)
class Served:
    """The vehicle's decided trip was committed: a leg over [t_start, t_end], `driven`
    seconds of it moving."""

    vehicle: int
    t_start: float
    t_end: float
    driven: float


@dataclass(frozen=True)
class Amended:
    """The vehicle's committed leg from t_start was postponed: it now ends at t_end."""

    vehicle: int
    t_start: float
    t_end: float
    driven: float


@dataclass(frozen=True)
class Cancelled:
    """The vehicle's committed trip of `kind` was cut short, `driven` seconds of it driven."""

    vehicle: int
    kind: TaskKind
    driven: float


@dataclass(frozen=True)
class Down:
    """The vehicle stands for good on `cells` from t on."""

    vehicle: int
    t: float
    cells: frozenset[Cell]


@dataclass(frozen=True)
class Up:
    """The vehicle moves again from t, from `cell`."""

    vehicle: int
    t: float
    cell: Cell


@dataclass(frozen=True)
class Closed:
    """A zone closes `cells` over [t, until)."""

    cells: frozenset[Cell]
    t: float
    until: float


Input = Advance | Served | Amended | Cancelled | Down | Up | Closed


class WorkLog(Protocol):
    """Where the inputs go as they are taken (a dispatcher's journal file)."""

    def append(self, record: list) -> None: ...


def to_record(i: Input) -> list:
    match i:
        case Advance(t):
            return ["advance", t]
        case Served(vehicle, t_start, t_end, driven):
            return ["served", vehicle, t_start, t_end, driven]
        case Amended(vehicle, t_start, t_end, driven):
            return ["amended", vehicle, t_start, t_end, driven]
        case Cancelled(vehicle, kind, driven):
            return ["cancelled", vehicle, kind.value, driven]
        case Down(vehicle, t, cells):
            return ["down", vehicle, t, cells_out(cells)]
        case Up(vehicle, t, cell):
            return ["up", vehicle, t, list(cell)]
        case Closed(cells, t, until):
            return ["closed", cells_out(cells), t, until]
    raise TypeError(f"not an order work input: {i!r}")


def from_record(raw: object) -> Input:
    """The input a record holds; ValueError naming what is wrong with it."""
    if not isinstance(raw, list) or not raw or not isinstance(raw[0], str):
        raise ValueError(f"not a record (a list led by its kind): {raw!r:.80}")
    kind, fields = raw[0], raw[1:]
    shapes = {"advance": 1, "served": 4, "amended": 4, "cancelled": 3, "down": 3, "up": 3,
              "closed": 3}
    if kind not in shapes:
        raise ValueError(f"unknown record kind {kind!r}")
    if len(fields) != shapes[kind]:
        raise ValueError(f"a {kind} record has {shapes[kind]} fields, not {len(fields)}")
    if kind == "advance":
        return Advance(time_field(fields[0], "t"))
    if kind in ("served", "amended"):
        cls = Served if kind == "served" else Amended
        return cls(vehicle_field(fields[0]), time_field(fields[1], "t_start"),
                   time_field(fields[2], "t_end"), time_field(fields[3], "driven"))
    if kind == "cancelled":
        try:
            task = TaskKind(fields[1])
        except ValueError:
            raise ValueError(f"unknown trip kind {fields[1]!r}") from None
        return Cancelled(vehicle_field(fields[0]), task, time_field(fields[2], "driven"))
    if kind == "down":
        return Down(vehicle_field(fields[0]), time_field(fields[1], "t"), cells_field(fields[2]))
    if kind == "up":
        return Up(vehicle_field(fields[0]), time_field(fields[1], "t"), cell_field(fields[2]))
    return Closed(cells_field(fields[0]), time_field(fields[1], "t"),
                  time_field(fields[2], "until", infinite=True))


def vehicle_field(value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"vehicle must be a number from 1, not {value!r:.40}")
    return value


def time_field(value: object, name: str, infinite: bool = False) -> float:
    ok = isinstance(value, int | float) and not isinstance(value, bool) and \
        not math.isnan(value) and value >= 0 and (infinite or math.isfinite(value))
    if not ok:
        raise ValueError(f"{name} must be a time in seconds, not {value!r:.40}")
    return float(value)


def cell_field(value: object) -> Cell:
    if not (isinstance(value, list) and len(value) == 2 and
            all(isinstance(v, int) and not isinstance(v, bool) for v in value)):
        raise ValueError(f"a cell is [col, row], not {value!r:.40}")
    return (value[0], value[1])


def cells_field(value: object) -> frozenset[Cell]:
    if not isinstance(value, list):
        raise ValueError(f"cells are a list of [col, row], not {value!r:.40}")
    return frozenset(cell_field(v) for v in value)


def cells_out(cells: frozenset[Cell]) -> list[list[int]]:
    return [list(c) for c in sorted(cells)]
