"""`fleet bench ...`: benchmarks (speed goals live here, not in timed tests)."""

from __future__ import annotations

import argparse
import itertools
import json
import platform
import sys
import time
from pathlib import Path

from fleet.commands.progress import ProgressBar
from fleet.dispatching.decision import Strategy
from fleet.errors import UserError
from fleet.mission.spec import ClockMode
from fleet.params import LOOKAHEAD_S
from fleet.recording.rundir import RUNS, default_name
from fleet.runtime.argtypes import (
    integer,
    layout_arg,
    lookahead_arg,
    lookahead_text,
    non_negative_int,
    positive_float,
    positive_floats,
    positive_int,
    positive_ints,
    text_file,
    writable_dir,
)
from fleet.runtime.helptext import strategies_epilog

ANN_SEEDS = 5  # training seeds of `fleet bench strategies`


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="run a benchmark",
                       description="Benchmarks: speed goals are measured here, not in timed "
                       "tests (docs/benchmarks.md, docs/experiment.md).")
    which = p.add_subparsers(dest="bench", required=True, metavar="BENCH")
    planner = which.add_parser("planner", help="seeded station <-> stack planner queries",
                               description="Time the improved hybrid A* on seeded random "
                               "queries between stations and stacks.")
    planner.add_argument("--layout", default="paper", type=layout_arg,
                         help="layout name or TOML file (default paper)")
    planner.add_argument("--queries", type=positive_int, default=240,
                         help="planner queries (default 240)")
    planner.add_argument("--seed", type=integer, default=2026,
                         help="seed of the queries (default 2026)")
    planner.add_argument("--json", action="store_true", help="print one JSON object")
    planner.set_defaults(handler=run_planner)
    planner004 = which.add_parser("planner004", help="seed 004's A*: binary heap against "
                                  "plain list, and the turning cost",
                                  description="Seed 004's improved A* on paper004: the "
                                  "binary-heap open list against the plain list on the same "
                                  "seeded queries of every task type (same paths, planning "
                                  "time), and the turning cost on empty fetches over an empty "
                                  "floor (turns and route lengths) (docs/agv-004.md).")
    planner004.add_argument("--queries", type=positive_int, default=500,
                            help="queries of each task type, and fetches for the turning "
                            "cost (default 500)")
    planner004.add_argument("--seed", type=integer, default=2026,
                            help="seed of the queries (default 2026)")
    planner004.add_argument("--json", action="store_true", help="print one JSON object")
    planner004.set_defaults(handler=run_planner004)
    strategies = which.add_parser("strategies", help="the five strategies on fill and empty "
                                  "(Table 4 of seed 000) with a lower bound",
                                  description="Run every strategy in process on the fill "
                                  "and empty missions and compare their end times with a "
                                  "lower bound (Table 4 of seed 000); train the ANN "
                                  "strategy over several seeds; switch the comprehensive "
                                  "strategy's terms off in turn (docs/experiment.md).",
                                  epilog=strategies_epilog())
    strategies.add_argument("--layout", default="paper", type=layout_arg,
                            help="layout name or TOML file (default paper)")
    strategies.add_argument("--mission", choices=["fill", "empty", "both"], default="both",
                            help="which missions (default both)")
    strategies.add_argument("--weights", type=text_file, metavar="FILE",
                            help="MLP weights for the ANN strategy (default: shipped)")
    strategies.add_argument("--ann-seeds", type=non_negative_int, default=ANN_SEEDS,
                            metavar="N", help="train the ANN strategy's networks with seeds "
                            f"0 .. N-1 (3 cycles each) and report its end time over them "
                            f"(default {ANN_SEEDS})")
    strategies.add_argument("--json", action="store_true", help="print one JSON object")
    strategies.set_defaults(handler=run_strategies)
    seed002 = which.add_parser("seed002", help="seed 002's Figures 17-19: bidirectional "
                               "against unidirectional lanes, over order seeds",
                               description="Run seed 002's three experiments in process: "
                               "order missions on paper002 (bidirectional channels) and "
                               "paper002-uni (one-way lanes), mean and spread of the makespan "
                               "over order seeds, every run judged by the lane oracle and "
                               "the double-booking check (docs/experiment-002.md).")
    seed002.add_argument("--jobs", type=positive_int, default=None, metavar="N",
                         help="missions run at once, each in a process of its own (default: "
                         "one a core); the results do not depend on it")
    seed002.add_argument("--seeds", type=positive_int, default=10,
                         help="order seeds per point (default 10)")
    seed002.add_argument("--json", action="store_true", help="print one JSON object")
    seed002.add_argument("--plots", type=writable_dir, metavar="DIR",
                         help="also draw the makespan curves into DIR: fig17.png, fig18.png, "
                         "fig19.png (mean with one standard deviation as error bars; `fleet "
                         "plot RESULT.json` draws them from a saved --json result; default: "
                         "none)")
    seed002.set_defaults(handler=run_seed002)
    seed004 = which.add_parser("seed004", help="seed 004's Tables 5-6 and Figures 7-8: heat "
                               "cost, recall, turning cost and heap, fleet sizes",
                               description="Run seed 004's experiments in process on "
                               "paper004: heat cost off and on after a history run (Table 5), "
                               "each optimisation item against a baseline (Table 6), the "
                               "turning-cost example (Figures 7-8) and fleet sizes, means over "
                               "order seeds, every run judged by the verifiers of cells, "
                               "rules and giving way (docs/experiment-004.md).")
    seed004.add_argument("--seeds", type=positive_int, default=10,
                         help="order seeds per point (default 10)")
    seed004.add_argument("--orders", type=positive_int, default=500,
                         help="orders per mission (default 500)")
    seed004.add_argument("--vehicles", type=positive_int, default=40,
                         help="AGVs in Tables 5 and 6 (default 40)")
    seed004.add_argument("--sizes", type=positive_ints, default=[10, 20, 40, 60],
                         metavar="N,N,...", help="fleet sizes compared (default 10,20,40,60)")
    seed004.add_argument("--heat-weights", type=positive_floats, default=[1.0, 2.0, 4.0],
                         metavar="W,W,...", help="w_heat values each run against heat off, "
                         "beside Table 5's 2 (default 1,2,4)")
    seed004.add_argument("--jobs", type=positive_int, default=None, metavar="N",
                         help="missions run at once, each in a process of its own (default: "
                         "one a core); only the planning times depend on it")
    seed004.add_argument("--json", action="store_true", help="print one JSON object")
    seed004.add_argument("--plots", type=writable_dir, metavar="DIR",
                         help="also draw DIR/heat.png: the history run's heat and the cells "
                         "entered with heat off and on, for order seed 0 (Figures 10-11; "
                         "default: none)")
    seed004.set_defaults(handler=run_seed004)
    runtime = which.add_parser("runtime", help="the distributed runtime: commit round trip, "
                               "multi-process / in-process wall time, largest real-time fleet",
                               description="Measure the distributed runtime: the "
                               "reservation commit round trip, a fill as processes against "
                               "in process, and the largest fleet that keeps real time.")
    runtime.add_argument("--commits", type=positive_int, default=2000,
                         help="commits timed (default 2000)")
    runtime.add_argument("--seed", type=integer, default=2026,
                         help="seed of the commits (default 2026)")
    runtime.add_argument("--ratio-layout", default="paper", type=layout_arg,
                         help="layout of the multi-process vs in-process fill (default paper)")
    runtime.add_argument("--ratio-repeats", type=non_negative_int, default=3,
                         help="runs of each, alternated (default 3; 0 skips)")
    runtime.add_argument("--agents", type=fleet_sizes, default="25,50,100,150",
                         help="fleet sizes to try in real time, ascending (default "
                         "25,50,100,150; 'none' skips)")
    runtime.add_argument("--window", type=positive_float, default=15.0,
                         help="seconds of state messages measured per fleet (default 15)")
    runtime.add_argument("--json", action="store_true", help="print one JSON object")
    runtime.set_defaults(handler=run_runtime)
    scale = which.add_parser("scale", help="whole fill missions with growing fleets, in process "
                             "and as processes",
                             description="Run a fill mission on a generated warehouse for each "
                             "fleet size (parking for 1.5 times the fleet, about ten stacks a "
                             "forklift), on the fast clock, in process and as processes, each "
                             "judged by its recording's verdicts; report wall time per decision, "
                             "failures and peak memory, and how each grows with the fleet "
                             "(docs/benchmarks.md).")
    scale.add_argument("--fleets", type=fleet_sizes, default="12,32,64,100",
                       help="fleet sizes, ascending (default 12,32,64,100)")
    scale.add_argument("--modes", choices=["both", "inprocess", "processes"], default="both",
                       help="in process, as processes, or both (default)")
    scale.add_argument("--strategy", choices=[s.value for s in Strategy], default="greedy",
                       help="dispatch strategy (default greedy: the ANN's networks are "
                       "trained for paper)")
    scale.add_argument("--lookahead", type=lookahead_arg, default=LOOKAHEAD_S,
                       metavar="SECONDS", help=f"Algorithm 1's lookahead, as fleet run takes it "
                       f"(none: no bound; default {LOOKAHEAD_S:g})")
    scale.add_argument("--timeout", type=positive_float, default=30.0, metavar="MINUTES",
                       help="give a mission up after this many minutes of wall time "
                       "(default 30)")
    scale.add_argument("--keep", type=Path, metavar="DIR",
                       help="keep every run's directory (recording, logs) and floor in DIR, "
                       "a new directory (default: only a run that did not complete is kept, "
                       "in a temporary directory the report names)")
    scale.add_argument("--json", action="store_true", help="print one JSON object")
    scale.set_defaults(handler=run_scale)
    runtime004 = which.add_parser(
        "runtime004", help="seed 004 as processes: against in process, and real time",
        description="Seed 004's lifting AGVs as one agent process each: an order mission on "
        "paper004 as processes against in process, side by side (same record), and whole "
        "missions of large fleets on the real-time clock at speed 1: instants handled late "
        "and the memory of each agent process (docs/benchmarks.md).")
    runtime004.add_argument("--orders", type=positive_int, default=100,
                            help="orders of the side-by-side mission (default 100)")
    runtime004.add_argument("--vehicles", type=positive_int, default=10,
                            help="AGVs of the side-by-side mission (default 10)")
    runtime004.add_argument("--repeats", type=non_negative_int, default=3,
                            help="runs of each, alternated (default 3; 0 skips)")
    runtime004.add_argument("--agents", type=fleet_sizes, default="40,96",
                            help="fleets run in real time at speed 1 (default 40,96: "
                            "paper004 parks 96; 'none' skips)")
    runtime004.add_argument("--rt-orders", type=positive_int, default=100,
                            help="orders of each real-time mission (default 100)")
    runtime004.add_argument("--speed", type=positive_float, default=1.0,
                            help="sim seconds per wall second of the real-time missions "
                            "(default 1)")
    runtime004.add_argument("--json", action="store_true", help="print one JSON object")
    runtime004.set_defaults(handler=run_runtime004)
    vda = which.add_parser(
        "vda5050", help="the VDA 5050 gateway under a fleet: latency, states, losses",
        description="A generated warehouse with a park per forklift, fleet run --dispatch "
        "external on a mosquitto of its own, and a measuring master that sends every "
        "forklift an order at once (its park to the nearest free stack), then one back once "
        "all are driven, and reads every state: order-to-motion latency p50 and p99 (order "
        "published to the first state with driving true) for fresh agents and warm ones, "
        "states per second held while the fleet drives, states lost (gaps in each "
        "forklift's headerIds). Needs mosquitto.")
    vda.add_argument("--vehicles", type=positive_int, default=50,
                     help="forklifts, each a VDA 5050 AGV (default 50)")
    vda.add_argument("--json", action="store_true", help="print one JSON object")
    vda.set_defaults(handler=run_vda5050)
    recorder = which.add_parser("recorder", help="the recorder: messages a second without "
                                "loss, and what recording costs a mission's wall time",
                                description="Measure the recorder: how many messages a "
                                "second it keeps without loss, and what recording costs a "
                                "mission's wall time.")
    recorder.add_argument("--rates", type=positive_ints, default="2000,5000,10000,20000,40000",
                          help="target messages a second, in all (default "
                          "2000,5000,10000,20000,40000)")
    recorder.add_argument("--seconds", type=positive_float, default=5.0,
                          help="seconds of publishing per rate (default 5)")
    recorder.add_argument("--publishers", type=positive_int, default=4,
                          help="state streams, one per vehicle (default 4)")
    recorder.add_argument("--repeats", type=non_negative_int, default=3,
                          help="fills with and without the recorder, alternated (default 3; "
                          "0 skips)")
    recorder.add_argument("--layout", default="paper", type=layout_arg,
                          help="layout of the fills (default paper)")
    recorder.add_argument("--json", action="store_true", help="print one JSON object")
    recorder.set_defaults(handler=run_recorder)
    faults = which.add_parser("faults", help="every shipped fault scenario beside the "
                              "fault-free run: detection, recovery, extra mission time, verdicts "
                              "(docs/reliability.md)",
                              description="Run every shipped fault scenario (or those named) "
                              "beside the fault-free run and report how each fault was "
                              "detected and recovered from, the extra mission time and the "
                              "verdicts (docs/reliability.md).")
    faults.add_argument("--scenarios", help="comma-separated shipped scenarios (default all)")
    faults.add_argument("--json", action="store_true", help="print one JSON object keyed by "
                        "scenario (a kind's own scenario is named after the kind)")
    faults.add_argument("--clock", choices=[m.value for m in ClockMode],
                        default=ClockMode.FAST.value,
                        help="the runs' clock (default fast)")
    faults.add_argument("--speed", type=positive_float, default=20.0,
                        help="sim seconds per wall second with --clock realtime (default 20)")
    faults.add_argument("--layout", default="paper", type=layout_arg,
                        help="paper: its fill with four forklifts (default); a lane layout "
                        "(paper002) or a seed-004 floor (paper004): an order mission, with "
                        "the layout's own scenarios")
    faults.add_argument("--orders", type=positive_int, default=40,
                        help="an order mission's orders (default 40)")
    faults.add_argument("--vehicles", type=positive_int, default=6,
                        help="an order mission's AGVs (default 6)")
    faults.set_defaults(handler=run_faults)
    campaign = which.add_parser("campaign", help="seeded random fault scenarios, fill and "
                                "empty, each run judged as fleet analyze judges it "
                                "(docs/reliability.md)",
                                description="Run missions, each with faults drawn from the "
                                "seed and the run's number (kinds, instants, forklifts, "
                                "durations; several per run), fill and empty in turn, and "
                                "judge each by its recording's verdicts against the same "
                                "mission without faults. Every failing run's scenario is "
                                "written to OUT as a TOML file that fleet run --faults FILE "
                                "replays (bit for bit on the fast clock), its recording "
                                "beside it (docs/reliability.md).")
    campaign.add_argument("--runs", type=positive_int, default=10,
                          help="missions with faults (default 10)")
    campaign.add_argument("--seed", type=non_negative_int, default=2026,
                          help="seed of the faults (default 2026)")
    campaign.add_argument("--clock", choices=[m.value for m in ClockMode],
                          default=ClockMode.FAST.value,
                          help="fast: in process, the reference (default); realtime: as "
                          "processes")
    campaign.add_argument("--speed", type=positive_float, default=20.0,
                          help="sim seconds per wall second with --clock realtime (default 20)")
    campaign.add_argument("--layout", default="paper", type=layout_arg,
                          help="layout name or TOML file (default paper)")
    campaign.add_argument("--strategy", choices=[s.value for s in Strategy], default="ann",
                          help="the dispatch strategy of every run (default ann: it needs "
                          "--weights or weights shipped for the layout)")
    campaign.add_argument("--weights", type=text_file, metavar="FILE",
                          help="MLP weights for the ANN strategy (default: shipped)")
    campaign.add_argument("--kind", choices=["fill", "empty", "both"], default="both",
                          help="the missions: fill and empty in turn (both, the default) "
                          "or one of them")
    campaign.add_argument("--out", type=writable_dir, metavar="DIR",
                          help="a new or empty directory for the failing runs' scenarios and "
                          "recordings and campaign.json (default: "
                          "runs/DATE-TIME-LAYOUT-campaign)")
    campaign.add_argument("--json", action="store_true", help="print one JSON object")
    campaign.set_defaults(handler=run_campaign)


