"""`fleet layout list|show|check|generate`: look at, validate and make warehouse layouts."""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from collections.abc import Sequence

from fleet.commands.output import write_or_print
from fleet.commands.progress import ProgressBar
from fleet.errors import UserError
from fleet.runtime.argtypes import layout_arg, positive_int, writable_file
from fleet.world.floor004 import CLASSES
from fleet.world.floor004_check import floor_problems
from fleet.world.generator import MIN_DEPTH, Shape, generate_toml
from fleet.world.lane_reachability import lane_problems
from fleet.world.layout import LANE_SYMBOLS, Layout
from fleet.world.layout_file import MAX_MAP_CELLS, builtin_names, load_layout
from fleet.world.reachability import reachability_problems


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("layout", help="list, show, check or generate warehouse layouts",
                       description="Warehouse layouts are data: TOML files with the map's "
                       "bounds, clusters of stacks and their fill order, stations, obstacles, "
                       "passages and the forklifts' start poses, and a drawing the loader "
                       "checks against them; or, for a lane layout (seed 002), directed lanes, "
                       "shelf areas, packing stations and charging piles (docs/layouts.md). "
                       "Built-in layouts go by name.")
    which = p.add_subparsers(dest="layout_command", required=True, metavar="ACTION")
    which.add_parser("list", help="the built-in layouts",
                     description="List the built-in layouts: stacks, forklifts and what "
                     "each is.").set_defaults(handler=run_list)
    show = which.add_parser("show", help="print a layout's drawing and summary",
                            description="Print a layout's drawing (its legend is in "
                            "docs/layouts.md) and a summary of its clusters, stations and "
                            "start poses, or of its lanes, junctions, shelves, packing "
                            "stations and piles.")
    show.add_argument("name", type=layout_arg, help="built-in layout name or TOML file")
    show.set_defaults(handler=run_show)
    check = which.add_parser("check", help="validate a layout file: structure, drawing, and "
                             "that every stack can be served in fill order",
                             description="Validate a layout as fleet run would load it: its "
                             "structure and drawing (the first error, naming the element), "
                             "that it has start poses, and that every stack can be served "
                             "from every station in fill order and every start reaches a "
                             "dock; for a lane layout, that every slot, packing station and "
                             "pile can be reached from every other along the lanes "
                             "(every problem, one a line). Exit 1 on problems, 2 on a "
                             "structural error.")
    check.add_argument("file", type=layout_arg, help="TOML file (or built-in layout name)")
    check.set_defaults(handler=run_check)
    gen = which.add_parser("generate", help="write a large parametric warehouse layout",
                           description="Write a parametric warehouse: AISLES horizontal "
                           "aisles off a vertical main passage, DEPTH lanes of LANE_DEPTH "
                           "stacks on each side, stations at both ends of the main passage "
                           "and parking starts for the forklifts.")
    defaults = Shape()
    gen.add_argument("--aisles", type=positive_int, default=defaults.aisles,
                     help=f"horizontal aisles (default {defaults.aisles})")
    gen.add_argument("--depth", type=positive_int, default=defaults.depth,
                     help=f"lanes per side of the main passage, at least {MIN_DEPTH}: the "
                     f"forklifts park beside them (default {defaults.depth})")
    gen.add_argument("--lane-depth", type=positive_int, default=defaults.lane_depth,
                     help=f"stacks per lane (default {defaults.lane_depth})")
    gen.add_argument("--vehicles", type=positive_int, default=defaults.vehicles,
                     help=f"forklifts and their parking starts (default {defaults.vehicles})")
    gen.add_argument("--name", help="layout name (default generated-AxD)")
    gen.add_argument("--out", type=writable_file, metavar="FILE",
                     help="write here (default: print to stdout)")
    gen.set_defaults(handler=run_generate)


def run_list(args: argparse.Namespace) -> int:
    names = builtin_names()
    width = max(map(len, names))
    for name in names:
        layout = load_layout(name)
        if layout.has_lanes or layout.floor is not None:
            slots, piles = ((len(layout.slots), len(layout.piles)) if layout.floor is None
                            else (len(layout.floor.slots), len(layout.floor.piles)))
            print(f"{name:{width}} {slots:5} slots   {piles:3} piles     {layout.description}")
            continue
        print(f"{name:{width}} {len(layout.stacks):5} stacks  {len(layout.vehicle_starts):3} "
              f"vehicles  {layout.description}")
    return 0


