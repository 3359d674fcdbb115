"""`fleet bench seed004`: seed 004's experiments in process on `paper004` (seed pack note B.5,
docs/experiment-004.md), means over order seeds with identical orders in each comparison:

- `heat` (Table 5, E004-1): a history run with heat off on orders of seed s + 1000 counts the
  traffic (fleet/mission/heat004.py); its T_value is frozen; then seed s runs with heat off
  and on (w_heat 2);
- `heat_weights`: the same with other weights of the heat cost (w_heat 1 and 4 beside the
  seed's 2 by default), each against heat off: whether the seed's effect is a matter of weight;
- `items` (Table 6, E004-2): a baseline without recall, turning cost or heap, and each item
  added alone; the heap changes only the time spent planning (the paths are the same), which
  is reported beside completion;
- `turn_example` (Figures 7-8, E004-3): two empty AGVs' fetch routes on the empty floor, with
  and without the turning cost;
- `fleet_sizes` (E004-5): completion and conflicts with 10 to 60 AGVs.

Every run is judged apart from the tracker and the planner (fleet/analysis/verdicts004.py):
`clashes`, `bad_moves`, `rule_breaches` and `yield_breaches` must be 0.
"""

from __future__ import annotations

import itertools
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass

from bench.pool import run_all
from fleet.analysis.verdicts004 import judge
from fleet.errors import UserError
from fleet.mission.heat004 import HISTORY_SEED, W_HEAT, heat_counts, history_heat
from fleet.mission.orders004 import Mission004, WorkParams, generate_orders
from fleet.mission.tracking004 import (
    STEPPED_ASIDE,
    Conflict,
    Moved,
    Replanned,
    Stuck,
    TrackingParams,
)
from fleet.planning.astar004 import Costs, count_turns, plan
from fleet.planning.rules004 import Kind, Task
from fleet.world.floor004 import Floor004, paper004

SEEDS = 10
ORDERS = 500
VEHICLES = 40
FLEET_SIZES = (10, 20, 40, 60)
HEAT_WEIGHTS = (1.0, 2.0, 4.0)
SWEPT = ("completion_s", "head_on", "crossing", "replans", "replans_head_on", "path_length",
         "turns")
ITEMS = ("baseline", "recall", "turn", "heap")
HEAD_ON_REPLANS = (Conflict.HEAD_ON.value, STEPPED_ASIDE)  # going around, or giving way


@dataclass(frozen=True)
class Job:
    experiment: str  # heat, items or sizes
    variant: str  # heat: off / on / w=W (another w_heat); items: ITEMS; sizes: the fleet size
    seed: int
    vehicles: int
    orders: int


@dataclass(frozen=True)
class Run:
    completion_s: float
    shelves_home_s: float
    head_on: int
    crossing: int
    rear_end: int
    replans: int
    # the replans a head-on conflict caused (an empty AGV going around a loaded one): the
    # seed's "far fewer replans" comes of avoiding where head-on conflicts happen
    replans_head_on: int
    path_length: int  # cells driven by the fleet
    turns: int
    recalled: int
    charges: int
    lowest_soc: float
    planning_s: float  # wall time in the planner
    pass_cv: float  # coefficient of variation of entries per drivable cell
    under_shelves: float  # share of empty AGVs' cells driven under shelves
    clashes: int
    bad_moves: int
    rule_breaches: int  # moves against the traffic rules, slots or lanes
    yield_breaches: int  # loaded AGVs that gave way to empty ones


def _numbers(run: Run) -> dict:
    return {k: getattr(run, k) for k in Run.__dataclass_fields__}


def _config(job: Job, floor: Floor004) -> tuple[TrackingParams, WorkParams]:
    """The tracker's and the work's settings of a job."""
    if job.experiment == "items":
        on = {"baseline": set(), "recall": {"recall"}, "turn": {"turn"}, "heap": {"heap"}}[
            job.variant]
        return (TrackingParams(costs=Costs(turn=1.0 if "turn" in on else 0.0),
                               heap="heap" in on), WorkParams(recall="recall" in on))
    if job.experiment == "heat" and job.variant != "off":
        heat = history_heat(floor, job.vehicles, job.orders, job.seed)
        weight = W_HEAT if job.variant == "on" else float(job.variant.removeprefix("w="))
        return TrackingParams(costs=Costs(heat=weight, t_value=heat)), WorkParams()
    return TrackingParams(), WorkParams()


