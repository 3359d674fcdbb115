"""`fleet bench campaign`: seeded random fault scenarios, each run judged by the analysis
`fleet analyze` uses (docs/reliability.md).

Run i draws its faults from a numpy Generator seeded by (seed, i): how many, their kinds,
instants, forklifts, durations and zones. Runs alternate fill and empty (or keep to one kind).
Each is measured against the same mission without faults (run once per mission kind and
reused): its extra mission time. A run that fails (not completed, or a verdict failing)
leaves its scenario as a TOML file that `fleet run --faults FILE` replays: bit for bit on the
fast clock, which runs in process (the reference; a run of processes gives the same record),
while `--clock realtime` runs processes.
"""

from __future__ import annotations

import dataclasses
import math
import shutil
import statistics
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bench.faults import timings
from fleet.analysis.analyze import analyze
from fleet.analysis.report import Report
from fleet.dispatching.decision import Strategy
from fleet.errors import UserError
from fleet.mission.engine import engine_options
from fleet.mission.faults import (
    SERVICES,
    Fault,
    FaultKind,
    Scenario,
    check_against,
    scenario_toml,
)
from fleet.mission.spec import ClockMode, Mission, MissionKind
from fleet.mission.standstill import Cause
from fleet.recording.inprocess import recorded_run, write_recording
from fleet.recording.mission_record import recorded_standstill
from fleet.recording.reader import Recording, read_recording
from fleet.recording.rundir import claim
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.wire.protocol import DeadlockSeen
from fleet.world.layout import Layout
from fleet.world.layout_file import load_layout

MAX_FAULTS = 4  # faults drawn per run: 2 to this many
FIRST_AT_S = 5.0  # no fault before: the fleet has left its starts
HORIZON = 0.8  # faults start within this share of the fault-free mission's end time
DURATION_S = (5.0, 90.0)  # a forklift's fault lasts this long (uniform), then it is back
ZONE_DURATION_S = (10.0, 90.0)
ZONE_SIZE = (3, 2)  # a spill covers up to this many columns and rows of floor
FACTOR = (2.0, 10.0)  # a slow planner's factor
# Sim seconds between a dispatcher's kill and the start of any forklift's fault: a forklift
# is frozen about a second of wall time after its fault starts (detection and the margin),
# and a successor asks the forklifts as it starts; real-time sim time runs on meanwhile.
DISPATCHER_MARGIN_S = 60.0
# What each clock can show: in process a slow planner or a killed service changes no sim time
# (the fast clock stands still while a service restarts), so the fast clock draws the kinds
# that move the schedule; processes in real time take every kind.
MOVING_KINDS = (FaultKind.KILL_VEHICLE, FaultKind.STALL_VEHICLE, FaultKind.CUT_LINK,
                FaultKind.VEHICLE_BREAKDOWN, FaultKind.CLOSE_ZONE)
ALL_KINDS = (*MOVING_KINDS, FaultKind.SLOW_PLANNER, FaultKind.KILL_SERVICE)


@dataclass(frozen=True)
class CampaignSpec:
    layout: str
    runs: int
    seed: int
    clock: ClockMode = ClockMode.FAST
    speed: float = 20.0  # sim seconds per wall second, real time only
    kinds: tuple[MissionKind, ...] = (MissionKind.FILL, MissionKind.EMPTY)  # taken in turn
    strategy: Strategy = Strategy.ANN
    weights: Path | None = None  # the ANN strategy's MLP (None: the layout's shipped weights)


@dataclass(frozen=True)
class Outcome:
    """One mission as run: its recording's analysis (None: nothing to analyse), whether it
    finished, wedged (MissionStuck) or failed otherwise, and why."""

    completed: bool
    wedged: bool
    error: str
    digest: str
    report: Report | None
    recording: Recording | None
    detect_s: list[float]  # processes only: from each fault to the dispatcher seeing it


# -- drawing a run's faults ----------------------------------------------------------------------
def draw_scenario(seed: int, index: int, layout: Layout, vehicles: int, kind: MissionKind,
                  horizon_s: float, clock: ClockMode) -> Scenario:
    """Run `index`'s faults, from a Generator seeded by (seed, index) alone: the same run
    draws the same faults whatever else the campaign holds."""
    rng = np.random.default_rng([seed, index])
    kinds = MOVING_KINDS if clock is ClockMode.FAST else ALL_KINDS
    floor = _floor_cells(layout)
    faults: list[Fault] = []
    for _ in range(int(rng.integers(2, MAX_FAULTS + 1))):
        for _attempt in range(8):  # one fault at a time per forklift and per service
            fault = _draw_fault(rng, kinds[int(rng.integers(len(kinds)))], vehicles,
                                max(horizon_s * HORIZON, FIRST_AT_S + 1.0), floor)
            if not any(_overlap(fault, f) for f in faults):
                faults.append(fault)
                break
    faults.sort(key=lambda f: f.at)
    scenario = Scenario(f"campaign-{seed}-{index}",
                        f"fleet bench campaign --seed {seed}: run {index}, {kind.value} on "
                        f"{layout.name}", tuple(faults))
    check_against(scenario, layout, vehicles)
    return scenario


