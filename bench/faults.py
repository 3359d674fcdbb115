"""`fleet bench faults`: every shipped fault scenario on paper with four forklifts (or on a lane
layout such as paper002, or a seed-004 floor such as paper004, its own scenarios on an order
mission), as real processes on the fast or the real-time clock, beside the fault-free run on
the same clock: how fast each fault is detected and recovered from (wall clock), what it
costs the mission (sim time), whether the record is the fault-free run's, and what the
recording's verdicts say (docs/reliability.md). A seed-004 run's faults are struck by its
tracker at their instants, not detected: its rows have no detection times, and its
overlaps, moves outside and messages lost are its cells shared, bad moves and events no
segment holds.

Detection: from the injector applying the fault (its wall clock) to the dispatcher seeing it
(a liveliness token gone, a forklift's report). Recovery: from there to the engine asking the
clock again, with the freeze committed to the store and the forklifts told. Rejoin: from the
fault's end (restart, SIGCONT, link restored, repair) to the dispatcher seeing the forklift
back. Both processes read the same machine's clock.
"""

from __future__ import annotations

import statistics
import tempfile
from collections import Counter
from collections.abc import Callable
from pathlib import Path

from fleet.analysis.analyze import analyze
from fleet.analysis.analyze004 import analyze004
from fleet.dispatching.decision import Strategy
from fleet.mission.faults import DETECT_TIMEOUT_S, VEHICLE_KINDS, builtin_scenarios, load_scenario
from fleet.mission.faults004 import injected004, taken004
from fleet.mission.spec import ClockMode, Mission, MissionKind
from fleet.recording.reader import Recording, read_recording
from fleet.runtime.local_run import RunOutcome, RunSpec, run_processes
from fleet.wire.protocol import Halt, MissionDone, Resume
from fleet.world.layout_file import load_layout

MISSION = Mission("paper", MissionKind.FILL, Strategy.ANN, 4, 0)
ORDERS, AGVS = 40, 6  # a lane layout's order mission: long enough for every fault


def order_mission(layout: str, orders: int = ORDERS, vehicles: int = AGVS) -> Mission:
    return Mission(layout, MissionKind.ORDERS, Strategy.NEAREST, vehicles, 0, orders=orders)


def run(names: list[str] | None = None, say: Callable[[str], None] = print,
        clock: ClockMode = ClockMode.FAST, speed: float = 1.0,
        mission: Mission = MISSION) -> dict:
    """One row per scenario (a kind's own scenario is named after the kind; the layout's own
    version where it ships one; on a seed-004 floor those it takes), and the fault-free
    run's as "fault_free"."""
    names = names or scenarios_for(mission.layout)
    with tempfile.TemporaryDirectory() as tmp:
        say(f"fault-free run ({clock} clock) ...")
        base = _run(Path(tmp) / "none", None, clock, speed, mission)
        base_end = base["end_time_s"]
        base["extra_s"] = 0.0
        rows = {"fault_free": base}
        for name in names:
            say(f"{name} ...")
            row = _run(Path(tmp) / name, name, clock, speed, mission)
            row["extra_s"] = round(row["end_time_s"] - base_end, 2) \
                if row["end_time_s"] is not None else None
            row["same_record"] = bool(row["digest"]) and row["digest"] == base["digest"]
            rows[name] = row
            say(f"  {_line(name, row)}")
    return rows


def scenarios_for(layout: str) -> list[str]:
    """The shipped scenarios a run on the layout takes (a seed-004 floor: not every kind)."""
    if load_layout(layout).floor is None:
        return builtin_scenarios()
    return [name for name in builtin_scenarios()
            if all(taken004(f) for f in load_scenario(name, layout).faults)]