def judged_run(job: Job) -> Run | str:
    """The run's figures, or why it stuck (a watchdog's message)."""
    floor = paper004()
    try:
        tracking, work = _config(job, floor)
        mission = Mission004(floor, job.vehicles, generate_orders(floor, job.orders, job.seed),
                             tracking, work)
        result = mission.run()
    except Stuck as exc:
        return f"{job.experiment} {job.variant} seed {job.seed}: {exc}"
    moved = [e for e in result.events if isinstance(e, Moved)]
    verdict = judge(floor, result.events,
                    {v: floor.parking[v - 1] for v in range(1, job.vehicles + 1)})
    drivable = [xy for xy, kind in floor.kinds.items() if kind in (Kind.FLOOR, Kind.SLOT)]
    entries = {xy: 0 for xy in drivable}
    for m in moved:
        if m.to in entries:
            entries[m.to] += 1
    counts = [entries[xy] for xy in drivable]
    mean = statistics.fmean(counts)
    empty = [m for m in moved if not m.loaded]
    c = result.counts
    return Run(result.completion_s, result.shelves_home_s, c.get("head-on", 0),
               c.get("crossing", 0), c.get("rear-end", 0), c["replans"],
               sum(isinstance(e, Replanned) and e.why in HEAD_ON_REPLANS for e in result.events),
               c["cells"],
               c["turns"], sum(p.recalled for p in result.picked), result.charges,
               result.lowest_soc, mission.tracker.planning_s,
               statistics.pstdev(counts) / mean if mean else 0.0,
               sum(floor.kind(m.to) is Kind.SLOT for m in empty) / len(empty) if empty else 0.0,
               len(verdict.clashes), len(verdict.bad_moves), len(verdict.rule_breaches),
               len(verdict.yield_breaches))


def heat_variant(weight: float) -> str:
    return "on" if weight == W_HEAT else f"w={weight:g}"


def jobs(seeds: int, orders: int, vehicles: int, sizes: tuple[int, ...],
         weights: tuple[float, ...] = HEAT_WEIGHTS) -> list[Job]:
    variants = dict.fromkeys(("off", "on", *map(heat_variant, weights)))
    out = [Job("heat", v, s, vehicles, orders) for s in range(seeds) for v in variants]
    out += [Job("items", v, s, vehicles, orders) for s in range(seeds) for v in ITEMS]
    out += [Job("sizes", str(n), s, n, orders) for n in sizes for s in range(seeds)]
    return sorted(out, key=lambda j: (j.variant == "off" or j.experiment != "heat",
                                      j.vehicles))  # the longest first


def run(seeds: int = SEEDS, orders: int = ORDERS, vehicles: int = VEHICLES,
        sizes: tuple[int, ...] = FLEET_SIZES,
        progress: Callable[[int, int], None] | None = None, workers: int | None = None,
        weights: tuple[float, ...] = HEAT_WEIGHTS) -> dict:
    """Every experiment, its missions spread over `workers` processes (default: one a core);
    each mission is deterministic, so the result does not depend on how many (but for the
    measured planning time)."""
    todo = jobs(seeds, orders, vehicles, sizes, weights)
    started = time.perf_counter()
    runs = run_all(todo, judged_run, progress, workers)

    def mean_of(experiment: str, variant: str) -> dict:
        of = [_numbers(r) for j, r in runs.items()
              if (j.experiment, j.variant) == (experiment, variant) and isinstance(r, Run)]
        if not of:
            stuck = [r for j, r in runs.items()
                     if (j.experiment, j.variant) == (experiment, variant)]
            raise UserError(f"every run of {experiment} {variant} stuck: {stuck[0]}")
        return {k: statistics.fmean(r[k] for r in of) for k in Run.__dataclass_fields__}

    judged = [r for r in runs.values() if isinstance(r, Run)]

    def paired(experiment: str, base: str, variant: str, key: str) -> float | None:
        """One-sided p that `variant` lowers `key` against `base`, seed by seed."""
        by_seed = {(j.variant, j.seed): r for j, r in runs.items()
                   if j.experiment == experiment and isinstance(r, Run)}
        return lower_p([getattr(by_seed[variant, s], key) - getattr(by_seed[base, s], key)
                        for s in range(seeds)
                        if (variant, s) in by_seed and (base, s) in by_seed])

    heat = {v: mean_of("heat", v) for v in ("off", "on")}

    def sweep(variant: str) -> dict:
        """A weight's means and their change against heat off, seed for seed the same."""
        on = mean_of("heat", variant)
        return {**{k: on[k] for k in SWEPT},
                "change": {k: _change(heat["off"][k], on[k]) for k in SWEPT},
                "head_on_p": paired("heat", "off", variant, "head_on"),
                "replans_p": paired("heat", "off", variant, "replans")}
    items = {v: mean_of("items", v) for v in ITEMS}
    result = {
        "floor": "paper004", "seeds": seeds, "orders": orders, "vehicles": vehicles,
        "w_heat": W_HEAT,
        "heat": heat,
        "heat_change": {k: _change(heat["off"][k], heat["on"][k]) for k in heat["off"]},
        "items": items,
        "paired_p": {
            "heat_completion": paired("heat", "off", "on", "completion_s"),
            "heat_head_on": paired("heat", "off", "on", "head_on"),
            "heat_path_length": paired("heat", "off", "on", "path_length"),
            **{f"{item}_completion": paired("items", "baseline", item, "completion_s")
               for item in ITEMS[1:]},
            "recall_path_length": paired("items", "baseline", "recall", "path_length"),
            "heap_planning": paired("items", "baseline", "heap", "planning_s"),
        },
        "turn_example": turn_example(paper004()),
        "heat_weights": {f"{w:g}": sweep(heat_variant(w)) for w in weights},
        "fleet_sizes": {str(n): mean_of("sizes", str(n)) for n in sizes},
        "stuck": [r for r in runs.values() if isinstance(r, str)],
        "clashes": sum(r.clashes for r in judged),
        "bad_moves": sum(r.bad_moves for r in judged),
        "rule_breaches": sum(r.rule_breaches for r in judged),
        "yield_breaches": sum(r.yield_breaches for r in judged),
        "runs": len(todo),
        "wall_s": time.perf_counter() - started,
    }
    result["checks"] = shape_checks(result)
    return result


