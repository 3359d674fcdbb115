"""`fleet analyze RUN.mcap|DIR`: the run's numbers and its safety, work and message verdicts
(a run directory: every segment its recorders wrote, read as one recording, and the verdicts
kept in it for `fleet runs`, as `fleet run` keeps them)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from fleet.mission.standstill import Standstill

LABEL_WIDTH = 19  # "  label              value": where the value starts, after two spaces


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("analyze", help="analyze a recording: numbers and verdicts",
                       description="Read a recording (also one a killed recorder left) and "
                       "report the mission's end time, each forklift's distance and time, "
                       "message counts and gaps, and the verdicts: safety (no two forklifts "
                       "on one cell at once, none outside its reservation), work (every stack "
                       "exactly once) and messages (none lost). Exit status 1 when a verdict "
                       "fails. Of a run directory (or its run.mcap) the verdicts are kept in "
                       "its summary.json for `fleet runs`.")
    p.add_argument("recording", type=Path, help="an MCAP file, or a run directory holding "
                   "run.mcap (and run-2.mcap, ... of a restarted recorder: read as one)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    return print_analysis(args.recording, args.json)


def print_analysis(recording: Path, as_json: bool = False) -> int:
    """Print what the recording says (as one JSON object); 1 when a verdict fails."""
    from fleet.analysis.analyze import analyze
    from fleet.commands.runs import write_summary
    from fleet.recording.mission_record import recorded_standstill
    from fleet.recording.reader import read_recording, recording_file
    from fleet.recording.segments import RUN_FILE

    first = recording_file(recording)  # refuses what is no recording, saying why
    read = read_recording(recording)
    if read.info is not None and read.layout().floor is not None:
        report004 = _print_analysis004(read, as_json)
        if recording.is_dir() or recording.name == RUN_FILE:
            write_summary(first.parent, report004)
        return 0 if report004.passed else 1
    report = analyze(read)
    stopped = recorded_standstill(read)
    if recording.is_dir() or recording.name == RUN_FILE:  # a run's, every segment
        write_summary(first.parent, report, stopped)
    if as_json:
        print(json.dumps({**report.to_json(),
                          "stopped": stopped.to_dict() if stopped is not None else None}))
    else:
        print("\n".join(report.lines() + (stopped_lines(stopped) if stopped else [])))
    return 0 if report.passed else 1


def _print_analysis004(read, as_json: bool):
    """A seed-004 recording: its events judged (fleet/analysis/analyze004.py)."""
    from fleet.analysis.analyze004 import analyze004, report_json, report_lines, verdict_lines

    report = analyze004(read)
    if as_json:
        print(json.dumps(report_json(report)))
    else:
        print("\n".join([*report_lines(report), f"  {'recording':<19}{report.path}",
                         *verdict_lines(report)]))
    return report


def stopped_lines(stopped: Standstill) -> list[str]:
    """How far a mission that did not finish got, as `fleet analyze` and `fleet run` say it:
    the headline, then where each forklift stood and what it was at."""
    head, *vehicles = stopped.lines()
    return [f"  {'stopped':<{LABEL_WIDTH}}{head}",
            *(f"  {'':<{LABEL_WIDTH}}{line}" for line in vehicles)]