def _run(out: Path, name: str | None, clock: ClockMode, speed: float,
         mission: Mission) -> dict:
    scenario = load_scenario(name, mission.layout) if name else None
    assert mission.vehicles is not None
    if load_layout(mission.layout).floor is not None:
        return _run004(out, name, clock, speed, mission)
    outcome = run_processes(RunSpec(mission, mission.vehicles, out, clock, speed,
                                    faults=scenario, faults_source=name or ""))
    recording = read_recording(out)
    report = analyze(recording)
    detect, recover, rejoin = timings(outcome, recording)
    lost, twice = len(report.stacks_lost), len(report.stacks_duplicated)
    if mission.kind is MissionKind.ORDERS:  # the work verdict counts stacks: the record
        lost, twice = _orders(recording, mission.orders)
    return _outcome(outcome, report.end_time_s) | {
        "faults": sum(not a.ends for a in outcome.injected if _timed(a.fault)),
        "detected": len(detect),
        "detect_s": _median(detect), "detect_max_s": max(detect, default=None),
        "recover_s": _median(recover), "rejoin_s": _median(rejoin),
        "overlaps": len(report.overlaps),
        "outside_reservation": len(report.outside_reservation),
        "stacks_lost": lost,  # an order mission: orders
        "stacks_duplicated": twice,
        "messages_lost": report.messages_lost,
        "messages_not_recorded": report.messages_not_recorded,
        "verdicts_pass": report.passed,
    }


def _outcome(outcome: RunOutcome, end_time_s: float | None) -> dict:
    """What every row says of the run itself."""
    return {
        "completed": outcome.done is not None and outcome.done.ok,
        "error": outcome.error,
        "end_time_s": end_time_s,
        "wall_s": round(outcome.done.wall_s, 1) if outcome.done else None,
        "injected": len(outcome.injected),  # the injector's actions (kills, restarts, ...)
        "digest": outcome.done.digest if outcome.done else "",
    }


def _run004(out: Path, name: str | None, clock: ClockMode, speed: float,
            mission: Mission) -> dict:
    """A seed-004 order mission with the scenario, its row in the same columns."""
    scenario = load_scenario(name, mission.layout) if name else None
    assert mission.vehicles is not None
    outcome = run_processes(RunSpec(
        mission, mission.vehicles, out, clock, speed,
        faults=injected004(scenario) if scenario is not None else None,
        faults_source=name or "", clocked_agents=False))
    report = analyze004(read_recording(out))
    v = report.verdict
    return _outcome(outcome, report.end_time_s) | {
        "faults": 0, "detected": 0,  # struck by the tracker itself, at their instants
        "detect_s": None, "detect_max_s": None, "recover_s": None, "rejoin_s": None,
        "overlaps": len(v.clashes),
        "outside_reservation": len(v.bad_moves),
        "stacks_lost": report.orders_expected - report.orders_picked,  # orders
        "stacks_duplicated": 0,
        "messages_lost": sum(b - a + 1 for a, b in report.events_missing),
        "messages_not_recorded": 0,
        "verdicts_pass": report.passed,
    }


def _orders(recording: Recording, total: int) -> tuple[int, int]:
    """An order mission's orders not done and done twice, as its final record has them."""
    records = [m.record for _, m in recording.of(MissionDone) if m.ok]
    if not records:
        return total, 0
    done = Counter(index for _, index, _ in records[-1]["stacks_done"])
    return total - len(done), sum(n > 1 for n in done.values())