def lower_p(differences: list[float]) -> float | None:
    """The exact one-sided p of a paired sign-flip test that the differences are below 0 (the
    share of the 2^n sign flips whose mean is as low or lower); None without differences."""
    n = len(differences)
    if n == 0:
        return None
    observed = sum(differences)
    flips = itertools.product((1, -1), repeat=n)
    as_low = sum(sum(s * d for s, d in zip(signs, differences, strict=True)) <= observed + 1e-9
                 for signs in flips)
    return as_low / 2 ** n


def _change(before: float, after: float) -> float:
    return (after - before) / before if before else 0.0


def heat_panels(seed: int, orders: int, vehicles: int) -> list[tuple[str, dict]]:
    """Figures 10-11 for one order seed: the history run's T_value, and the cells entered
    with heat off and on."""
    floor = paper004()
    heat = history_heat(floor, vehicles, orders, seed)
    panels: list[tuple[str, dict]] = [
        (f"T_value from the history run (orders of seed {seed + HISTORY_SEED})", heat)]
    for name, costs in (("off", Costs()), ("on", Costs(heat=W_HEAT, t_value=heat))):
        result = Mission004(floor, vehicles, generate_orders(floor, orders, seed),
                            TrackingParams(costs=costs)).run()
        panels.append((f"cells entered, heat {name} (seed {seed}), completion "
                       f"{result.completion_s:.0f} s", dict(heat_counts(result.events).passes)))
    return panels


def turn_example(floor: Floor004) -> dict:
    """Figures 7-8: two fetches from the top area to the coldest band, 13 cells each both
    with and without the turning cost, planned on the empty floor: those the cost saves the
    most turns on (ties: the cells)."""
    coldest = sorted(s.xy for s in floor.slots if s.goods.startswith("black"))
    top = sorted(xy for xy, kind in floor.kinds.items()
                 if kind is Kind.FLOOR and xy[1] < floor.shape.parking_rows)
    candidates = []
    for start, goal in itertools.product(top, coldest):
        if abs(start[0] - goal[0]) + abs(start[1] - goal[1]) != 13:
            continue
        off = plan(floor.grid, Task.FETCH, start, goal, None, Costs(turn=0.0))
        on = plan(floor.grid, Task.FETCH, start, goal, None, Costs(turn=1.0))
        if off is None or on is None or not off.length == on.length == 13:
            continue
        candidates.append((count_turns(on.cells) - count_turns(off.cells), start, goal, off,
                           on))
    candidates.sort(key=lambda c: (c[0], c[1], c[2]))
    picked, used = [], set()
    for _, start, goal, off, on in candidates:
        if start in used or goal in used:
            continue
        picked.append((start, goal, off, on))
        used |= {start, goal}
        if len(picked) == 2:
            break
    return {
        "routes": [{"from": s, "to": g} for s, g, _, _ in picked],
        "length_off": sum(off.length for *_, off, _ in picked),
        "length_on": sum(on.length for *_, on in picked),
        "turns_off": sum(count_turns(off.cells) for *_, off, _ in picked),
        "turns_on": sum(count_turns(on.cells) for *_, on in picked),
    }


