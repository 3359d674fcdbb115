"""Checks of a whole mission record for tests, apart from the engine and the planner: every
trajectory covers its own swept cells (brute_force), no two vehicles ever hold one cell at once,
every stack is done exactly once, and every forklift ends parked."""

from __future__ import annotations

from collections import Counter, defaultdict

from brute_force import check_trajectory

from fleet.record_io import held_intervals, record_to_dict


def mission_problems(rec, layout) -> list[str]:
    problems = []
    for s in rec.subtasks:
        problems += [f"vehicle {s.vehicle} {s.kind.value} to {s.target}: {p}"
                     for p in check_trajectory(s.trajectory, [])]
    per_cell = defaultdict(list)
    for vehicle, cell, t0, t1 in held_intervals(record_to_dict(rec)):
        per_cell[cell].append((t0, t1, vehicle))
    for cell, spans in per_cell.items():
        active: list[tuple[float, float, int]] = []  # spans still open at the sweep time
        for b0, b1, vb in sorted(spans):
            active = [a for a in active if a[1] > b0]
            problems += [f"vehicles {va} and {vb} both hold {cell}: [{a0}, {a1}) and "
                         f"[{b0}, {b1})" for a0, a1, va in active if va != vb]
            active.append((b0, b1, vb))
    counts = Counter((c, i) for c, i, _ in rec.stacks_done)
    expected = {(s.cluster, s.index) for s in layout.stacks}
    problems += [f"stack {k} done {n} times" for k, n in counts.items() if n != 1]
    problems += [f"stack {k} never done" for k in expected - set(counts)]
    last = {}
    for s in rec.subtasks:
        last[s.vehicle] = s.trajectory
    for vehicle, traj in last.items():
        if not any(iv.t1 == float("inf") for iv in traj.intervals):
            problems.append(f"vehicle {vehicle} does not end parked")
    return problems