def run_scale(args: argparse.Namespace) -> int:
    from bench import scale

    modes = scale.MODES if args.modes == "both" else (args.modes,)
    if not args.fleets:
        raise UserError("--fleets none leaves nothing to run: give fleet sizes, e.g. 12,32")
    if args.keep is not None:
        try:
            args.keep.mkdir(parents=True)
        except FileExistsError:
            raise UserError(f"--keep {args.keep}: already there; give a new directory, so "
                            f"no earlier run's recordings are mixed in or replaced") from None
    result = scale.run(args.fleets, modes, args.strategy, args.timeout * 60,
                       lambda line: print(line, file=sys.stderr, flush=True), args.keep,
                       args.lookahead)
    code = 0 if all(r.get("completed") and r["passed"] for r in result["rows"]) else 1
    if emitted_json(result, args.json):
        return code
    lookahead = "" if args.lookahead == LOOKAHEAD_S else \
        f", lookahead {lookahead_text(args.lookahead)}"
    print(f"fill missions, strategy {result['strategy']}{lookahead}, fast clock:")
    for row in result["rows"]:
        print(f"  {row['vehicles']:4d} forklifts {row['mode']:10s} {scale.describe(row)}")
    for mode, steps in result["growth"].items():
        for step in steps:
            print(f"  {mode}: {step['from']} -> {step['to']} forklifts (x{step['fleet_x']}): "
                  f"wall per decision x{step['wall_per_decision_x']} (exponent "
                  f"{step['exponent']}), peak memory x{step['peak_mb_x']}")
    return code


