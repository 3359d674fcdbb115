"""`fleet plan` on a lane layout (seed 002): one AGV route, by the lanes mode or the paper's
literal dynamic map, judged by the independent lane oracle (docs/agv-002.md)."""

from __future__ import annotations

import argparse
import time

from fleet.analysis.lane_rules import lane_violations
from fleet.errors import UserError
from fleet.planning import dynamic_map
from fleet.planning.geometry import Cell
from fleet.planning.lane_route import LaneRoutes, Route
from fleet.world.lanes import lane_graph, places
from fleet.world.layout import Layout
from fleet.world.places import col_row

MAPS = ("lanes", "literal", "literal-raw")


def place_cell(layout: Layout, text: str) -> Cell:
    """A slot ('s-3-2'), packing station ('p1'), pile ('c1') or lane cell ('col,row')."""
    text = text.strip()
    named = {place.name: place.cell for _, place in places(layout)}
    if text in named:
        return named[text]
    if "," in text:
        col, row = col_row(text)
        if (col, row) in layout.lane_directions or (col, row) in named.values():
            return col, row
        raise UserError(f"place {text!r}: cell ({col}, {row}) of layout {layout.name} is no "
                        f"lane cell, slot, packing station or pile")
    examples = ", ".join(p.name for p in (*layout.packing[:1], *layout.slots[:1],
                                          *layout.piles[:1]))
    raise UserError(f"place {text!r}: layout {layout.name} has no slot, packing station or "
                    f"pile of that name (for example {examples}), nor is it a cell 'col,row'")


def plan_route(layout: Layout, start: Cell, goal: Cell, mode: str) -> Route | None:
    if mode == "lanes":
        return LaneRoutes(lane_graph(layout)).route(start, goal)
    try:
        return dynamic_map.literal_route(layout, start, goal,
                                         unpatched=mode == "literal-raw")
    except (ValueError, KeyError) as exc:
        raise UserError(f"--map {mode}: {exc}") from None


def run(args: argparse.Namespace, layout: Layout) -> int:
    for flag, value in (("--reserved", args.reserved), ("--png", args.png)):
        if value is not None:
            raise UserError(f"{flag}: not for a lane layout yet (its AGVs plan on space "
                            f"only; docs/agv-002.md)")
    start, goal = place_cell(layout, args.start), place_cell(layout, args.goal)
    t0 = time.perf_counter()
    route = plan_route(layout, start, goal, args.map)
    wall_ms = (time.perf_counter() - t0) * 1000
    print(f"route {args.start} {start} -> {args.goal} {goal} on {layout.name}, {args.map} map")
    if route is None:
        print("no route")
        return 1
    print(" ".join(f"{x},{y}" for x, y in route.cells))
    print(f"{len(route.cells) - 1} moves ({sum(d == 1.4 for d in route.distances())} diagonal), "
          f"g = {route.cost_s:.2f} s at 1 cell/s; search: {route.expansions} expansions, "
          f"{wall_ms:.1f} ms")
    violations = lane_violations(layout, route.cells)
    if not violations:
        print("lane rules: kept (fleet/analysis/lane_rules.py)")
        return 0
    print(f"lane rules: {len(violations)} broken")
    for v in violations:
        print(f"  move {v.index} {v.move[0]} -> {v.move[1]}: {v.rule}: {v.detail}")
    return 1
