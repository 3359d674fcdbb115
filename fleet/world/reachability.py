"""Reachability of a layout: can every stack be served in its fill order?

A stack is served from one of its unload poses (forks pointing at it) and the forklift must
get there from a station dock and back. Blocking more cells never creates a path, so each
stack is checked in the hardest state it can meet: the stacks before it in its cluster filled,
every other cluster full, and the stack itself filled (the forklift must get out again).
Emptying meets the same states in reverse, so one check covers both missions. Start poses
must reach a dock on the empty floor (a fill mission starts there).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from fleet.world.layout import Layout, LayoutError


@dataclass(frozen=True)
class Problem:
    element: str
    reason: str

    def __str__(self) -> str:
        return f"{self.element}: {self.reason}"


NO_STARTS = Problem("starts", "the layout has no start poses, so no forklift can run on it "
                    "(give one 'col,row,H' per forklift)")


def fleet_size(layout: Layout, vehicles: int | None) -> int:
    """The fleet of a run on `layout`: `vehicles`, or one forklift per start pose; refused,
    naming the limit, when the layout has no start for it."""
    starts = len(layout.vehicle_starts)
    if starts == 0:
        raise LayoutError(f"layout {layout.name}: {NO_STARTS}")
    if vehicles is None:
        return starts
    if not 1 <= vehicles <= starts:
        raise LayoutError(f"--vehicles {vehicles}: layout {layout.name} has start poses for "
                          f"1 to {starts} forklifts")
    return vehicles


def reachability_problems(layout: Layout,
                          progress: Callable[[int, int], None] | None = None) -> list[Problem]:
    """Every stack, dock and start that cannot be served, with why (empty list: all good);
    a layout without start poses is a problem too (no run could use it)."""
    problems: list[Problem] = [] if layout.vehicle_starts else [NO_STARTS]
    kind = layout.vehicle_kind
    empty = kind.planner(layout.grid_map())
    docks = {s.name: empty.component(s.dock) for s in layout.stations}
    for i, start in enumerate(layout.vehicle_starts, start=1):
        if empty.component(start) not in docks.values():
            problems.append(Problem(f"start {i} ({start})", "cannot reach any station dock"))
    all_cells = {s.cell for s in layout.stacks}
    total, done = len(layout.stacks), 0
    for cluster in layout.clusters:
        stacks = layout.cluster_stacks(cluster.name)
        filled = all_cells - {s.cell for s in stacks}
        for stack in stacks:
            element = f"cluster {cluster.name} stack {stack.index} at {stack.cell}"
            poses = layout.unload_poses(stack.cell, filled)
            if not poses:
                problems.append(Problem(element, "no free pose can point its forks at it "
                                        "once the stacks before it are filled"))
            else:
                # Connected with the stack already filled: the forklift must also get out.
                planner = kind.planner(layout.grid_map(filled | {stack.cell}))
                reached = {planner.component(p) for p in poses}
                cut_off = [name for name, station in zip(
                    docks, layout.stations, strict=True)
                    if planner.component(station.dock) not in reached]
                if len(cut_off) == len(layout.stations):
                    problems.append(Problem(element, "no unload pose connects to a station "
                                            "dock (there and back, with the stack filled) "
                                            "once the stacks before it are filled"))
                elif cut_off:
                    problems.append(Problem(element, "unreachable from the dock of "
                                            + ", ".join(cut_off)))
            filled.add(stack.cell)
            done += 1
            if progress:
                progress(done, total)
    return problems


def check_layout(layout: Layout, progress: Callable[[int, int], None] | None = None) -> None:
    """Raise LayoutError naming the first element that cannot be served."""
    problems = reachability_problems(layout, progress)
    if problems:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        raise LayoutError(f"layout {layout.name}: {problems[0]}{more}")
