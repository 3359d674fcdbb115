"""`fleet bench seed002`: seed 002's three experiments (Section 6, Figures 17-19), the
bidirectional warehouse (`paper002`) against the unidirectional one (`paper002-uni`), every
mission in process, mean and spread over order seeds (docs/experiment-002.md).

- Figure 17: 10 AGVs, 50 to 250 orders;
- Figure 18: 50 orders, 5 to 20 AGVs;
- Figure 19: 10 AGVs, 10 to 40 orders bunched on the lower-left shelf area.

`checks` holds the seed pack note's shape targets (A-EXP-1 to 3), each True or False.

Every run is also judged, apart from the planner: each AGV's routes by the lane oracle
(fleet/analysis/lane_rules.py) and the cells held by the safety verifier's double-booking
check (fleet/analysis/safety.py), so a saving never comes from a broken rule.
"""

from __future__ import annotations

import itertools
import statistics
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

from bench.pool import run_all
from fleet.analysis.lane_rules import lane_violations
from fleet.analysis.safety import Held, double_bookings
from fleet.dispatching.decision import Strategy
from fleet.mission.engine import run_mission
from fleet.mission.record import MissionSummary, held_intervals
from fleet.mission.spec import Mission, MissionKind
from fleet.planning.trajectory import Pose
from fleet.world.layout_file import load_layout

BIDIRECTIONAL, UNIDIRECTIONAL = "paper002", "paper002-uni"
FIG17 = tuple((orders, 10) for orders in (50, 100, 150, 200, 250))
FIG18 = tuple((50, agvs) for agvs in (5, 10, 15, 20))
FIG19 = tuple((orders, 10) for orders in (10, 15, 20, 25, 30, 35, 40))
LOWER_LEFT = "lower-left"
SEEDS = 10


@dataclass(frozen=True)
class Point:
    orders: int
    agvs: int
    bi_s: float  # mean makespan (the last order's shelf put down), seconds
    uni_s: float
    bi_sd: float  # sample standard deviation over the seeds
    uni_sd: float
    saving: float  # 1 - bi_s / uni_s
    # Where the time goes, means over the seeds: the AGVs' driving and their waits for the
    # collision rules, summed over the fleet, seconds.
    bi_drive_s: float
    uni_drive_s: float
    bi_wait_s: float
    uni_wait_s: float


@dataclass(frozen=True)
class Run:
    end_s: float
    drive_s: float
    wait_s: float
    lane_violations: int
    double_bookings: int


@dataclass(frozen=True)
class Job:
    figure: str
    orders: int
    agvs: int
    layout: str
    seed: int
    area: str


def judged_run(job: Job) -> Run:
    layout = load_layout(job.layout)
    record = run_mission(Mission(layout=layout.name, kind=MissionKind.ORDERS,
                                 strategy=Strategy.NEAREST, vehicles=job.agvs, seed=job.seed,
                                 orders=job.orders, order_area=job.area), layout=layout)
    summary = MissionSummary.of_record(record)
    lanes = sum(len(lane_violations(layout, route_cells(s.steps))) for s in summary.subtasks)
    held = [Held(v, cell, t0, t1) for v, cell, t0, t1 in held_intervals(summary)]
    wait = layout.vehicle_kind.is_wait
    steps = [(label, t1 - t0) for s in summary.subtasks for label, _, _, t0, t1, *_ in s.steps]
    return Run(record.end_time, sum(d for label, d in steps if not wait(label)),
               sum(d for label, d in steps if wait(label)), lanes,
               len(double_bookings(held)))


def route_cells(steps) -> list[tuple[int, int]]:
    """The cells a subtask's recorded steps drive through, in order (a wait repeats one)."""
    if not steps:
        return []
    cells = [Pose.parse(steps[0][1]).cell]
    cells += [Pose.parse(end).cell for _, _, end, *_ in steps]
    return cells


def jobs(seeds: int) -> list[Job]:
    """Every mission of the three experiments, the longest first (a pool ends sooner)."""
    figures = {"fig17": (FIG17, ""), "fig18": (FIG18, ""), "fig19": (FIG19, LOWER_LEFT)}
    out = [Job(fig, orders, agvs, layout, seed, area)
           for fig, (points, area) in figures.items() for orders, agvs in points
           for layout in (BIDIRECTIONAL, UNIDIRECTIONAL) for seed in range(seeds)]
    return sorted(out, key=lambda j: -j.orders)