def _draw_fault(rng: np.random.Generator, kind: FaultKind, vehicles: int, until_s: float,
                floor: list[tuple[int, int]]) -> Fault:
    at = round(float(rng.uniform(FIRST_AT_S, until_s)), 1)
    if kind is FaultKind.CLOSE_ZONE:
        return Fault(kind, at, duration=_seconds(rng, ZONE_DURATION_S),
                     cells=_zone(rng, floor))
    if kind is FaultKind.KILL_SERVICE:
        return Fault(kind, at, service=SERVICES[int(rng.integers(len(SERVICES)))],
                     downtime=round(float(rng.uniform(0.5, 2.0)), 1))
    vehicle = int(rng.integers(1, vehicles + 1))
    factor = round(float(rng.uniform(*FACTOR)), 1) if kind is FaultKind.SLOW_PLANNER else 1.0
    return Fault(kind, at, vehicle, _seconds(rng, DURATION_S), factor)


def _seconds(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    return round(float(rng.uniform(*bounds)), 1)


def _floor_cells(layout: Layout) -> list[tuple[int, int]]:
    """Where a spill may happen: cells forklifts drive on (no stack, station or obstacle)."""
    taken = layout.static_blocked | {s.cell for s in layout.stacks}
    return [(c, r) for r in range(layout.rows) for c in range(layout.cols)
            if (c, r) not in taken]


def _zone(rng: np.random.Generator, floor: list[tuple[int, int]]) -> tuple[tuple[int, int], ...]:
    c0, r0 = floor[int(rng.integers(len(floor)))]
    cols, rows = int(rng.integers(1, ZONE_SIZE[0] + 1)), int(rng.integers(1, ZONE_SIZE[1] + 1))
    free = set(floor)
    return tuple(sorted((c, r) for c in range(c0, c0 + cols) for r in range(r0, r0 + rows)
                        if (c, r) in free))


def _overlap(a: Fault, b: Fault) -> bool:
    """Two faults of one forklift or one service at once (a scenario refuses them), or a
    dispatcher killed near the start of a forklift's fault. A dispatcher may die while
    forklifts are down (its successor finds them in its journal), but not while it freezes
    one (between telling the store and the forklifts), nor as its successor asks each
    forklift that is up what it holds (docs/faults.md)."""
    same = (a.vehicle is not None and a.vehicle == b.vehicle) or \
        (a.service is not None and a.service == b.service)
    if same:
        return a.at <= b.over and b.at <= a.over
    kill, other = (a, b) if a.service == "dispatcher" else (b, a)
    return kill.service == "dispatcher" and other.vehicle is not None and \
        abs(kill.at - other.at) <= DISPATCHER_MARGIN_S


# -- running one mission ---------------------------------------------------------------------------
def run_inprocess(mission: Mission, layout: Layout, scenario: Scenario | None, folder: Path,
                  weights: Path | None, progress: Callable[[int, float], None]) -> Outcome:
    """The fast-clock reference in this process, its recording (up to where it stopped, if
    it did not finish) written to `folder`."""
    options = engine_options(mission, layout, weights,
                             lambda done, total, t, failures: progress(done, t))
    try:
        done, stream = recorded_run(mission, layout, options, "fleet bench campaign", scenario)
    except Exception as exc:  # a crash is a finding: its scenario is kept to replay it
        return Outcome(False, False, f"{type(exc).__name__}: {exc}", "", None, None, [])
    write_recording(folder / "run.mcap", stream, layout)
    return judged(done.ok, done.error, done.digest, read_recording(folder / "run.mcap"), [])


def run_with_processes(mission: Mission, vehicles: int, scenario: Scenario | None,
                       folder: Path, clock: ClockMode, speed: float, weights: Path | None,
                       progress: Callable[[int, float], None]) -> Outcome:
    """The mission as processes (what `fleet run` starts) in `folder`, the scenario read from
    a file there as `fleet run --faults FILE` reads it."""
    source = ""
    if scenario is not None:
        source = str(folder.parent / f"{folder.name}.toml")
        Path(source).write_text(scenario_toml(scenario))
    outcome = run_processes(RunSpec(mission, vehicles, folder, clock, speed, weights,
                                    faults=scenario, faults_source=source),
                            lambda p: progress(p.done, p.t))
    ok = outcome.done is not None and outcome.done.ok
    digest = outcome.done.digest if ok and outcome.done is not None else ""
    recording = read_recording(folder) if (folder / "run.mcap").exists() else None
    detect = timings(outcome, recording)[0] if recording is not None else []
    return judged(ok, outcome.error, digest, recording, detect)


def judged(ok: bool, error: str, digest: str, recording: Recording | None,
           detect_s: list[float]) -> Outcome:
    """A run's outcome as its recording tells it: a mission that did not finish is wedged
    when its dispatcher said it was stuck (MissionStuck), else it failed."""
    if recording is None:
        return Outcome(ok, False, error, digest, None, None, detect_s)
    standstill = None if ok else recorded_standstill(recording)
    wedged = standstill is not None and standstill.cause is Cause.STUCK
    return Outcome(ok, wedged, error, digest, analyze(recording), recording, detect_s)


# -- the campaign ----------------------------------------------------------------------------------
def run(spec: CampaignSpec, out: Path, progress: Callable[[str, int, int], None],
        say: Callable[[str], None] = print) -> dict[str, Any]:
    """Every run of the campaign; the failing runs' scenarios written to `out` as TOML.
    `progress(label, done, total)`: runs done, then stacks done within the run."""
    layout = load_layout(spec.layout)
    vehicles = len(layout.vehicle_starts)
    base: dict[MissionKind, Outcome] = {}
    per_run: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="fleet-campaign-") as tmp:
        work = Path(tmp)

        def mission_run(name: str, kind: MissionKind, scenario: Scenario | None) -> Outcome:
            mission = Mission(spec.layout, kind, spec.strategy)  # as fleet run has it
            folder = claim(work / name).path  # a run directory: its recording carries its id
            total = len(layout.stacks)

            def stacks(done: int, t: float) -> None:
                progress(f"{name}: {kind.value}, t={t:.0f} s", done, total)

            if spec.clock is ClockMode.FAST:
                return run_inprocess(mission, layout, scenario, folder, spec.weights, stacks)
            return run_with_processes(mission, vehicles, scenario, folder, spec.clock,
                                      spec.speed, spec.weights, stacks)

        for kind in dict.fromkeys(spec.kinds):
            say(f"fault-free {kind.value} on {layout.name} ({spec.clock} clock) ...")
            base[kind] = mission_run(f"fault-free-{kind.value}", kind, None)
            if not base[kind].completed:
                raise UserError(f"the fault-free {kind.value} mission on {layout.name} did "
                                f"not complete ({base[kind].error}): nothing to measure "
                                f"faults against")
        for i in range(spec.runs):
            kind = spec.kinds[i % len(spec.kinds)]
            horizon = _end(base[kind].report)
            scenario = draw_scenario(spec.seed, i, layout, vehicles, kind, horizon, spec.clock)
            t0 = time.perf_counter()
            outcome = mission_run(f"run-{i}", kind, scenario)
            row = run_row(i, kind, scenario, outcome, _end(base[kind].report),
                          time.perf_counter() - t0)
            if row["failed"]:  # its scenario to replay, and what was recorded to look at
                row["replay"] = str(write_replay(out, spec, kind, scenario, row))
                row["run_dir"] = str(shutil.move(work / f"run-{i}", out / scenario.name))
            per_run.append(row)
            progress("runs", i + 1, spec.runs)
            say(line(row))
    return summary(spec, layout, base, per_run, out)


