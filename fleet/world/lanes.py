"""Moves on a lane layout (seed 002): which way a vehicle may drive from each cell, and where
a route into or out of a slot, packing station or pile begins and ends.

A lane cell allows its lane's direction; a junction cell, where a horizontal and a vertical
lane cross, allows both, so vehicles turn only at junctions. A move must land on a lane
cell that runs the move's way. A slot, station or pile is entered from an access cell
beside it and left back to it (docs/layouts.md states the rule). These are pure functions
of the layout, for the checks here and for the planner.
"""

from __future__ import annotations

from fleet.planning.geometry import Cell
from fleet.planning.lane_conflicts import Area
from fleet.planning.lane_route import DIAGONAL, STRAIGHT, LaneGraph, Move
from fleet.world.layout import DIRECTIONS, Layout, PackingStation, Pile, Slot

Place = Slot | PackingStation | Pile


def step(cell: Cell, direction: str) -> Cell:
    dx, dy = DIRECTIONS[direction]
    return (cell[0] + dx, cell[1] + dy)


def direction_between(a: Cell, b: Cell) -> str:
    """The direction of the orthogonal step from a to b."""
    delta = (b[0] - a[0], b[1] - a[1])
    for name, d in DIRECTIONS.items():
        if d == delta:
            return name
    raise ValueError(f"{a} -> {b} is not one orthogonal step")


def allowed_moves(layout: Layout, cell: Cell) -> frozenset[str]:
    """The directions a vehicle on `cell` may drive one cell in: its lanes' directions, onto
    a lane cell that runs the same way (empty off the lanes). So a vehicle turns only on a
    junction cell, never onto the side of a lane that merely ends beside another."""
    lanes = layout.lane_directions
    return frozenset(d for d in lanes.get(cell, ()) if d in lanes.get(step(cell, d), ()))


def diagonal_moves(layout: Layout, cell: Cell) -> frozenset[str]:
    """The diagonal moves ("NE", "SW", ...) a vehicle on `cell` may make: both orthogonal
    neighbours are lane cells (no corner cutting) and one of the two ways round the corner
    is allowed step by step, so a diagonal only cuts a turn the lanes allow (seed pack note
    A.4.2, the lane mode)."""
    lanes = layout.lane_directions
    found = set()
    for v in ("N", "S"):
        for h in ("E", "W"):
            across, up = step(cell, h), step(cell, v)
            if across not in lanes or up not in lanes or step(across, v) not in lanes:
                continue
            if ((h in allowed_moves(layout, cell) and v in allowed_moves(layout, across))
                    or (v in allowed_moves(layout, cell) and h in allowed_moves(layout, up))):
                found.add(v + h)
    return frozenset(found)


def places(layout: Layout) -> list[tuple[str, Place]]:
    """Every slot, packing station and pile, each with how errors name it: stations first
    (where orders go), then slots, then piles."""
    return ([(f"station {p.name}", p) for p in layout.packing]
            + [(f"slot {s.name}", s) for s in layout.slots]
            + [(f"pile {p.name}", p) for p in layout.piles])


def doors(layout: Layout, place: Place) -> frozenset[Cell]:
    """The lane cells a route leaving `place` may begin on, which are also those a route to
    it may end on. The vehicle steps out onto its access cell, and may go on straight across
    one cell more (across the channel, onto its far lane): that is where the lane mode of
    seed 002 lets it cross the opposite lane, in the start's and end's own column. An access
    cell that is no lane cell is only crossed, so only the cell beyond it is a door."""
    lanes = layout.lane_directions
    found: set[Cell] = set()
    for near in place.access:
        beyond = step(near, direction_between(place.cell, near))
        if near in lanes:
            found.add(near)
        if beyond in lanes:
            found.add(beyond)
    return frozenset(found)


def lane_graph(layout: Layout) -> LaneGraph:
    """The moves of seed 002's lane mode (A.4.2) for the route search: along the lanes
    (`allowed_moves`, `diagonal_moves`); out of each place onto its access cell and straight
    on across one cell more; into each place the same ways back (`doors`)."""
    if not layout.has_lanes:
        raise ValueError(f"layout {layout.name} has no lanes: routes on lanes need a lane "
                         f"layout")
    moves = {}
    for cell in sorted(layout.lane_directions):
        straight = [Move(step(cell, d), STRAIGHT) for d in sorted(allowed_moves(layout, cell))]
        diagonal = [Move(step(step(cell, d[0]), d[1]), DIAGONAL)
                    for d in sorted(diagonal_moves(layout, cell))]
        moves[cell] = (*straight, *diagonal)
    lanes = layout.lane_directions
    ways_out: dict[Cell, tuple[Move, ...]] = {}
    ways_in: dict[Cell, dict[Cell, Move]] = {}
    for _, place in places(layout):
        out: list[Move] = []
        into: dict[Cell, Move] = {}
        for near in place.access:
            beyond = step(near, direction_between(place.cell, near))
            if near in lanes:
                out.append(Move(near, STRAIGHT))
                into[near] = Move(place.cell, STRAIGHT)
            if beyond in lanes:
                out.append(Move(beyond, 2 * STRAIGHT, (near,)))
                into.setdefault(beyond, Move(place.cell, 2 * STRAIGHT, (near,)))
        ways_out[place.cell] = tuple(out)
        ways_in[place.cell] = into
    return LaneGraph(layout.name, layout.cell_size, moves, ways_out, ways_in)


def floor_cells(layout: Layout) -> frozenset[Cell]:
    """The cells a lane layout's vehicles can be on: lanes, access cells and places."""
    return frozenset({*layout.lane_directions, *layout.access_cells,
                      *(place.cell for _, place in places(layout))})


def collision_areas(layout: Layout) -> dict[Cell, Area]:
    """Each cell's set in seed 002's Section 5.3 (cells off every set are not driven)."""
    found: dict[Cell, Area] = {}
    for lane in layout.lanes:
        area = Area.HORIZONTAL if lane.direction in "EW" else Area.LONGITUDINAL
        for cell in lane.cells:
            found[cell] = area
    for junction in layout.junctions:
        area = Area.CROSSROAD if junction.kind == "crossroad" else Area.T_CROSSROAD
        for cell in junction.cells:
            found[cell] = area
    for _, place in places(layout):
        found[place.cell] = Area.OFF_CHANNEL
    for cell in layout.access_cells:
        found[cell] = Area.OFF_CHANNEL
    return found
