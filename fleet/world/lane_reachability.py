"""Reachability on a lane layout: can every slot, packing station and pile be reached from
every other along the lanes?

A graph search on cells: from each lane cell to the next along its allowed moves
(`fleet.world.lanes`). A route starts on one of its place's doors and ends on one of its
target's, passing through no other slot, station or pile (the vehicle enters those only at a
route's two ends). The lane graph is cut into strongly connected components once; then each
pair of places is one look-up, so the 441 places of paper002 check at once.
"""

from __future__ import annotations

from fleet.planning.geometry import Cell
from fleet.world.lanes import allowed_moves, doors, places, step
from fleet.world.layout import Layout
from fleet.world.reachability import Problem


def components(layout: Layout) -> dict[Cell, int]:
    """Each lane cell's strongly connected component (Tarjan's, iterative), numbered so a
    component reaches only components of lower numbers."""
    succ = {c: [step(c, d) for d in sorted(allowed_moves(layout, c))]
            for c in sorted(layout.lane_directions)}
    index: dict[Cell, int] = {}
    low: dict[Cell, int] = {}
    on_stack: set[Cell] = set()
    stack: list[Cell] = []
    comp: dict[Cell, int] = {}
    count = 0
    for root in succ:
        if root in index:
            continue
        work = [(root, 0)]
        while work:
            cell, i = work.pop()
            if i == 0:
                index[cell] = low[cell] = len(index)
                stack.append(cell)
                on_stack.add(cell)
            if i < len(succ[cell]):
                work.append((cell, i + 1))
                nxt = succ[cell][i]
                if nxt not in index:
                    work.append((nxt, 0))
                elif nxt in on_stack:
                    low[cell] = min(low[cell], index[nxt])
                continue
            if low[cell] == index[cell]:
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    comp[member] = count
                    if member == cell:
                        break
                count += 1
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[cell])
    return comp


def _reach(layout: Layout, comp: dict[Cell, int]) -> list[int]:
    """For each component, the bit set of the components it reaches (itself included)."""
    count = len(set(comp.values()))
    edges: list[set[int]] = [set() for _ in range(count)]
    for cell, number in comp.items():
        for d in allowed_moves(layout, cell):
            edges[number].add(comp[step(cell, d)])
    reach = [0] * count
    for number in range(count):  # Tarjan numbers sinks first: successors are done already
        bits = 1 << number
        for other in edges[number]:
            if other != number:
                bits |= reach[other]
        reach[number] = bits
    return reach


def lane_problems(layout: Layout) -> list[Problem]:
    """Every slot, packing station and pile that some other cannot reach, or that cannot
    reach some other, with the first such partner (empty list: all good)."""
    comp = components(layout)
    reach = _reach(layout, comp)
    named = places(layout)
    door_sets = [frozenset(comp[c] for c in doors(layout, place)) for _, place in named]
    out_bits = [0] * len(named)
    for i, numbers in enumerate(door_sets):
        for number in numbers:
            out_bits[i] |= reach[number]

    def reaches(i: int, j: int) -> bool:
        return any(out_bits[i] >> number & 1 for number in door_sets[j])

    problems = []
    for j, (name, _) in enumerate(named):
        source = next((i for i in range(len(named)) if i != j and not reaches(i, j)), None)
        if source is not None:
            problems.append(Problem(name, f"cannot be reached from {named[source][0]} along "
                                    f"the lanes"))
            continue
        target = next((k for k in range(len(named)) if k != j and not reaches(j, k)), None)
        if target is not None:
            problems.append(Problem(name, f"cannot reach {named[target][0]} along the lanes"))
    return problems
