"""`fleet runs [DIR]`: the runs under runs/ (or DIR), oldest first, with their verdicts.

Judging a recording means reading all of it, so `fleet run` and `fleet analyze DIR` keep
what they judged in the run directory (summary.json: the mission, its end time, the three
verdicts, whether the figures are whole, and the segments read); a run without one (or whose
segments changed since) is described from its recording's metadata, which is read from the
start of the file only, and listed as not analysed, or as "no result" when the summary
section at the end of its recording shows no result of the dispatcher (a run stopped early,
or one whose processes died) or nothing was recorded at all.
"""

from __future__ import annotations

import argparse
import calendar
import json
import os
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from fleet.errors import UserError
from fleet.mission.standstill import Standstill
from fleet.recording.reader import RecordingError, read_description, result_recorded
from fleet.recording.rundir import MARKER, RUNS, marker_of, run_id_of
from fleet.recording.segments import RUN_FILE, segment_paths

SUMMARY = "summary.json"
VERDICTS = ("safety", "work", "messages")
SEARCH_DEPTH = 3  # run directories are looked for this many levels below DIR


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("runs", help="list past runs and their verdicts",
                       description="List the runs under a directory (default runs/), oldest "
                       "first: layout, mission, strategy, clock, fleet size, end time and "
                       "verdicts as `fleet run` or `fleet analyze DIR` judged them (\"not "
                       "analysed\" for a run neither judged, or whose recording changed since: "
                       "fleet analyze DIR judges it; \"no result\" for a run whose recording "
                       "ends before the mission's result, one interrupted or whose processes "
                       "died).")
    p.add_argument("dir", nargs="?", type=Path, default=RUNS,
                   help="where to look (default runs/); a run directory lists itself")
    p.add_argument("--json", action="store_true",
                   help="one JSON object per run and line instead of the table")
    p.set_defaults(handler=list_runs)


@dataclass
class RunEntry:
    directory: str
    started: str  # UTC, ISO 8601: the marker's, else the recording's modification time
    run_id: str | None
    layout: str = ""
    mission: str = ""
    strategy: str = ""
    clock: str = ""
    vehicles: int | None = None
    end_time_s: float | None = None  # the mission's (sim time of the last stack done)
    verdict: str = "not analysed"  # pass, FAIL, not analysed, no result, unreadable
    verdicts: dict[str, bool] = field(default_factory=dict)  # safety, work, messages
    problem: str = ""  # why it is unreadable or has no result, or its summary no longer holds
    incomplete: bool = False  # its figures miss what no recorder or record kept
    stopped: str = ""  # a mission that did not finish: how and when ("stuck at t=1913.00 s")

    @property
    def verdict_text(self) -> str:
        whole = "; figures incomplete" if self.incomplete else ""
        stopped = f"; {self.stopped}" if self.stopped else ""
        if self.verdict == "FAIL":
            return "FAIL: " + ", ".join(k for k in VERDICTS if not self.verdicts.get(k)) + \
                stopped + whole
        return (f"{self.verdict} ({self.problem})" if self.problem else self.verdict) + \
            stopped + whole


# -------------------------------------------------------------------------- the summary


def summary_of(report, run_id: str | None, segments: dict[str, int],
               stopped: Standstill | None = None) -> dict[str, Any]:
    """What `fleet runs` keeps of a judged run (a fleet.analysis.report.Report), and of one
    that did not finish how far it got (`stopped`, as its recording says)."""
    verdicts = {"safety": report.safe, "work": report.work_done,
                "messages": report.messages_whole}
    return {"run_id": run_id, "judged": _utc(time.time()), "mission": report.mission,
            "finished": report.finished, "end_time_s": report.end_time_s,
            "stopped": stopped.to_dict() if stopped is not None else None,
            "verdicts": verdicts, "passed": report.passed, "incomplete": report.incomplete,
            "segments": segments}


def write_summary(run_dir: Path, report, stopped: Standstill | None = None) -> None:
    """Keep the verdicts `fleet run` or `fleet analyze` just gave in the run directory
    (written whole, then renamed into place: never half a file). A summary.json that is not
    one of these is left alone, and one that already says the same is not written again.
    Failing to keep it fails nothing (one note): `fleet runs` then lists the run as not
    analysed."""
    summary = summary_of(report, run_id_of(run_dir), _segment_sizes(run_dir), stopped)
    if (run_dir / SUMMARY).exists():
        kept = _summary(run_dir)
        if kept is None:
            return  # a file of the same name that is not ours
        if {k: v for k, v in kept.items() if k != "judged"} == \
                {k: v for k, v in json.loads(json.dumps(summary)).items() if k != "judged"}:
            return  # it says so already (a read-only directory is then no trouble)
    temporary = run_dir / f".{SUMMARY}.tmp"
    try:
        temporary.write_text(json.dumps(summary, indent=1) + "\n")
        os.replace(temporary, run_dir / SUMMARY)
    except OSError as exc:
        print(f"note: could not keep the run's summary in {run_dir / SUMMARY}: "
              f"{exc.strerror}", file=sys.stderr)


def _segment_sizes(run_dir: Path) -> dict[str, int]:
    return {p.name: p.stat().st_size for p in segment_paths(run_dir) if p.exists()}


# -------------------------------------------------------------------------- the listing


