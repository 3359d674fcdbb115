"""The Table 4 experiment: the five strategies on fill and on empty against a lower bound, the
ANN strategy over several training seeds, and an ablation of the comprehensive strategy.

Every mission is the in-process reference engine, so each number but the wall time is
deterministic. The missions and trainings are independent jobs, spread over a process a core.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from bench.pool import run_all
from fleet.dispatching.decision import Strategy
from fleet.dispatching.scorer import load_scorer, shipped_weights
from fleet.errors import UserError
from fleet.mission.engine import EngineOptions, run_mission
from fleet.mission.lower_bound import Bound, gap, relaxed_trips, stack_trips
from fleet.mission.record import MissionRecord
from fleet.mission.spec import STACK_KINDS, Mission, MissionKind
from fleet.params import DispatchParams
from fleet.world.layout import Layout
from fleet.world.layout_file import load_layout

ORDER = (Strategy.ANN, Strategy.COMPREHENSIVE, Strategy.GREEDY, Strategy.TRAFFIC,
         Strategy.BALANCE)
# The comprehensive strategy's terms (Equation 3), each switched off in turn.
ABLATION: dict[str, dict[str, float]] = {
    "all terms": {},
    "without G_d": {"C1": 0.0},
    "without H": {"cover_weight": 0.0},
    "without I_d": {"C2": 0.0},
    "without J_d,0 (H, I_d)": {"cover_weight": 0.0, "C2": 0.0},
}
ANN_CYCLES = 3  # fleet train's default


@dataclass(frozen=True)
class Job:
    layout: str
    kinds: tuple[MissionKind, ...]
    strategy: Strategy
    weights: str | None = None  # the ANN strategy's networks (None: shipped)
    train_seed: int | None = None  # train networks with this seed first (ANN_CYCLES cycles)
    ablate: str = ""  # a key of ABLATION (the comprehensive strategy only)
    solo: bool = False  # the first forklift alone


def _row(layout_name: str, kind: MissionKind, strategy: Strategy, options: EngineOptions,
         solo: bool) -> tuple[dict, MissionRecord]:
    layout = load_layout(layout_name)
    starts = layout.vehicle_starts[:1] if solo else ()
    t0 = time.perf_counter()
    record = run_mission(Mission(layout=layout_name, kind=kind, strategy=strategy,
                                 starts=starts), options, layout)
    return {"end_time_s": record.end_time, "failures": record.decision_failures,
            "wait_s": round(record.total_wait_s, 2),
            "wall_s": round(time.perf_counter() - t0, 2),
            "stacks": len(record.stacks_done), **fill_pattern(layout, record)}, record


def fill_pattern(layout: Layout, record: MissionRecord) -> dict:
    """What Section 6.2 tells of each run: stacks done per quarter of the end time, the
    spread of the clusters' done fractions at the quarter instants (0: perfectly balanced),
    and the cluster whose stack was done last."""
    end = record.end_time
    done = sorted(record.stacks_done, key=lambda d: d[2])
    quarters = [sum(1 for d in done if q * end / 4 < d[2] <= (q + 1) * end / 4)
                for q in range(4)]
    quarters[0] += sum(1 for d in done if d[2] <= 0)
    sizes = {c.name: len(layout.cluster_stacks(c.name)) for c in layout.clusters}
    spreads = []
    for q in (1, 2, 3):
        fractions = [sum(1 for d in done if d[0] == name and d[2] <= q * end / 4) / size
                     for name, size in sizes.items()]
        spreads.append(max(fractions) - min(fractions))
    return {"quarters": quarters, "cluster_spread": round(statistics.fmean(spreads), 3),
            "last_cluster": done[-1][0] if done else None}


def run_job(job: Job) -> dict[str, tuple[dict, MissionRecord]]:
    """Each mission kind's row and record (a worker process's job)."""
    from fleet.dispatching.mlp import one_thread
    from fleet.mission.training import train

    one_thread()  # one process a core already

    layout = load_layout(job.layout)
    params = replace(DispatchParams(), **ABLATION[job.ablate]) if job.ablate else \
        DispatchParams()
    mlp = None
    if job.train_seed is not None:
        mlp, _ = train(layout, ANN_CYCLES, job.train_seed)
    elif job.strategy is Strategy.ANN:
        mlp = load_scorer(layout, Path(job.weights) if job.weights else None)
    return {kind.value: _row(job.layout, kind, job.strategy,
                             EngineOptions(params=params, mlp=mlp), job.solo)
            for kind in job.kinds}


def _summary(values: list[float]) -> dict[str, float]:
    return {"mean": round(statistics.fmean(values), 2),
            "sd": round(statistics.stdev(values), 2) if len(values) > 1 else 0.0,
            "min": min(values), "max": max(values)}


def run(layout_name: str = "paper", missions: tuple[MissionKind, ...] = STACK_KINDS,
        weights: Path | None = None, ann_seeds: int = 0,
        progress: Callable[[str, int, int], None] | None = None) -> dict:
    layout = load_layout(layout_name)
    if not layout.stacks or not layout.vehicle_starts:
        raise UserError(f"layout {layout.name} has no stacks or no forklift starts: the Table 4 "
                        f"experiment fills and empties stacks (seed 000's layouts: paper, "
                        f"paper-cut, paper-firewall, small, hall)")
    if weights is not None:
        load_scorer(layout, weights)  # a bad file is named before anything runs
    starts = layout.vehicle_starts
    result: dict = {"layout": layout.name, "vehicles": len(starts), "lower_bound_s": {},
                    "relaxed_bound_s": {}}
    trips = stack_trips(layout, starts, None if progress is None else
                        lambda done, total: progress("lower bound", done, total))
    relaxed = relaxed_trips(layout, starts)
    bounds = {kind.value: Bound.of(trips, kind, starts, DispatchParams()) for kind in missions}
    for kind in missions:
        result["lower_bound_s"][kind.value] = round(bounds[kind.value].value, 2)
        result["relaxed_bound_s"][kind.value] = round(
            Bound.of(relaxed, kind, starts, DispatchParams()).value, 2)
    if weights is not None or shipped_weights(layout.name) is not None:
        load_scorer(layout, weights)  # shipped ones must fit the layout too
        ann = Job(layout_name, missions, Strategy.ANN, str(weights) if weights else None)
        result["ann_weights"] = str(weights) if weights else "shipped"
    else:  # as they would ship: `fleet train` with seed 0
        ann = Job(layout_name, missions, Strategy.ANN, train_seed=0)
        result["ann_weights"] = f"trained here: seed 0, {ANN_CYCLES} cycles"
    strategies = {s: ann if s is Strategy.ANN else Job(layout_name, missions, s) for s in ORDER}
    seeds = [Job(layout_name, missions, Strategy.ANN, train_seed=seed)
             for seed in range(ann_seeds)]
    ablation = {name: Job(layout_name, missions, Strategy.COMPREHENSIVE, ablate=name)
                for name in ABLATION if name != "all terms"}
    solo = Job(layout_name, missions, Strategy.COMPREHENSIVE, solo=True)
    jobs = list(dict.fromkeys([*strategies.values(), *seeds, *ablation.values(), solo]))
    done = run_all(jobs, run_job, None if progress is None else
                   lambda n, total: progress("missions and trainings", n, total))

    def with_bound(kind: str, row: dict, record: MissionRecord, b: Bound | None = None
                   ) -> dict:
        b = b or bounds[kind]
        return {**row, "ratio_to_bound": round(row["end_time_s"] / b.value, 4),
                "gap": gap(record, b).as_dict()}

    for kind in missions:
        k = kind.value
        result[k] = {s.value: with_bound(k, *done[job][k]) for s, job in strategies.items()}
        result.setdefault("ablation", {})[k] = {"all terms": result[k]["comprehensive"]} | {
            name: with_bound(k, *done[job][k]) for name, job in ablation.items()}
    for kind in missions:  # what the planner and dispatcher do with nobody in the way
        k = kind.value
        alone = Bound.of(trips, kind, starts[:1], DispatchParams())
        row = with_bound(k, *done[solo][k], alone)
        result.setdefault("solo", {})[k] = row | {
            "per_forklift_s": round(row["end_time_s"] / len(starts), 2),
            "comprehensive_vs_per_forklift": round(
                result[k]["comprehensive"]["end_time_s"] * len(starts) / row["end_time_s"], 4)}
    if seeds:
        result["ann_seeds"] = {"training": {"cycles": ANN_CYCLES,
                                            "seeds": [j.train_seed for j in seeds]}}
        for kind in missions:
            k = kind.value
            rows = [{"seed": j.train_seed, "end_time_s": done[j][k][0]["end_time_s"],
                     "failures": done[j][k][0]["failures"]} for j in seeds]
            ends = [r["end_time_s"] for r in rows]
            comprehensive = result[k]["comprehensive"]["end_time_s"]
            result["ann_seeds"][k] = {
                "runs": rows, "end_time_s": _summary(ends),
                "failures": _summary([float(r["failures"]) for r in rows]),
                "mean_vs_comprehensive": round(statistics.fmean(ends) / comprehensive - 1, 4)}
    return result


def table(result: dict) -> str:
    lines = [f"Table 4 style, layout {result['layout']}, {result['vehicles']} forklifts; "
             f"ANN networks: {result['ann_weights']}"]
    for kind in ("fill", "empty"):
        if kind not in result:
            continue
        bound_s = result["lower_bound_s"][kind]
        lines.append(f"\n{kind}: lower bound {bound_s:.2f} s (relaxed, by proof: "
                     f"{result['relaxed_bound_s'][kind]:.2f} s)")
        lines.append(f"  {'strategy':<24} {'end time s':>10} {'x bound':>8} {'failures':>8} "
                     f"{'waiting s':>9} {'wall s':>7}")
        for name, row in result[kind].items():
            lines.append(_line(name, row))
        seeds = result.get("ann_seeds", {}).get(kind)
        if seeds:
            e, f = seeds["end_time_s"], seeds["failures"]
            lines.append(f"  {'ann, ' + str(len(seeds['runs'])) + ' training seeds':<24} "
                         f"{e['mean']:>10.2f} {e['mean'] / bound_s:>8.3f} {f['mean']:>8.1f}"
                         f"   sd {e['sd']:.2f} s, {e['min']:.2f} .. {e['max']:.2f} s, "
                         f"{100 * seeds['mean_vs_comprehensive']:+.1f} % vs comprehensive")
        solo = result.get("solo", {}).get(kind)
        if solo:
            lines.append(f"  comprehensive, the first forklift alone: {solo['end_time_s']:.2f} s "
                         f"({solo['ratio_to_bound']:.3f} x its bound); shared by "
                         f"{result['vehicles']}: {solo['per_forklift_s']:.2f} s, which "
                         f"comprehensive takes {solo['comprehensive_vs_per_forklift']:.3f} x")
        lines.append(f"  ablation of comprehensive ({kind}):")
        for name, row in result.get("ablation", {}).get(kind, {}).items():
            lines.append(_line("  " + name, row))
    return "\n".join(lines)


def _line(name: str, row: dict) -> str:
    return (f"  {name:<24} {row['end_time_s']:>10.2f} {row['ratio_to_bound']:>8.3f} "
            f"{row['failures']:>8} {row['wait_s']:>9.1f} {row['wall_s']:>7.1f}")