def fleet_sizes(text: str) -> list[int]:
    """--agents: ascending fleet sizes, or 'none'."""
    sizes = [] if text == "none" else positive_ints(text)
    if sizes != sorted(sizes):
        raise argparse.ArgumentTypeError(f"{text!r} must be in ascending order, e.g. 25,50,100")
    return sizes


def emitted_json(result: dict, as_json: bool) -> bool:
    """Stamp the machine on a result; print it as one JSON object if asked (True then)."""
    result["machine"] = f"{platform.machine()} {platform.python_implementation()} " \
                        f"{platform.python_version()}"
    if as_json:
        print(json.dumps(result))
    return as_json


def run_planner(args: argparse.Namespace) -> int:
    from bench import planner

    bar = ProgressBar(args.queries, "planner bench", unit="queries", enabled=not args.json)
    try:
        result = planner.run(args.layout, args.queries, args.seed,
                             lambda done, _: bar.update(done))
    finally:
        bar.close()
    if emitted_json(result, args.json):
        return 0
    print(f"planner on {result['layout']}: {result['queries']} queries (seed {result['seed']})")
    print(f"  per query  p50 {result['p50_ms']} ms   p95 {result['p95_ms']} ms   "
          f"max {result['max_ms']} ms   mean {result['mean_ms']} ms")
    print(f"  found only p50 {result['found_p50_ms']} ms   p95 {result['found_p95_ms']} ms;  "
          f"{result['over_100ms']} queries over 100 ms")
    print(f"  success    {result['success_rate']:.1%}   outcomes {result['outcomes']}")
    print(f"  expansions p50 {result['expansions_p50']}   p95 {result['expansions_p95']}   "
          f"max {result['expansions_max']} (machine-independent)")
    print(f"  setup per fill state (not in the query time) p50 {result['setup_p50_ms']} ms")
    return 0