def find_runs(root: Path, depth: int = SEARCH_DEPTH) -> list[Path]:
    """Run directories at or under `root`: those with a marker or a run.mcap (nothing is
    looked for inside a run directory, nor in hidden ones)."""
    if _is_run(root):
        return [root]
    if depth == 0:
        return []
    try:
        children = sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith("."))
    except OSError:
        return []
    return [run for child in children for run in find_runs(child, depth - 1)]


def _is_run(path: Path) -> bool:
    return (path / MARKER).is_file() or (path / RUN_FILE).is_file()


def describe(run_dir: Path) -> RunEntry:
    """A run as its summary says, else as its recording's metadata says."""
    mark = marker_of(run_dir)
    entry = RunEntry(str(run_dir), mark.get("started") or _utc(_modified(run_dir)),
                     mark.get("run_id"))
    summary = _summary(run_dir)
    if summary is not None and summary["segments"] == _segment_sizes(run_dir) and \
            summary.get("run_id") == entry.run_id:
        m, verdicts = summary["mission"], summary["verdicts"]
        entry.layout, entry.mission, entry.strategy, entry.clock = (
            str(m.get(k, "")) for k in ("layout", "kind", "strategy", "clock"))
        entry.vehicles = m.get("vehicles") if isinstance(m.get("vehicles"), int) else None
        entry.end_time_s = float(summary["end_time_s"])
        entry.verdicts = {k: bool(verdicts.get(k)) for k in VERDICTS}
        entry.verdict = "pass" if all(entry.verdicts.values()) else "FAIL"
        entry.incomplete = bool(summary.get("incomplete"))
        entry.stopped = _stopped_text(summary.get("stopped"))
        return entry
    if summary is not None:
        entry.problem = "its recording changed since it was judged"
    segments = [p for p in segment_paths(run_dir) if p.exists()]
    if not segments:
        if mark:
            entry.verdict, entry.problem = "no result", "nothing was recorded"
        else:
            entry.verdict, entry.problem = "unreadable", f"no {RUN_FILE}"
        return entry
    try:
        run = read_description(segments[0]).get("run", {})
    except RecordingError as exc:
        entry.verdict, entry.problem = "unreadable", str(exc)
        return entry
    entry.layout, entry.mission, entry.strategy, entry.clock = (
        run.get(k, "") for k in ("layout", "mission", "strategy", "clock"))
    entry.vehicles = int(run["vehicles"]) if run.get("vehicles", "").isdigit() else None
    if result_recorded(segments[-1]) is False:
        entry.verdict = "no result"
        entry.problem = "its recording ends before the mission's result: interrupted, or a " \
            "process died"
    return entry


def _summary(run_dir: Path) -> dict | None:
    """The run's summary.json, if there is one as `write_summary` writes it."""
    try:
        data = json.loads((run_dir / SUMMARY).read_text())
    except (OSError, ValueError):
        return None
    shaped = isinstance(data, dict) and all(
        isinstance(data.get(k), dict) for k in ("mission", "verdicts", "segments")) and \
        isinstance(data.get("end_time_s"), int | float)
    return data if shaped else None


def _stopped_text(stopped: Any) -> str:
    """How and when a judged run's mission stopped, from its summary ("" when it finished,
    or the summary does not say in the expected shape)."""
    if not isinstance(stopped, dict):
        return ""
    cause, t = stopped.get("cause"), stopped.get("t")
    if not isinstance(cause, str) or not isinstance(t, int | float) or isinstance(t, bool):
        return ""
    return f"{cause} at t={t:.2f} s"


def _modified(run_dir: Path) -> float:
    for path in (run_dir / RUN_FILE, run_dir):
        try:
            return path.stat().st_mtime
        except OSError:
            continue
    return 0.0


def _utc(epoch: float) -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(epoch))


def _started(entry: RunEntry) -> float:
    try:
        return calendar.timegm(time.strptime(entry.started, "%Y-%m-%dT%H:%M:%SZ"))
    except ValueError:
        return 0.0


def table(entries: list[RunEntry]) -> list[str]:
    header = ("directory", "layout", "mission", "strategy", "clock", "vehicles", "end time",
              "verdicts")
    rows = [(e.directory, e.layout or "-", e.mission or "-", e.strategy or "-",
             e.clock or "-", "-" if e.vehicles is None else str(e.vehicles),
             "-" if e.end_time_s is None else f"{e.end_time_s:.2f} s", e.verdict_text)
            for e in entries]
    widths = [max(len(r[k]) for r in [header, *rows]) for k in range(len(header) - 1)]
    right = {5, 6}  # numbers

    def line(row: tuple[str, ...]) -> str:
        cells = [c.rjust(w) if k in right else c.ljust(w)
                 for k, (c, w) in enumerate(zip(row, widths, strict=False))]
        return "  ".join([*cells, row[-1]])

    return [line(header), *map(line, rows)]


def list_runs(args: argparse.Namespace) -> int:
    root: Path = args.dir
    if not root.is_dir():
        if root == RUNS and not root.exists():
            print(f"no runs yet: {RUNS}/ does not exist (fleet run makes it)", file=sys.stderr)
            return 0
        raise UserError(f"{root}: {'not a directory' if root.exists() else 'no such directory'}")
    entries = sorted((describe(run) for run in find_runs(root)),
                     key=lambda e: (_started(e), e.directory))
    if not entries:
        print(f"no runs under {root}", file=sys.stderr)
        return 0
    if args.json:
        for entry in entries:
            print(json.dumps(asdict(entry)))
    else:
        print("\n".join(table(entries)))
    return 0