def _end(report: Report | None) -> float:
    return report.end_time_s if report is not None and report.end_time_s is not None \
        else math.nan


def run_row(index: int, kind: MissionKind, scenario: Scenario, outcome: Outcome,
            base_end_s: float, wall_s: float) -> dict[str, Any]:
    report = outcome.report
    verdicts = None if report is None else {
        "safety": report.safe, "work": report.work_done,
        "messages": report.messages_whole, "passed": report.passed}
    end = report.end_time_s if report is not None and outcome.completed else None
    return {
        "index": index,
        "kind": kind.value,
        "scenario": scenario.name,
        "faults": [f.describe() for f in scenario.faults],
        "completed": outcome.completed,
        "wedged": outcome.wedged,
        "error": outcome.error,
        "verdicts": verdicts,
        "failed": not outcome.completed or not (verdicts or {}).get("passed", False),
        "end_time_s": end,
        "extra_s": round(end - base_end_s, 2) if end is not None else None,
        "deadlocks": deadlocks(outcome.recording),
        "detect_s": outcome.detect_s,
        "digest": outcome.digest,
        "wall_s": round(wall_s, 2),
        "replay": None,
        "run_dir": None,
    }


def deadlocks(recording: Recording | None) -> list[dict[str, Any]]:
    """The deadlocks the dispatcher saw and how each was broken (who was sent aside, to
    which siding, for whom), as its recording says (`dispatch/deadlock`)."""
    if recording is None:
        return []
    return [dataclasses.asdict(m) for _, m in recording.of(DeadlockSeen)]