def run(seeds: int = SEEDS, progress: Callable[[int, int], None] | None = None,
        workers: int | None = None) -> dict:
    """The three experiments, their missions spread over `workers` processes (default: one
    a core); every mission is deterministic, so the result does not depend on how many."""
    todo = jobs(seeds)
    started = time.perf_counter()
    runs = run_all(todo, judged_run, progress, workers)
    result: dict = {"seeds": seeds}
    for fig, points in (("fig17", FIG17), ("fig18", FIG18), ("fig19", FIG19)):
        out = []
        for orders, agvs in points:
            of = {name: [r for j, r in runs.items() if (j.figure, j.orders, j.agvs, j.layout)
                         == (fig, orders, agvs, name)]
                  for name in (BIDIRECTIONAL, UNIDIRECTIONAL)}
            bi, uni = ([r.end_s for r in of[n]] for n in (BIDIRECTIONAL, UNIDIRECTIONAL))
            out.append(Point(orders, agvs, statistics.fmean(bi), statistics.fmean(uni),
                             _sd(bi), _sd(uni), 1 - statistics.fmean(bi) / statistics.fmean(uni),
                             *(statistics.fmean(getattr(r, what) for r in of[n])
                               for what in ("drive_s", "wait_s")
                               for n in (BIDIRECTIONAL, UNIDIRECTIONAL))))
        result[fig] = [asdict(p) for p in out]
    result["mean_saving_fig17"] = statistics.fmean(p["saving"] for p in result["fig17"])
    result["checks"] = shape_checks(result)
    result["lane_violations"] = sum(r.lane_violations for r in runs.values())
    result["double_bookings"] = sum(r.double_bookings for r in runs.values())
    result["runs"] = len(todo)
    result["wall_s"] = time.perf_counter() - started
    return result


def shape_checks(result: dict) -> dict[str, bool]:
    """The paper's statements as the note's checks (A-EXP-1 to 3)."""
    f17, f18, f19 = result["fig17"], result["fig18"], result["fig19"]

    def rising(points: list[dict], key: str) -> bool:
        return all(a[key] < b[key] for a, b in itertools.pairwise(points))

    uni19 = [p["uni_s"] for p in f19]
    second = [a - 2 * b + c for a, b, c in zip(uni19, uni19[1:], uni19[2:], strict=False)]
    return {
        "fig17_rises_with_orders": rising(f17, "bi_s") and rising(f17, "uni_s"),
        "fig17_saving_15_35_each": all(0.15 <= p["saving"] <= 0.35 for p in f17),
        "fig17_mean_saving_18_30": 0.18 <= result["mean_saving_fig17"] <= 0.30,
        "fig18_falls_with_agvs": all(a[k] > b[k] for k in ("bi_s", "uni_s")
                                     for a, b in itertools.pairwise(f18)),
        "fig18_diminishing_returns": all(f18[0][k] - f18[1][k] > f18[2][k] - f18[3][k]
                                         for k in ("bi_s", "uni_s")),
        "fig18_bi_faster": all(p["bi_s"] < p["uni_s"] for p in f18),
        "fig19_bi_faster": all(p["bi_s"] < p["uni_s"] for p in f19),
        "fig19_uni_steepens": statistics.fmean(second) > 0,
        "fig19_gap_grows": f19[-1]["uni_s"] - f19[-1]["bi_s"] > f19[0]["uni_s"] - f19[0]["bi_s"],
    }


def _sd(values: list[float]) -> float:
    return statistics.stdev(values) if len(values) > 1 else 0.0


def table(result: dict) -> str:
    lines = [f"seed 002 experiments: {result['runs']} order missions in process, "
             f"{result['seeds']} order seeds a point, {result['wall_s']:.0f} s"]
    titles = {"fig17": "Figure 17: 10 AGVs, orders vary",
              "fig18": "Figure 18: 50 orders, AGVs vary",
              "fig19": "Figure 19: 10 AGVs, orders on the lower-left shelf area"}
    for fig, title in titles.items():
        lines += ["", title, f"{'orders':>6} {'AGVs':>4} {'bidirectional s':>17} "
                  f"{'unidirectional s':>18} {'saving':>7}   {'driving s bi/uni':>17} "
                  f"{'waiting s bi/uni':>16}"]
        for p in result[fig]:
            lines.append(f"{p['orders']:>6} {p['agvs']:>4} {p['bi_s']:>9.1f} ± {p['bi_sd']:<5.1f} "
                         f"{p['uni_s']:>10.1f} ± {p['uni_sd']:<5.1f} {p['saving']:>6.1%}   "
                         f"{p['bi_drive_s']:>8.0f}/{p['uni_drive_s']:<8.0f} "
                         f"{p['bi_wait_s']:>7.0f}/{p['uni_wait_s']:<7.0f}")
    lines += ["", f"mean saving over Figure 17: {result['mean_saving_fig17']:.1%}",
              "the paper's shape (seed pack note A-EXP-1 to 3): " + ", ".join(
                  f"{name} {'yes' if held else 'NO'}" for name, held in result["checks"].items()),
              f"lane rules broken: {result['lane_violations']}; cells double-booked: "
              f"{result['double_bookings']}"]
    return "\n".join(lines)
