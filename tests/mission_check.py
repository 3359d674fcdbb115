"""Checks of a whole mission record for tests, apart from the engine and the planner: every
trajectory covers its own swept cells (brute_force), no two vehicles ever hold one cell at once,
every stack is done exactly once, and every forklift ends parked."""

from __future__ import annotations

from collections import Counter, defaultdict

from brute_force import check_trajectory

from fleet.mission.record import MissionSummary, held_intervals


def mission_problems(rec, layout) -> list[str]:
    problems = []
    for s in rec.subtasks:
        problems += [f"vehicle {s.vehicle} {s.kind.value} to {s.target}: {p}"
                     for p in check_trajectory(s.trajectory, [])]
    problems += record_problems(MissionSummary.of_record(rec), layout)
    last = {}
    for s in rec.subtasks:
        last[s.vehicle] = s.trajectory
    for vehicle, traj in last.items():
        if not any(iv.t1 == float("inf") for iv in traj.intervals):
            problems.append(f"vehicle {vehicle} does not end parked")
    return problems


def record_problems(record: MissionSummary, layout) -> list[str]:
    """The checks above that need only the mission record (a distributed run's recording)."""
    problems = overlaps(held_intervals(record))
    counts = Counter((s.cluster, s.index) for s in record.stacks_done)
    expected = {(s.cluster, s.index) for s in layout.stacks}
    problems += [f"stack {k} done {n} times" for k, n in counts.items() if n != 1]
    problems += [f"stack {k} never done" for k in expected - set(counts)]
    return problems


def journal_overlaps(path) -> list[str]:
    """Replay a reservation journal without the reservation table's code (each commit first
    cuts the committer's own intervals at release_from, then adds its intervals) and report
    every cell two owners held at once at any point of the history."""
    from reservation.journal import Journal

    held: dict[int, list[tuple[tuple[int, int], float, float]]] = defaultdict(list)
    for change in Journal(path).replay().changes:
        mine = held[change.vehicle]
        if change.release_from is not None:  # on the listed cells only, if any are
            cut, only = change.release_from, change.release_cells
            only = None if only is None else {tuple(c) for c in only}
            held[change.vehicle] = mine = [
                (c, t0, min(t1, cut)) if only is None or c in only else (c, t0, t1)
                for c, t0, t1 in mine if t0 < cut or (only is not None and c not in only)]
        mine += [((c, r), t0, t1) for c, r, t0, t1 in change.intervals]
    return overlaps([(v, cell, t0, t1) for v, spans in held.items() for cell, t0, t1 in spans])


def overlaps(held) -> list[str]:
    """Pairs of (owner, cell, t0, t1) of different owners that share a cell in time."""
    per_cell = defaultdict(list)
    for owner, cell, t0, t1 in held:
        if t1 > t0:
            per_cell[tuple(cell)].append((t0, t1, owner))
    problems = []
    for cell, spans in per_cell.items():
        active: list[tuple[float, float, int]] = []
        for b0, b1, vb in sorted(spans):
            active = [a for a in active if a[1] > b0]
            problems += [f"owners {va} and {vb} both hold {cell}: [{a0}, {a1}) and "
                         f"[{b0}, {b1})" for a0, a1, va in active if va != vb]
            active.append((b0, b1, vb))
    return problems