def run_planner004(args: argparse.Namespace) -> int:
    from bench import planner004

    bar = ProgressBar(5 * args.queries, "seed 004 planner", unit="queries",
                      enabled=not args.json)
    try:
        result = planner004.run(args.queries, args.seed, lambda done, _: bar.update(done))
    finally:
        bar.close()
    if emitted_json(result, args.json):
        return 0
    r = result
    print(f"seed 004's A* on {r['layout']}: {r['queries']} queries (seed {r['seed']}), "
          f"{r['found']} found")
    print(f"  heap  {r['heap_total_s']} s in all, p50 {r['heap_p50_ms']} ms")
    print(f"  list  {r['list_total_s']} s in all, p50 {r['list_p50_ms']} ms")
    print(f"  the heap {r['heap_speedup']}x faster; the same path in {r['same_paths']} of "
          f"{r['queries']} queries")
    print(f"  turning cost on {r['turn_queries']} empty fetches: turns {r['turns_off']} -> "
          f"{r['turns_on']} ({r['turns_cut']:.1%} fewer), cells {r['length_off']} -> "
          f"{r['length_on']}, {r['lengthened']} routes longer")
    return 0


def run_strategies(args: argparse.Namespace) -> int:
    from bench import strategies
    from fleet.mission.spec import STACK_KINDS, MissionKind

    kinds = STACK_KINDS if args.mission == "both" else (MissionKind(args.mission),)
    bars: dict[str, ProgressBar] = {}

    def progress(label: str, done: int, total: int) -> None:
        if label not in bars:
            for bar in bars.values():
                bar.close()
            bars[label] = ProgressBar(total, label,
                                      unit="stacks" if "bound" in label else "jobs")
        bars[label].update(done)

    result = strategies.run(args.layout, kinds, args.weights, args.ann_seeds, progress)
    for bar in bars.values():
        bar.close()
    if not emitted_json(result, args.json):
        print(strategies.table(result))
    return 0


