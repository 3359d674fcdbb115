"""`fleet plan`: one improved hybrid A* query on a layout, printed and optionally drawn."""

from __future__ import annotations

import argparse
import math
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from fleet.commands import floor_plan, lane_plan
from fleet.errors import UserError
from fleet.planning.reservations import Interval, ReservationTable
from fleet.planning.trajectory import PlanFailure, Pose, Trajectory
from fleet.runtime.argtypes import (
    MAX_SIM_SECONDS,
    layout_arg,
    non_negative_float,
    png_file,
    positive_int,
    sim_seconds,
    text_file,
)
from fleet.vehicles.kind import Planners
from fleet.world.layout import Layout
from fleet.world.layout_file import load_layout
from fleet.world.places import filled_counts, resolve
from fleet.world.site import planners_for


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plan", help="plan one trajectory with the improved hybrid A*",
                       description="Plan one query. Places: a pose 'col,row,H' (H in E N W S),"
                       " a station name (its docking pose) or a stack 's1#5' (forks at it).")
    p.add_argument("--layout", default="paper", type=layout_arg,
                   help="layout name or TOML file (default paper)")
    p.add_argument("--from", dest="start", required=True, help="start place")
    p.add_argument("--to", dest="goal", required=True, help="goal place")
    p.add_argument("--at", type=sim_seconds, default=0.0,
                   help="start time in seconds (default 0)")
    p.add_argument("--vehicle", type=positive_int, default=1,
                   help="the planning forklift's id, one of the layout's (default 1)")
    p.add_argument("--reserved", type=text_file, metavar="FILE",
                   help="TOML file of other vehicles' plans and reservations "
                   "(docs/planning.md; default: none, only the planning vehicle is there)")
    p.add_argument("--png", type=png_file, metavar="FILE",
                   help="draw the plan into this PNG file (default: no drawing)")
    p.add_argument("--map", choices=lane_plan.MAPS, default="lanes",
                   help="on a lane layout (seed 002; places are slots 's-3-2', packing "
                   "stations, piles or cells 'col,row'): the lanes mode, the paper's literal "
                   "dynamic map with errata E1-E7, or with its raw indices (default lanes)")
    p.add_argument("--task", choices=list(floor_plan.TASKS),
                   help="on a seed-004 floor (places are slots 's-7-45', stations "
                   "'station-3' or cells 'col,row'): the AGV's task, whose traffic rules it "
                   "keeps (default: from the places: to a pile charge, slot to station "
                   "deliver, station to slot return, else fetch)")
    p.add_argument("--turn-cost", type=non_negative_float, default=1.0,
                   help="on a seed-004 floor: the turning cost, cells a quarter turn "
                   "(default 1; 0 switches it off)")
    p.add_argument("--relaxed", action="store_true",
                   help="on a seed-004 floor: an empty AGV plans without the traffic rules, "
                   "as after repeated failures (default: with them)")
    p.add_argument("--list-open", action="store_true",
                   help="on a seed-004 floor: search with the plain list, not the binary heap "
                   "(the same path, slower)")
    p.set_defaults(handler=run)


@dataclass
class Scene:
    """Everything in the table before the query: fill state and other vehicles."""

    filled: set = field(default_factory=set)
    start: Pose | None = None  # the planning vehicle's start
    others: list[Trajectory] = field(default_factory=list)