def run_show(args: argparse.Namespace) -> int:
    layout = load_layout(args.name)
    print(layout.render_drawing())
    print()
    print(summary(layout))
    return 0


def _map_lines(layout: Layout) -> list[str]:
    x0 = layout.origin[0] - layout.cell_size / 2
    y0 = layout.origin[1] - layout.cell_size / 2
    return [
        f"layout {layout.name}: {layout.description}".rstrip(": "),
        f"  map      {layout.cols} x {layout.rows} cells of {layout.cell_size:g} m, "
        f"x [{x0:g}, {x0 + layout.cols * layout.cell_size:g}] m, "
        f"y [{y0:g}, {y0 + layout.rows * layout.cell_size:g}] m",
    ]


def _wrapped(head: str, items: list[str]) -> list[str]:
    """The items after the head, as many a line as fit 92 columns, none broken."""
    lines = [f"  {head:8} "]
    for i, item in enumerate(items):
        text = item + ("," if i < len(items) - 1 else "")
        if len(lines[-1]) + len(text) > 92 and lines[-1].strip():
            lines.append(" " * 11)
        lines[-1] += text + " "
    return [line.rstrip() for line in lines]


def lane_summary(layout: Layout) -> str:
    """What `fleet layout show` prints under a lane layout's drawing: the lanes with their
    direction arrows, the junctions, shelves, packing stations, piles and the vehicle kind."""
    kinds = Counter(j.kind for j in layout.junctions)
    dwells = sorted({p.dwell for p in layout.packing})
    lines = _map_lines(layout) + _wrapped(f"lanes {len(layout.lanes)}", [
        f"{lane.name} {LANE_SYMBOLS[lane.direction]} {lane.cells[0]}..{lane.cells[-1]}"
        for lane in layout.lanes])
    lines.append(f"  junctions {len(layout.junctions)}: {kinds['crossroad']} crossroads (X), "
                 f"{kinds['t']} T-crossroads (T), {kinds['corner']} corners (L); vehicles "
                 f"turn only there")
    lines.append(f"  shelves  {len(layout.slots)} in {len(layout.shelf_areas)} shelf areas, "
                 f"one a slot at start, each named after its home slot (s-COL-ROW)")
    if layout.access_cells:
        lines.append(f"  access   {len(layout.access_cells)} cells, crossed straight between "
                     f"a slot and its lane")
    if layout.packing:
        lines += _wrapped(f"packing {len(layout.packing)}", [
            f"{p.name} {p.cell}" for p in layout.packing])
        lines.append(f"           dwell {' / '.join(f'{d:g}' for d in dwells)} s")
    if layout.piles:
        lines += _wrapped(f"piles {len(layout.piles)}", [
            f"{p.name} {p.cell}" for p in layout.piles])
    lines.append(f"  vehicles {layout.vehicle.kind}s (no start poses: where they start is "
                 f"the mission's)")
    if layout.obstacles:
        lines.append("  obstacles " + ", ".join(
            f"{o.name} ({o.kind}, {len(o.cells)} cells)" for o in layout.obstacles))
    return "\n".join(lines)


def floor_summary(layout: Layout) -> str:
    """What `fleet layout show` prints under a seed-004 floor's drawing: its slots and goods
    by popularity class, stations, piles and parking places."""
    floor = layout.floor
    assert floor is not None
    by_class = Counter(s.goods.rsplit("-", 1)[0] for s in floor.slots)
    lines = _map_lines(layout)
    lines.append(f"  slots    {len(floor.slots)} in {len({s.block for s in floor.slots})} "
                 f"blocks of {floor.shape.block_width} x 2, one shelf each (named after its "
                 f"home slot, s-COL-ROW); empty AGVs drive under them")
    lines += _wrapped(f"goods {len(floor.goods)}", [
        f"{c} {by_class[c]} slots" for c in CLASSES])
    lines += _wrapped(f"stations {len(floor.stations)}", [
        f"{s.name} entrance {floor.cell(s.entrance)} work {floor.cell(s.work)}"
        for s in floor.stations])
    lines.append(f"           each a fixed route: entrance, {len(floor.stations[0].waiting)} "
                 f"waiting cells, the work cell, {len(floor.stations[0].exits)} exit cells, "
                 f"the exit point" if floor.stations else "")
    lines.append(f"  piles    {len(floor.piles)} in the side walls, left only outward")
    lines.append(f"  parking  {len(floor.parking)} places on the top rows; vehicles "
                 f"{layout.vehicle.kind}s")
    return "\n".join(line for line in lines if line)