def run_seed002(args: argparse.Namespace) -> int:
    from bench import seed002

    bar = ProgressBar(1, "seed 002 experiments", unit="missions")

    def progress(done: int, total: int) -> None:
        bar.total = total
        bar.update(done)

    result = seed002.run(args.seeds, progress, args.jobs)
    bar.close()
    if not emitted_json(result, args.json):
        print(seed002.table(result))
    if args.plots is not None:
        from fleet.commands.plot import write_makespan
        from fleet.views.makespan import curves

        args.plots.mkdir(parents=True, exist_ok=True)
        for path in write_makespan(curves(result, "fleet bench seed002"), args.seeds,
                                   args.plots):
            print(f"wrote {path}", file=sys.stderr if args.json else sys.stdout)
    return 0 if result["lane_violations"] == 0 and result["double_bookings"] == 0 else 1


def run_seed004(args: argparse.Namespace) -> int:
    from bench import seed004
    from fleet.world.floor004 import paper004

    parking = len(paper004().parking)
    for n in (args.vehicles, *args.sizes):
        if n > parking:
            raise UserError(f"paper004 parks {parking} AGVs, not {n}")
    bar = ProgressBar(1, "seed 004 experiments", unit="missions")

    def progress(done: int, total: int) -> None:
        bar.total = total
        bar.update(done)

    result = seed004.run(args.seeds, args.orders, args.vehicles, tuple(args.sizes), progress,
                         args.jobs, tuple(args.heat_weights))
    bar.close()
    if not emitted_json(result, args.json):
        print(seed004.table(result))
    if args.plots is not None:
        from fleet.views.drawing import save_figure
        from fleet.views.heat004 import heat_maps

        args.plots.mkdir(parents=True, exist_ok=True)
        path = args.plots / "heat.png"
        save_figure(heat_maps(paper004(), seed004.heat_panels(0, args.orders, args.vehicles),
                              f"fleet bench seed004: {args.vehicles} AGVs, {args.orders} "
                              f"orders on paper004, the brighter the hotter"), str(path))
        print(f"wrote {path}", file=sys.stderr if args.json else sys.stdout)
    judged = ("stuck", "clashes", "bad_moves", "rule_breaches", "yield_breaches")
    return 0 if not any(result[k] for k in judged) else 1