def write_replay(out: Path, spec: CampaignSpec, kind: MissionKind, scenario: Scenario,
                 row: dict[str, Any]) -> Path:
    """The failing run's scenario, with how to replay it in its header."""
    path = out / f"{scenario.name}.toml"
    strategy = f" --weights {spec.weights}" if spec.weights else ""
    if spec.strategy is not Strategy.ANN:
        strategy = f" --strategy {spec.strategy.value}"
    clock = " --inprocess" if spec.clock is ClockMode.FAST else \
        f" --clock realtime --speed {spec.speed:g}"
    outcome = "wedged" if row["wedged"] else row["error"] or \
        ("completed, verdicts failing" if row["completed"] else "failed")
    header = (f"{scenario.description}: {outcome}\n"
              f"replay: fleet run{clock} --layout {spec.layout} --mission {kind.value}"
              f"{strategy} --faults {path}")
    path.write_text(scenario_toml(scenario, header))
    return path


def summary(spec: CampaignSpec, layout: Layout, base: dict[MissionKind, Outcome],
            per_run: list[dict[str, Any]], out: Path) -> dict[str, Any]:
    extra = sorted(r["extra_s"] for r in per_run if r["extra_s"] is not None)
    return {
        "layout": layout.name,
        "vehicles": len(layout.vehicle_starts),
        "strategy": spec.strategy.value,
        "seed": spec.seed,
        "clock": spec.clock.value,
        "speed": spec.speed if spec.clock is ClockMode.REALTIME else None,
        "kinds": [k.value for k in spec.kinds],
        "runs": len(per_run),
        "completed": sum(r["completed"] for r in per_run),
        "wedged": sum(r["wedged"] for r in per_run),
        "crashed": sum(not r["completed"] and not r["wedged"] for r in per_run),
        "verdict_failures": sum(r["verdicts"] is not None and not r["verdicts"]["passed"]
                                for r in per_run),
        "fault_free_end_s": {k.value: _end(o.report) for k, o in base.items()},
        "extra_s": _distribution(extra),
        "out": str(out),
        "per_run": per_run,
    }


def _distribution(values: list[float]) -> dict[str, float | None]:
    if not values:
        return {"min": None, "p50": None, "p90": None, "max": None, "mean": None}
    return {"min": values[0], "p50": round(statistics.median(values), 2),
            "p90": round(float(np.percentile(values, 90)), 2), "max": values[-1],
            "mean": round(statistics.fmean(values), 2)}


def line(row: dict[str, Any]) -> str:
    """One run, as the campaign says it on the way."""
    state = "completed" if row["completed"] else "WEDGED" if row["wedged"] else "FAILED"
    verdict = "-" if row["verdicts"] is None else \
        "pass" if row["verdicts"]["passed"] else "FAIL"
    extra = "-" if row["extra_s"] is None else f"{row['extra_s']:+.1f} s"
    return (f"run {row['index']:>3} {row['kind']:<5} {len(row['faults'])} faults  {state:<9} "
            f"verdicts {verdict:<4}  extra {extra:>9}  deadlocks {len(row['deadlocks'])}"
            + (f"  replay {row['replay']}" if row["replay"] else ""))


def table(result: dict[str, Any]) -> str:
    """What `fleet bench campaign` prints without --json."""
    e = result["extra_s"]
    extra = "-" if e["p50"] is None else \
        f"min {e['min']:g} s, median {e['p50']:g} s, p90 {e['p90']:g} s, max {e['max']:g} s"
    lines = [f"campaign on {result['layout']} ({result['vehicles']} forklifts, "
             f"{result['strategy']}, seed {result['seed']}, {result['clock']} clock): "
             f"{result['runs']} runs of {'/'.join(result['kinds'])}",
             f"  completed {result['completed']}, wedged {result['wedged']}, crashed "
             f"{result['crashed']}, verdicts failing {result['verdict_failures']}",
             f"  extra mission time over the fault-free run: {extra}",
             f"  deadlocks seen {sum(len(r['deadlocks']) for r in result['per_run'])}"]
    failing = [r for r in result["per_run"] if r["replay"]]
    if failing:
        lines.append(f"  failing runs' scenarios ({len(failing)}), each replays with "
                     f"fleet run --faults FILE:")
        lines += [f"    {r['replay']}" for r in failing]
    return "\n".join(lines)