def shape_checks(result: dict) -> dict[str, bool]:
    """The seed's statements as the note's direction targets (B-EXP-1, B-EXP-2, B-TURN-1)."""
    ch, items, ex = result["heat_change"], result["items"], result["turn_example"]
    base = items["baseline"]
    return {
        "heat_head_on_down_30": ch["head_on"] <= -0.30,
        "heat_replans_down_30": ch["replans"] <= -0.30,
        "heat_head_on_replans_down_30": ch["replans_head_on"] <= -0.30,
        "heat_path_shorter": ch["path_length"] < 0,
        "heat_more_turns": ch["turns"] > 0,
        "heat_crossing_within_15": abs(ch["crossing"]) <= 0.15,
        "heat_completion_0_10_shorter": -0.10 <= ch["completion_s"] <= 0,
        "heat_spread_more_even": ch["pass_cv"] < 0,
        "heat_more_under_shelves": ch["under_shelves"] > 0,
        "recall_less_distance": items["recall"]["path_length"] < base["path_length"],
        "recall_sooner": items["recall"]["completion_s"] < base["completion_s"],
        "recall_sooner_p05": _below(result["paired_p"]["recall_completion"], 0.05),
        "turn_more_distance_per_s": items["turn"]["path_length"] / items["turn"]["completion_s"]
        > base["path_length"] / base["completion_s"],
        "turn_sooner": items["turn"]["completion_s"] < base["completion_s"],
        "turn_sooner_p05": _below(result["paired_p"]["turn_completion"], 0.05),
        "heap_plans_faster": items["heap"]["planning_s"] < base["planning_s"],
        "heap_plans_faster_p05": _below(result["paired_p"]["heap_planning"], 0.05),
        "turn_example_26_cells": ex["length_off"] == ex["length_on"] == 26,
        "turn_example_turns_6_to_3": ex["turns_off"] >= 6 and ex["turns_on"] <= 3,
    }


def _below(p: float | None, level: float) -> bool:
    return p is not None and p < level


def table(result: dict) -> str:
    r = result
    lines = [f"seed 004 experiments on {r['floor']}: {r['runs']} order missions in process, "
             f"{r['orders']} orders, {r['seeds']} order seeds, {r['wall_s']:.0f} s"]
    cols = ("completion_s", "head_on", "crossing", "replans", "replans_head_on",
            "path_length", "turns", "pass_cv", "under_shelves")
    lines += ["", f"Table 5: heat cost off and on (w_heat {r['w_heat']:g}), {r['vehicles']} AGVs",
              f"{'':>9}" + "".join(f"{c:>15}" for c in cols)]
    for v in ("off", "on"):
        lines.append(f"{v:>9}" + "".join(f"{r['heat'][v][c]:>15.3g}" for c in cols))
    lines.append(f"{'change':>9}" + "".join(f"{r['heat_change'][c]:>15.1%}" for c in cols))
    lines += ["", "the heat cost's weight: change against heat off",
              f"{'w_heat':>9}" + "".join(f"{c:>15}" for c in SWEPT)]
    for w, m in r["heat_weights"].items():
        lines.append(f"{w:>9}" + "".join(f"{m['change'][c]:>15.1%}" for c in SWEPT))
    cols = ("completion_s", "path_length", "turns", "recalled", "planning_s")
    lines += ["", "Table 6: each optimisation item alone against the baseline",
              f"{'':>9}" + "".join(f"{c:>15}" for c in cols)]
    for v in ITEMS:
        lines.append(f"{v:>9}" + "".join(f"{r['items'][v][c]:>15.4g}" for c in cols))
    lines += ["", "one-sided paired p (sign flips over the seeds) that the change lowers it: " +
              ", ".join(f"{k} {v:.3g}" if v is not None else f"{k} -"
                        for k, v in r["paired_p"].items())]
    ex = r["turn_example"]
    lines += ["", f"Figures 7-8: two fetches, {ex['length_off']} cells and {ex['turns_off']} "
              f"turns without the turning cost, {ex['length_on']} cells and {ex['turns_on']} "
              f"turns with it"]
    cols = ("completion_s", "head_on", "crossing", "rear_end", "replans", "charges")
    lines += ["", "Fleet sizes", f"{'AGVs':>9}" + "".join(f"{c:>15}" for c in cols)]
    for n, m in r["fleet_sizes"].items():
        lines.append(f"{n:>9}" + "".join(f"{m[c]:>15.4g}" for c in cols))
    lines += ["", "the paper's statements (seed pack note B-EXP-1, B-EXP-2, B-TURN-1): " +
              ", ".join(f"{k} {'yes' if v else 'NO'}" for k, v in r["checks"].items()),
              f"cells two AGVs held at once: {r['clashes']}; moves that cannot be driven: "
              f"{r['bad_moves']}; against the rules, slots or lanes: {r['rule_breaches']}; "
              f"loaded AGVs giving way to empty ones: {r['yield_breaches']}"]
    return "\n".join(lines)
