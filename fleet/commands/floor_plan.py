"""`fleet plan` on a seed-004 floor: one query of the improved A* (docs/agv-004.md), on the
floor with nothing else on it, with the task's traffic rules and the turning cost."""

from __future__ import annotations

import argparse
import time

from fleet.errors import UserError
from fleet.planning.astar004 import Costs, plan
from fleet.planning.rules004 import XY, Kind, Task
from fleet.world.floor004 import Floor004
from fleet.world.layout import Layout
from fleet.world.places import col_row

TASKS = {"fetch": Task.FETCH, "deliver": Task.DELIVER, "return": Task.RETURN,
         "charge": Task.CHARGE}


def place(floor: Floor004, text: str, start: bool) -> XY:
    """A slot ('s-7-45'), a station ('station-3': its exit point to start from, its entrance
    to go to) or a cell 'col,row' (a floor cell, slot or pile), as a seed cell."""
    text = text.strip()
    slot = next((s for s in floor.slots if s.name == text), None)
    if slot is not None:
        return slot.xy
    station = next((s for s in floor.stations if s.name == text), None)
    if station is not None:
        return station.exit_point if start else station.entrance
    if "," in text:
        col, row = col_row(text)
        xy = (col, floor.height - 1 - row)
        if floor.kind(xy) in (Kind.FLOOR, Kind.SLOT):
            return xy
        raise UserError(f"place {text!r}: cell ({col}, {row}) of {floor.name} is "
                        f"{floor.kind(xy).value}, not floor, a slot or a pile")
    raise UserError(f"place {text!r}: {floor.name} has no slot or station of that name (for "
                    f"example {floor.slots[0].name}, {floor.stations[0].name}), nor is it a "
                    f"cell 'col,row'")


def task_for(floor: Floor004, start: XY, goal: XY) -> Task:
    """The task a query is, when not given: to a pile charges; from a slot to a station
    delivers; to a slot from a station's exit point returns; else a fetch."""
    entrances = {s.entrance for s in floor.stations}
    exits = {s.exit_point for s in floor.stations}
    if goal in floor.piles:
        return Task.CHARGE
    if floor.kind(start) is Kind.SLOT and goal in entrances:
        return Task.DELIVER
    if start in exits and floor.kind(goal) is Kind.SLOT:
        return Task.RETURN
    return Task.FETCH


def run(args: argparse.Namespace, layout: Layout) -> int:
    floor = layout.floor
    assert floor is not None
    for flag, value in (("--reserved", args.reserved), ("--png", args.png)):
        if value is not None:
            raise UserError(f"{flag}: not for a seed-004 floor yet (its AGVs plan on the "
                            f"floor alone and meet each other while driving; docs/agv-004.md)")
    start, goal = place(floor, args.start, True), place(floor, args.goal, False)
    task = TASKS[args.task] if args.task else task_for(floor, start, goal)
    home = {Task.DELIVER: start, Task.RETURN: goal}.get(task)  # a loaded AGV's own slot
    if home is not None and floor.kind(home) is not Kind.SLOT:
        home = None
    t0 = time.perf_counter()
    if args.relaxed and task.loaded:
        raise UserError(f"--relaxed: only an empty AGV plans without the rules; "
                        f"{task.value} ({task.name.lower()}) carries a shelf")
    path = plan(floor.grid, task, start, goal, costs=Costs(turn=args.turn_cost),
                heap=not args.list_open, relaxed=args.relaxed, home=home)
    wall_ms = (time.perf_counter() - t0) * 1000
    print(f"{task.value} ({task.name.lower()}) {args.start} {floor.cell(start)} -> {args.goal} "
          f"{floor.cell(goal)} on {floor.name}, turning cost {args.turn_cost:g}"
          + (", rules lifted" if args.relaxed else ""))
    if path is None:
        print("no path under the task's rules and filters")
        return 1
    print(" ".join("{},{}".format(*floor.cell(c)) for c in path.cells))
    under = sum(floor.kind(c) is Kind.SLOT for c in path.cells[1:-1])
    print(f"{path.length} cells, {path.turns()} turns, {under} under shelves; search: "
          f"{path.expansions} expansions, {wall_ms:.1f} ms "
          f"({'list' if args.list_open else 'heap'})")
    return 0