def load_scene(path: Path | None, layout: Layout, planners: Planners,
               table: ReservationTable, me: int, my_start: str) -> Scene:
    """Fill state and the other vehicles' plans; the planning vehicle is parked at its start
    first, so the others plan around it as they would in a fleet."""
    data = _scene_file(path, layout) if path is not None else {}
    scene = Scene()
    scene.filled = filled_counts(layout, data.get("filled", {}))
    scene.start = resolve(layout, my_start, scene.filled)[0]
    kind = layout.vehicle_kind
    table.park(me, kind.body_cells_at_rest(scene.start), 0.0)
    planner = planners.get(frozenset(scene.filled))
    vehicles = data.get("vehicle", [])
    starts = {}
    for i, entry in enumerate(vehicles):
        where = f"{path}: vehicle[{i}]"
        vid = entry["id"]
        if vid == me:
            raise UserError(f"{where}: id {vid} is the planning vehicle itself")
        starts[vid] = resolve(layout, entry["from"], scene.filled)[0]
        parked = table.park(vid, kind.body_cells_at_rest(starts[vid]), 0.0)
        if not parked.ok:
            other = parked.conflict_vehicle
            who = "the planning vehicle" if other == me else f"vehicle {other}"
            raise UserError(f"{where}: start {starts[vid]} overlaps {who}")
    for i, entry in enumerate(vehicles):
        if "to" not in entry:
            continue
        vid = entry["id"]
        goals = resolve(layout, entry["to"], scene.filled)
        result = planner.plan(vid, starts[vid], entry.get("at", 0.0), goals, table)
        if isinstance(result, PlanFailure):
            raise UserError(f"{path}: vehicle[{i}] (id {vid}) could not be planned: "
                            f"{result.reason.value}: {result.detail}")
        leg = planners.policy.commitment(result, table)
        if isinstance(leg, PlanFailure):
            raise UserError(f"{path}: vehicle[{i}] (id {vid}) could not be committed: "
                            f"{leg.detail}")
        leg.write(table)
        scene.others.append(leg.trajectory)
    for i, entry in enumerate(data.get("reservation", [])):
        iv = Interval(entry["cell"], entry["t0"], entry.get("t1", math.inf))
        written = table.commit(entry["vehicle"], [iv])
        if not written.ok:
            raise UserError(f"{path}: reservation[{i}] overlaps vehicle "
                            f"{written.conflict_vehicle}")
    return scene


def _scene_file(path: Path, layout: Layout) -> dict:
    """The --reserved file, every value checked (docs/planning.md): a refusal names the
    entry and what it should be."""
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{path}: not valid TOML: {exc}") from None
    _known(data, {"filled", "vehicle", "reservation"}, f"{path}")
    filled = data.get("filled", {})
    if not isinstance(filled, dict):
        raise UserError(f"{path}: filled must be a table of cluster = stacks filled")
    for name, count in filled.items():
        _whole(count, f"{path}: filled.{name}")
    forklifts = len(layout.vehicle_starts)

    def forklift(value, where: str) -> int:
        vid = _whole(value, where)
        if not 1 <= vid <= forklifts:
            raise UserError(f"{where}: layout {layout.name} has forklifts 1 to {forklifts}, "
                            f"not {vid}")
        return vid

    for i, entry in enumerate(_tables(data, "vehicle", path)):
        where = f"{path}: vehicle[{i}]"
        _known(entry, {"id", "from", "to", "at"}, where)
        if "id" not in entry or "from" not in entry:
            raise UserError(f"{where}: needs an integer 'id' and a 'from' place")
        forklift(entry["id"], f"{where}.id")
        for key in ("from", "to"):
            if key in entry and not isinstance(entry[key], str):
                raise UserError(f"{where}.{key}: a place is a string, not {entry[key]!r}")
        if "at" in entry:
            entry["at"] = _seconds(entry["at"], f"{where}.at")
    for i, entry in enumerate(_tables(data, "reservation", path)):
        where = f"{path}: reservation[{i}]"
        _known(entry, {"vehicle", "cell", "t0", "t1"}, where)
        missing = [k for k in ("vehicle", "cell", "t0") if k not in entry]
        if missing:
            raise UserError(f"{where}: needs {missing[0]!r} (and vehicle, cell = [c, r], t0)")
        forklift(entry["vehicle"], f"{where}.vehicle")
        cell = entry["cell"]
        if not (isinstance(cell, list) and len(cell) == 2 and
                all(isinstance(c, int) and not isinstance(c, bool) for c in cell)):
            raise UserError(f"{where}.cell: a cell is [column, row], not {cell!r}")
        if not (0 <= cell[0] < layout.cols and 0 <= cell[1] < layout.rows):
            raise UserError(f"{where}.cell: {cell} is off the {layout.cols} x {layout.rows} "
                            f"map")
        entry["cell"] = tuple(cell)
        entry["t0"] = _seconds(entry["t0"], f"{where}.t0")
        if "t1" in entry:
            entry["t1"] = _seconds(entry["t1"], f"{where}.t1", infinite=True)
            if entry["t1"] <= entry["t0"]:
                raise UserError(f"{where}: t1 {entry['t1']:g} must be after t0 "
                                f"{entry['t0']:g}")
    return data