def run_runtime(args: argparse.Namespace) -> int:
    from bench import runtime

    sizes = args.agents
    def say(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    result = runtime.run(args.commits, args.seed)
    say(f"commit round trip: p50 {result['commit_p50_ms']} ms, p99 {result['commit_p99_ms']} ms")
    if args.ratio_repeats > 0:
        from bench import multiprocess

        result |= multiprocess.run(args.ratio_layout, "ann", args.ratio_repeats, say)
    if sizes:
        from bench import fleet_scale

        result |= fleet_scale.run(sizes, args.window, progress=say)
    if emitted_json(result, args.json):
        return 0
    print(f"reservation commit round trip over zenoh on loopback, {result['commits']} commits")
    print(f"  p50 {result['commit_p50_ms']} ms   p99 {result['commit_p99_ms']} ms   "
          f"max {result['commit_max_ms']} ms   refused {result['refused']}")
    if "multiprocess_ratio" in result:
        print(f"fast-mode fill on {result['ratio_layout']}, median of "
              f"{result['ratio_repeats']}: processes {result['multiprocess_wall_s']} s, "
              f"in-process {result['inprocess_wall_s']} s, ratio "
              f"{result['multiprocess_ratio']} (same record: {result['same_record']})")
    if "fleets" in result:
        print(f"real time at speed 1 on the {result['layout']} layout:")
        for row in result["fleets"]:
            print(f"  {row['agents']:>4} agents: {row['received_share']:.1%} of states, "
                  f"lateness p99 {row['late_p99_ms']} ms, {row['rss_per_agent_mb']} MB per "
                  f"agent -> {'keeps' if row['keeps_real_time'] else 'misses'} real time")
        print(f"  largest fleet in real time: {result['max_realtime_agents']}")
    return 0


def run_vda5050(args: argparse.Namespace) -> int:
    from bench import vda5050

    r = vda5050.run(args.vehicles, lambda line: print(line, file=sys.stderr, flush=True))
    if emitted_json(r, args.json):
        return 0
    print(f"{r['vehicles']} forklifts as VDA 5050 AGVs ({r['layout']}), {r['orders']} orders "
          f"at once: order-to-motion latency p50 {r['latency_p50_s']} s, p99 "
          f"{r['latency_p99_s']} s ({r['moved']} moved), then warm: p50 "
          f"{r['warm_latency_p50_s']} s, p99 {r['warm_latency_p99_s']} s "
          f"({r['warm_moved']} moved); over {r['window_s']} s "
          f"{r['states_per_s']} states/s ({r['states_lost']} lost) and "
          f"{r['visualizations_per_s']} visualizations/s ({r['visualizations_lost']} lost)")
    return 0


def run_runtime004(args: argparse.Namespace) -> int:
    from bench import runtime004

    def say(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    result: dict = {}
    if args.repeats > 0:
        result["side_by_side"] = runtime004.side_by_side(args.orders, args.vehicles,
                                                         args.repeats, say)
    result["real_time"] = [runtime004.real_time(n, args.rt_orders, args.speed, say)
                           for n in (args.agents or [])]
    if emitted_json(result, args.json):
        return 0
    if "side_by_side" in result:
        r = result["side_by_side"]
        print(f"{r['orders']} orders, {r['vehicles']} AGVs on paper004, median of "
              f"{r['repeats']}: processes {r['processes_wall_s']} s, in process "
              f"{r['inprocess_wall_s']} s, ratio {r['ratio']} ({r['processes_ms_per_cell']} "
              f"ms a cell driven; same record: {r['same_record']})")
    for r in result["real_time"]:
        print(f"{r['vehicles']:>4} AGVs, {r['orders']} orders in real time at speed "
              f"{r['speed']:g}: lateness p50 {r['lateness_p50_s']} s, p99 "
              f"{r['lateness_p99_s']} s; {r['late_instants']} of {r['instants']} instants "
              f"over 0.3 s late (worst {r['worst_late_s']} s), {r['rss_per_agent_mb']} MB per "
              f"agent -> "
              f"{'keeps' if r['keeps_real_time'] else 'misses'} real time")
    return 0


def run_recorder(args: argparse.Namespace) -> int:
    from bench import recorder

    rates = args.rates

    def say(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    result = recorder.run(rates, args.seconds, args.publishers, args.repeats, args.layout, say)
    if not emitted_json(result, args.json):
        print(recorder.table(result))
    return 0


def run_faults(args: argparse.Namespace) -> int:
    from bench import faults
    from fleet.mission.faults import builtin_scenarios

    names = args.scenarios.split(",") if args.scenarios else None
    unknown = sorted(set(names or []) - set(builtin_scenarios()))
    if unknown:
        raise UserError(f"--scenarios: {unknown[0]!r} is not a shipped scenario "
                         f"({', '.join(builtin_scenarios())})")

    def say(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    from fleet.world.layout_file import load_layout

    layout = load_layout(args.layout)
    orders = layout.has_lanes or layout.floor is not None
    if not orders and args.layout != "paper":
        raise UserError(f"--layout {args.layout}: the fault bench runs paper's fill, or an "
                        f"order mission on a lane layout or a seed-004 floor")
    taken = faults.scenarios_for(args.layout)
    if names and set(names) - set(taken):
        raise UserError(f"--scenarios: {sorted(set(names) - set(taken))[0]!r} is not for "
                        f"{args.layout} (it takes {', '.join(taken)})")
    mission = faults.order_mission(args.layout, args.orders, args.vehicles) \
        if orders else faults.MISSION
    result = faults.run(names, say, ClockMode(args.clock), args.speed, mission)
    if not emitted_json(result, args.json):
        print(faults.table(result))
    return 0


def run_campaign(args: argparse.Namespace) -> int:
    from bench import campaign
    from fleet.mission.spec import STACK_KINDS, MissionKind
    from fleet.world.layout_file import load_layout

    layout = load_layout(args.layout)
    kinds = STACK_KINDS if args.kind == "both" else (MissionKind(args.kind),)
    spec = campaign.CampaignSpec(args.layout, args.runs, args.seed, ClockMode(args.clock),
                                 args.speed, kinds, Strategy(args.strategy), args.weights)
    out = campaign_dir(args.out, layout.name)
    runs = ProgressBar(args.runs, "campaign", unit="runs")  # on stderr: --json keeps stdout

    def progress(label: str, done: int, total: int) -> None:
        if label == "runs":
            runs.update(done)
        else:
            runs.update(runs.done, f"{label}, {done}/{total} stacks")

    def say(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    try:
        result = campaign.run(spec, out, progress, say)
    finally:
        runs.close()
    (out / "campaign.json").write_text(json.dumps(result, indent=1) + "\n")
    if not emitted_json(result, args.json):
        print(campaign.table(result))
    return 0 if result["completed"] == result["runs"] and result["verdict_failures"] == 0 \
        else 1


def campaign_dir(out: Path | None, layout: str) -> Path:
    """Where a campaign writes: `out` (new or empty), or a new directory under runs/ named
    for now and the layout (-2 after it if taken). Not a run directory itself: the failing
    runs' directories are inside it, so `fleet runs DIR` lists them."""
    if out is not None:
        if out.is_dir() and any(out.iterdir()):
            raise UserError(f"--out {out} is not empty: a campaign writes only in a new or "
                            f"empty directory (its failing runs' files are named by seed and "
                            f"run, and another campaign's would mix in)")
        out.mkdir(parents=True, exist_ok=True)
        return out
    name = default_name(layout, "campaign", time.localtime())
    for n in itertools.count(1):
        path = RUNS / (name if n == 1 else f"{name}-{n}")
        try:
            path.mkdir(parents=True)
            return path
        except FileExistsError:
            continue
    raise AssertionError("unreachable")
