"""Whole fill missions at scale (`fleet bench scale`): for each fleet size, a generated
warehouse with room to park half as many again as the fleet and about ten stacks a forklift
(lanes at least two deep), filled on the fast
clock in process and as processes (`fleet run`, each run a fresh process), every run judged
by its recording's verdicts. Reported per run: completed, verdicts, stacks, end time, wall
time, wall time per decision, decision failures and peak memory (in all, and per agent as
processes); per mode, how the wall time per decision grows with the fleet. A run that did not
complete reports how far it got, and its directory (recording, logs) is kept and named; with
`keep`, every run's is."""

from __future__ import annotations

import itertools
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from fleet.params import LOOKAHEAD_S
from fleet.runtime.argtypes import lookahead_text
from fleet.world.generator import MIN_DEPTH, Shape, generate_toml

STACKS_PER_FORKLIFT = 10
PARKING_PER_FORKLIFT = 1.5  # with a slot each and no more, crowded aisles fail most decisions
MIN_LANE_DEPTH = 2  # a lane one stack deep can leave its unload pose a dead end (a wedge)
MAX_LANE_DEPTH = 5
POLL_S = 0.5  # how often a run of processes has its processes' peak memory read
MODES = ("inprocess", "processes")


def floor_for(vehicles: int) -> Shape:
    """The smallest generated floor (fewest aisles, then lanes) with PARKING_PER_FORKLIFT
    parking slots a forklift, its lanes as deep as needed for STACKS_PER_FORKLIFT stacks a
    forklift (MIN_LANE_DEPTH to MAX_LANE_DEPTH): about square, since the lanes per side
    grow with the aisles. A lane one stack deep is left out on purpose: its unload pose, in
    an aisle two cells wide, has no way out once the lane across the aisle is filled, and a
    fill that still has that stack to fill wedges."""
    aisles = 1
    while True:
        for depth in range(MIN_DEPTH, 4 * aisles + MIN_DEPTH + 1):
            shape = Shape(aisles, depth, 1, vehicles)
            if shape.slots_per_aisle * aisles >= PARKING_PER_FORKLIFT * vehicles:
                lanes = 4 * aisles * depth  # 2 sides x above and below each aisle
                deep = math.ceil(STACKS_PER_FORKLIFT * vehicles / lanes)
                return Shape(aisles, depth, max(MIN_LANE_DEPTH, min(MAX_LANE_DEPTH, deep)),
                             vehicles)
        aisles += 1


@dataclass
class Watched:
    """A run of `fleet run`: its exit, output and peak resident memory (kB) per process."""

    code: int
    stdout: str
    stderr: str
    wall_s: float
    peaks_kb: dict[int, tuple[str, int]]  # pid -> (command line, peak)
    timed_out: bool


def _descendants(pid: int) -> list[int]:
    found, todo = [], [pid]
    while todo:
        p = todo.pop()
        try:
            children = Path(f"/proc/{p}/task/{p}/children").read_text().split()
        except OSError:
            continue
        found += [int(c) for c in children]
        todo += [int(c) for c in children]
    return found