def summary(layout: Layout) -> str:
    """What `fleet layout show` prints under the drawing: the map's size and extent, the
    clusters, stations, vehicles, obstacles and passages."""
    if layout.floor is not None:
        return floor_summary(layout)
    if layout.has_lanes:
        return lane_summary(layout)
    lines = [
        *_map_lines(layout),
        f"  stacks   {len(layout.stacks)} in {len(layout.clusters)} clusters: "
        + ", ".join(f"{c.name} {len(layout.cluster_stacks(c.name))}" for c in layout.clusters),
        f"  stations {len(layout.stations)}: "
        + ", ".join(f"{s.name} dock {s.dock}" for s in layout.stations),
        f"  vehicles {len(layout.vehicle_starts)} {layout.vehicle.kind}s starting at "
        + ", ".join(str(p) for p in layout.vehicle_starts),
    ]
    if layout.obstacles:
        lines.append("  obstacles " + ", ".join(
            f"{o.name} ({o.kind}, {len(o.cells)} cells)" for o in layout.obstacles))
    if layout.passages:
        lines.append("  passages " + ", ".join(
            f"{p.name} ({p.kind}, {len(p.cells)} cells)" for p in layout.passages))
    return "\n".join(lines)


def run_check(args: argparse.Namespace) -> int:
    layout = load_layout(args.file)  # structural errors raise LayoutError naming the element
    if layout.floor is not None:
        return _check_floor(args.file, layout)
    if layout.has_lanes:
        return _check_lanes(args.file, layout)
    bar = ProgressBar(len(layout.stacks), "reachability", unit="stacks")
    problems = reachability_problems(layout, lambda done, total: bar.update(done))
    bar.close()
    if problems:
        return _reported(args.file, problems)
    print(f"{args.file}: ok: {len(layout.stacks)} stacks in {len(layout.clusters)} clusters, "
          f"{len(layout.stations)} stations, {len(layout.vehicle_starts)} vehicles; every "
          f"stack can be served from every station in fill order")
    return 0


def _reported(name: str, problems: Sequence[object]) -> int:
    """Each problem on its own line, then how many: the check failed (1)."""
    for problem in problems:
        print(f"{name}: {problem}", file=sys.stderr)
    print(f"{name}: {len(problems)} problem(s)", file=sys.stderr)
    return 1


def _checked(name: str, problems: Sequence[object], ok: str) -> int:
    """The problems (1), or that the layout is ok and what it holds (0)."""
    if problems:
        return _reported(name, problems)
    print(f"{name}: ok: {ok}")
    return 0


def _check_lanes(name: str, layout: Layout) -> int:
    return _checked(name, lane_problems(layout),
                    f"{len(layout.slots)} slots, {len(layout.packing)} packing stations, "
                    f"{len(layout.piles)} piles, {len(layout.lanes)} lanes, "
                    f"{len(layout.junctions)} junctions; every slot, station and pile can be "
                    f"reached from every other along the lanes")


def _check_floor(name: str, layout: Layout) -> int:
    floor = layout.floor
    assert floor is not None
    return _checked(name, floor_problems(floor),
                    f"{len(floor.slots)} slots, {len(floor.goods)} goods, "
                    f"{len(floor.stations)} stations, {len(floor.piles)} piles; under the "
                    f"traffic rules empty AGVs reach every cell and slot, loaded AGVs every "
                    f"station from every slot and back, and every pile is reached and left")


def run_generate(args: argparse.Namespace) -> int:
    shape = Shape(aisles=args.aisles, depth=args.depth, lane_depth=args.lane_depth,
                  vehicles=args.vehicles)
    if shape.cols * shape.rows > MAX_MAP_CELLS:
        raise UserError(f"--aisles {args.aisles} --depth {args.depth} --lane-depth "
                        f"{args.lane_depth}: a map of {shape.cols} x {shape.rows} cells is "
                        f"more than a layout may have ({MAX_MAP_CELLS} cells)")
    if not write_or_print(generate_toml(shape, args.name), args.out):
        return 0
    print(f"wrote {args.out}: {shape.cols} x {shape.rows} cells, "
          f"{4 * shape.aisles * shape.depth * shape.lane_depth} stacks, "
          f"{shape.vehicles} vehicles; check it with: fleet layout check {args.out}")
    return 0
