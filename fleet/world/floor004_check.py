"""Whether a seed-004 floor's traffic rules let the work be done (the note's B-MAP-2), as
problems naming what is cut off: empty AGVs must reach every floor cell and slot from every
other; loaded AGVs must get from every slot to every station's entrance and from every exit
point back to every slot; an AGV must reach a pile to charge from wherever it may turn to
charge (a slot, a parking place, an exit point), and leave every pile.

Reachability here is on the rule graphs alone (fleet/planning/rules004.py), with nothing
else on the floor: whatever stands in the way while driving is the tracker's to meet.
"""

from __future__ import annotations

from fleet.planning.astar004 import heading_of
from fleet.planning.rules004 import STEP, XY, Grid004, Kind, Task, allowed
from fleet.world.floor004 import Floor004

Edges = dict[XY, list[XY]]


def floor_problems(floor: Floor004) -> list[str]:
    """Every problem, one a line (empty: the floor works)."""
    grid, piles = floor.grid, set(floor.piles)
    problems: list[str] = []
    empty = {c for c, k in floor.kinds.items() if k in (Kind.FLOOR, Kind.SLOT)} - piles
    edges = _edges(grid, Task.FETCH, empty)
    start = floor.parking[0]
    problems += [f"{_name(floor, c)} is not reached by empty AGVs from the parking area"
                 for c in sorted(empty - _reached(edges, start))]
    problems += [f"{_name(floor, c)} does not lead empty AGVs back to the parking area"
                 for c in sorted(empty - _reached(_reversed(edges), start))]
    aisles = {c for c, k in floor.kinds.items() if k is Kind.FLOOR} - piles
    loaded = _edges(grid, Task.DELIVER, aisles)
    forth, back = _reached(loaded, start), _reached(_reversed(loaded), start)
    for station in floor.stations:
        for cell, what in ((station.entrance, "entrance"), (station.exit_point, "exit point")):
            if cell not in forth or cell not in back:
                problems.append(f"{station.name}: its {what} {cell} is cut off from the "
                                f"loaded AGVs' aisles")
    for slot in floor.slots:
        out = [n for n in _around(slot.xy) if n in forth and n in back]
        into = [n for n in out if heading_of(n, slot.xy) in allowed(grid, Task.RETURN, n)]
        if not out:
            problems.append(f"slot {slot.name} at {slot.xy}: a loaded AGV cannot leave it "
                            f"into the aisles")
        elif not into:
            problems.append(f"slot {slot.name} at {slot.xy}: a loaded AGV cannot enter it "
                            f"from the aisles along the rules")
    return problems + _charging_problems(floor, empty)


def _charging_problems(floor: Floor004, empty: set[XY]) -> list[str]:
    """Every slot, parking place and exit point (where an AGV may turn to charge) reaches a
    pile under the charging rules, and every pile is left onto the floor."""
    if not floor.piles:
        return ["the floor has no charging pile"]
    grid = floor.grid
    charge = _reversed(_edges(grid, Task.CHARGE, empty | set(floor.piles)))
    to_pile = _reached(charge, *floor.piles)
    places = [(f"slot {s.name} at {s.xy}", s.xy) for s in floor.slots]
    places += [(f"parking place {c}", c) for c in floor.parking]
    places += [(f"{s.name}: its exit point {s.exit_point}", s.exit_point)
               for s in floor.stations]
    problems = [f"{name}: no pile is reached from there to charge"
                for name, cell in places if cell not in to_pile]
    for pile in floor.piles:
        (leave,) = allowed(grid, Task.CHARGE, pile)
        if (pile[0] + STEP[leave][0], pile[1] + STEP[leave][1]) not in empty:
            problems.append(f"pile at {pile}: it is not left onto the floor")
    return problems


def _name(floor: Floor004, cell: XY) -> str:
    slot = next((s for s in floor.slots if s.xy == cell), None)
    return f"slot {slot.name} at {cell}" if slot is not None else f"floor cell {cell}"


def _around(cell: XY) -> list[XY]:
    return [(cell[0] + dx, cell[1] + dy) for dx, dy in STEP.values()]


def _edges(grid: Grid004, task: Task, cells: set[XY]) -> Edges:
    return {c: [n for d in allowed(grid, task, c)
                if (n := (c[0] + STEP[d][0], c[1] + STEP[d][1])) in cells] for c in cells}


def _reversed(edges: Edges) -> Edges:
    back: Edges = {c: [] for c in edges}
    for c, ns in edges.items():
        for n in ns:
            back[n].append(c)
    return back


def _reached(edges: Edges, *starts: XY) -> set[XY]:
    seen, todo = set(starts), list(starts)
    while todo:
        for n in edges.get(todo.pop(), ()):
            if n not in seen:
                seen.add(n)
                todo.append(n)
    return seen