def _peak_kb(pid: int) -> tuple[str, int] | None:
    """The process's command line and its peak resident set (VmHWM), None once gone."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return None
    for line in status.splitlines():
        if line.startswith("VmHWM:"):
            return cmdline, int(line.split()[1])
    return None


def watch(args: list[str], timeout_s: float) -> Watched:
    """Run `python -m fleet ARGS` and read every process of its tree's peak memory until it
    ends (a process's peak is the last one read before it exits: read every POLL_S)."""
    peaks: dict[int, tuple[str, int]] = {}
    start = time.perf_counter()
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen([sys.executable, "-m", "fleet", *args], stdout=out,
                                stderr=err, text=True)
        timed_out = False
        while True:
            for pid in (proc.pid, *_descendants(proc.pid)):
                seen = _peak_kb(pid)
                if seen is not None and seen[1] >= peaks.get(pid, ("", 0))[1]:
                    peaks[pid] = seen
            try:
                proc.wait(POLL_S)
                break
            except subprocess.TimeoutExpired:
                if time.perf_counter() - start > timeout_s:
                    timed_out = True
                    proc.terminate()  # fleet run stops its children and records the stop
                    proc.wait()
                    break
        wall = time.perf_counter() - start
        out.seek(0)
        err.seek(0)
        return Watched(proc.returncode, out.read(), err.read(), wall, peaks, timed_out)


def run_one(layout: Path, vehicles: int, mode: str, strategy: str, timeout_s: float,
            keep: Path | None = None, lookahead: float = LOOKAHEAD_S) -> dict:
    """One fill mission; its row of the report. Its directory (`fleet run --out`) is `keep`,
    kept; without, a temporary one, kept and named in the row (`recording`) only when the run
    did not complete, so a mission given up can still be looked at."""
    out_dir = keep or Path(tempfile.mkdtemp(prefix=f"fleet-bench-scale-{vehicles}-{mode}-"))
    args = ["run", "--layout", str(layout), "--vehicles", str(vehicles), "--mission",
            "fill", "--strategy", strategy, "--json", "--out", str(out_dir),
            *(["--inprocess"] if mode == "inprocess" else []),
            *(["--lookahead", lookahead_text(lookahead)] if lookahead != LOOKAHEAD_S else [])]
    seen = watch(args, timeout_s)
    row = _row(vehicles, mode, seen)
    if keep is None and row["completed"]:
        shutil.rmtree(out_dir, ignore_errors=True)
    else:
        row["recording"] = str(out_dir)
    return row


def _row(vehicles: int, mode: str, seen: Watched) -> dict:
    row: dict = {"vehicles": vehicles, "mode": mode, "wall_s": round(seen.wall_s, 1),
                 "timed_out": seen.timed_out}
    try:
        summary = json.loads(seen.stdout)
    except ValueError:  # stopped before anything was recorded: what fleet run said instead
        said = [line for line in seen.stderr.strip().splitlines()
                if "logs and what was recorded" not in line]
        return row | {"completed": False, "passed": False,
                      "error": (said[-1:] or ["(nothing said)"])[0]}
    decisions = summary["subtasks"] + summary["decision_failures"]
    agents = [kb for cmd, kb in seen.peaks_kb.values() if " agent " in f"{cmd} "]
    return row | {
        "completed": summary["finished"] and not summary["incomplete"],
        "passed": summary["verdicts"]["passed"],
        "stacks_done": summary["stacks_done"], "stacks": summary["stacks_expected"],
        "end_time_s": summary["end_time_s"],
        "decisions": decisions, "decision_failures": summary["decision_failures"],
        "wall_per_decision_ms": round(1000 * seen.wall_s / max(1, decisions), 1),
        "peak_mb": round(sum(kb for _, kb in seen.peaks_kb.values()) / 1024, 1),
        "peak_agent_mb": round(max(agents) / 1024, 1) if agents else None,
        "digest": summary.get("digest", ""),
        "error": summary.get("error", ""),
    }


def growth(rows: list[dict]) -> dict[str, list[dict]]:
    """Per mode, from each fleet size to the next: how many times the fleet, the wall time
    per decision and the peak memory grew, and the exponent of the first in the second
    (1: linear in the fleet)."""
    out: dict[str, list[dict]] = {}
    for mode in MODES:
        done = sorted((r for r in rows if r["mode"] == mode and r.get("completed")),
                      key=lambda r: r["vehicles"])
        steps = []
        for a, b in itertools.pairwise(done):
            fleet = b["vehicles"] / a["vehicles"]
            per_decision = b["wall_per_decision_ms"] / a["wall_per_decision_ms"]
            steps.append({"from": a["vehicles"], "to": b["vehicles"],
                          "fleet_x": round(fleet, 2),
                          "wall_per_decision_x": round(per_decision, 2),
                          "exponent": round(math.log(per_decision) / math.log(fleet), 2),
                          "peak_mb_x": round(b["peak_mb"] / a["peak_mb"], 2)})
        out[mode] = steps
    return out


def run(sizes: list[int], modes: tuple[str, ...] = MODES, strategy: str = "greedy",
        timeout_s: float = 1800.0, progress: Callable[[str], None] | None = None,
        keep: Path | None = None, lookahead: float = LOOKAHEAD_S) -> dict:
    """The report; with `keep` (a directory not there yet), every run's directory is kept in
    it as VEHICLES-MODE."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="fleet-bench-floors-") as scratch:
        floors = keep or Path(scratch)
        for vehicles in sizes:
            shape = floor_for(vehicles)
            layout = floors / f"scale-{vehicles}.toml"
            layout.write_text(generate_toml(shape, f"scale-{vehicles}"))
            for mode in modes:
                if progress:
                    progress(f"{vehicles} forklifts, {mode}: a {shape.aisles} x {shape.depth} "
                             f"x {shape.lane_depth} floor ...")
                row = run_one(layout, vehicles, mode, strategy, timeout_s,
                              keep / f"{vehicles}-{mode}" if keep else None, lookahead)
                row["floor"] = {"aisles": shape.aisles, "depth": shape.depth,
                                "lane_depth": shape.lane_depth}
                rows.append(row)
                if progress:
                    progress(f"  {describe(row)}")
    digests = {}
    for row in rows:
        if row.get("completed"):
            digests.setdefault(row["vehicles"], set()).add(row["digest"])
    return {"strategy": strategy, "lookahead": None if math.isinf(lookahead) else lookahead,
            "sizes": sizes, "modes": list(modes), "rows": rows,
            "same_record": {v: len(d) == 1 for v, d in digests.items()},
            "growth": growth(rows), "cpus": os.cpu_count()}


def describe(row: dict) -> str:
    if not row.get("completed"):
        why = "timed out" if row["timed_out"] else "did not complete"
        got = (f"{row['stacks_done']}/{row['stacks']} stacks by t = {row['end_time_s']} s, "
               f"{row['decision_failures']} failures; " if "stacks_done" in row else "")
        kept = f"; kept in {row['recording']}" if row.get("recording") else ""
        return f"{why} after {row['wall_s']} s: {got}{row.get('error', '')}{kept}"
    agent = f", {row['peak_agent_mb']} MB an agent" if row.get("peak_agent_mb") else ""
    return (f"{row['stacks_done']}/{row['stacks']} stacks, end {row['end_time_s']} s, "
            f"{row['decision_failures']} failures, verdicts "
            f"{'pass' if row['passed'] else 'FAIL'}; wall {row['wall_s']} s, "
            f"{row['wall_per_decision_ms']} ms a decision, peak {row['peak_mb']} MB{agent}")