def timings(outcome: RunOutcome, recording: Recording
             ) -> tuple[list[float], list[float], list[float]]:
    """Pair the injector's actions with the dispatcher's detections (same forklift, same
    sim instant on the fast clock, the next one on the real-time clock). A dispatcher that
    was restarted took its detections with it: those come from the recording instead, as
    the instant the recorder heard the halt or the resume (detection plus recovery, a few
    milliseconds more)."""
    seen = list(outcome.done.detections if outcome.done else [])
    for kind, up in ((Halt, False), (Resume, True)):
        for r, m in recording.of(kind):
            if kind is Halt and m.moving:
                continue  # halted because of another forklift's fault
            if not any(d["vehicle"] == m.vehicle and d["t"] == m.t and d["up"] == up
                       for d in seen):
                seen.append({"vehicle": m.vehicle, "t": m.t, "up": up,
                             "detected_wall": r.log_ns / 1e9})
    detect, recover, rejoin = [], [], []
    used: set[int] = set()
    for applied in outcome.injected:
        fault = applied.fault
        if not _timed(fault):
            continue
        # The first sighting of this forklift going (or coming back) after the action: on
        # the fast clock at the fault's own instant, on the real-time one when noticed.
        t = fault.until if applied.ends else fault.at
        match = [i for i, d in enumerate(seen) if i not in used and
                 d["vehicle"] == fault.vehicle and d["up"] == applied.ends and
                 (d["t"] == t or 0 <= d["detected_wall"] - applied.wall <= DETECT_TIMEOUT_S)]
        if not match:
            continue  # not seen: a stall or a cut link shorter than the lease, in real time
        i = min(match, key=lambda i: (seen[i]["t"] != t, seen[i]["detected_wall"]))
        used.add(i)
        found = seen[i]
        latency = max(0.0, found["detected_wall"] - applied.wall)
        (rejoin if applied.ends else detect).append(round(latency, 3))
        if not applied.ends and "recovered_wall" in found:
            recover.append(round(found["recovered_wall"] - found["detected_wall"], 3))
    return detect, recover, rejoin


def _timed(fault) -> bool:
    """A fault the dispatcher detects: a forklift's (a slow planner is not noticed)."""
    return fault.kind in VEHICLE_KINDS and fault.kind.value != "slow_planner"


def _median(values: list[float]) -> float | None:
    return round(statistics.median(values), 3) if values else None


def _fmt(value, unit: str = "") -> str:
    return "-" if value is None else f"{value:g}{unit}"


def _seen(row: dict) -> str:
    """Forklift faults the dispatcher saw, of those applied."""
    return f"{row['detected']}/{row['faults']}" if row.get("faults") else "-"


def _line(name: str, row: dict) -> str:
    return (f"{name:<18} seen {_seen(row):>4}  detect {_fmt(row['detect_s'], ' s'):>8}  recover "
            f"{_fmt(row['recover_s'], ' s'):>8}  rejoin {_fmt(row['rejoin_s'], ' s'):>8}  "
            f"extra {_fmt(row['extra_s'], ' s'):>9}  overlaps {row['overlaps']}  outside "
            f"{row['outside_reservation']}  lost {row['stacks_lost']} twice "
            f"{row['stacks_duplicated']}  messages lost {row['messages_lost']} (not recorded "
            f"{row['messages_not_recorded']})  record {_record(row)}  "
            f"{'pass' if row['verdicts_pass'] else 'FAIL'}")


def _record(row: dict) -> str:
    """Whether the run's record is the fault-free run's."""
    return "-" if "same_record" not in row else "same" if row["same_record"] else "other"


def table(result: dict) -> str:
    """The markdown table of docs/reliability.md."""
    lines = ["| scenario | seen | detect | recover | rejoin | extra mission time | overlaps | "
             "outside reservation | stacks (orders) lost / twice | messages lost (not recorded) | "
             "record | verdicts |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, row in result.items():
        if not isinstance(row, dict):
            continue  # the machine's stamp
        lines.append(
            f"| {name} | {_seen(row)} | {_fmt(row['detect_s'], ' s')} | "
            f"{_fmt(row['recover_s'], ' s')} | "
            f"{_fmt(row['rejoin_s'], ' s')} | {_fmt(row['extra_s'], ' s')} | "
            f"{row['overlaps']} | {row['outside_reservation']} | {row['stacks_lost']} / "
            f"{row['stacks_duplicated']} | {row['messages_lost']} "
            f"({row['messages_not_recorded']}) | {_record(row)} | "
            f"{'pass' if row['verdicts_pass'] else 'FAIL'} |")
    return "\n".join(lines)