def _known(table: dict, keys: set[str], where: str) -> None:
    unknown = sorted(set(table) - keys)
    if unknown:
        raise UserError(f"{where}: unknown key {unknown[0]!r} (it takes "
                        f"{', '.join(sorted(keys))})")


def _tables(data: dict, key: str, path: Path) -> list[dict]:
    entries = data.get(key, [])
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise UserError(f"{path}: {key} entries must be [[{key}]] tables")
    return entries


def _whole(value, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise UserError(f"{where}: must be a whole number, not {value!r}")
    return value


def _seconds(value, where: str, infinite: bool = False) -> float:
    """A time in seconds: a number from 0, finite (or +inf where `infinite`)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise UserError(f"{where}: must be a time in seconds, not {value!r}")
    if not (0 <= value <= MAX_SIM_SECONDS or (infinite and value == math.inf)):  # NaN too
        raise UserError(f"{where}: must be a time from 0 to {MAX_SIM_SECONDS:.0f} seconds"
                        + (" (or inf)" if infinite else "") + f", not {value!r}")
    return float(value)


def format_trajectory(traj: Trajectory) -> str:
    lines = [f"{'t0':>8} {'t1':>8}  {'maneuver':<20} {'from':<10} {'to':<10} speed"]
    for s in traj.steps:
        lines.append(f"{s.t0:8.2f} {s.t1:8.2f}  {s.manner.label:<20} {s.start!s:<10} "
                     f"{s.end!s:<10} {s.v0.name.lower()}->{s.v1.name.lower()}")
    counts = traj.counts()
    lines.append(f"arrives at {traj.goal} at t={traj.t_end:.2f} s ({traj.t_end - traj.t_start:.2f}"
                 f" s, {len(traj.steps)} maneuvers, {counts['turns']} turns, "
                 f"{counts['lane_changes']} lane changes, {counts['reversals']} reversals); "
                 f"parked there to infinity")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    layout = load_layout(args.layout)
    if layout.floor is not None:
        return floor_plan.run(args, layout)
    if layout.has_lanes:
        return lane_plan.run(args, layout)
    forklifts = len(layout.vehicle_starts)
    if args.vehicle > forklifts:
        raise UserError(f"--vehicle {args.vehicle}: layout {layout.name} has forklifts 1 to "
                        f"{forklifts}" if forklifts else
                        f"--vehicle {args.vehicle}: layout {layout.name} has no forklifts "
                        f"(no start poses)")
    planners = planners_for(layout)
    table = ReservationTable()
    scene = load_scene(args.reserved, layout, planners, table, args.vehicle, args.start)
    goals = resolve(layout, args.goal, scene.filled)
    start = scene.start
    planner = planners.get(frozenset(scene.filled))
    t0 = time.perf_counter()
    result = planner.plan(args.vehicle, start, args.at, goals, table)
    wall_ms = (time.perf_counter() - t0) * 1000
    goal_text = ", ".join(str(g) for g in goals)
    print(f"vehicle {args.vehicle}: {start} -> {goal_text} on {layout.name}, t={args.at:g} s, "
          f"{len(scene.others)} other vehicles planned")
    if isinstance(result, Trajectory):
        print(format_trajectory(result))
    else:
        print(f"no trajectory: {result.reason.value}: {result.detail}")
    print(f"search: {result.expansions} expansions, {wall_ms:.1f} ms")
    if args.png:
        from fleet.views.drawing import plan_figure, save_figure

        traj = result if isinstance(result, Trajectory) else None
        outcome = (f"arrives at t = {traj.t_end:.2f} s" if traj
                   else f"no trajectory: {result.reason.value}")
        title = (f"Plan of vehicle {args.vehicle} from {args.start} to {args.goal} on "
                 f"{layout.name}, starting at t = {args.at:g} s: {outcome}\n"
                 f"among {len(scene.others)} other vehicles' plans and reservations")
        save_figure(plan_figure(layout, traj, scene.others, table.reservations(),
                                scene.filled, title), str(args.png))
        print(f"wrote {args.png}")
    return 0 if isinstance(result, Trajectory) else 1

