"""`fleet compare A B`: two recorded runs side by side, and how B differs from A.

Everything comes from each recording's mission record (fleet.recording.mission_record.
summary_of) and its analysis (fleet.analysis.analyze: the verdicts), summarised by
`summarize`; a row of the table is a `Field` naming a key of that summary, so a new
comparison is one more summary key and one more Field.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path
from statistics import mean
from typing import Any

from fleet.analysis.analyze import analyze
from fleet.commands.plot import read_run
from fleet.mission.record import MissionSummary
from fleet.recording.reader import Recording
from fleet.recording.segments import RUN_FILE


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compare", help="compare two recorded runs side by side",
                       description="Put two recorded runs side by side: the mission, end "
                       "time, stacks, decision failures, waiting time, utilisation, each "
                       "forklift's busy time and the verdicts of each, with B - A and B / A "
                       "for the numbers.")
    p.add_argument("a", type=Path, help=f"run A: an MCAP recording, or a directory holding "
                   f"{RUN_FILE}")
    p.add_argument("b", type=Path, help="run B, compared with A (differences are B - A)")
    p.add_argument("--json", action="store_true",
                   help="print both summaries and the differences as one JSON object")
    p.set_defaults(handler=run)


@dataclass(frozen=True)
class Field:
    """A row: a summary key ("busy_s.1" looks into the busy_s map), its label, the format of
    a number (empty for text, which is only compared for equality) and whether B / A means
    something."""

    key: str
    label: str
    fmt: str = ""
    ratio: bool = True

    @property
    def numeric(self) -> bool:
        return bool(self.fmt)


FIELDS: tuple[Field, ...] = (
    Field("mission", "mission"),
    Field("strategy", "strategy"),
    Field("layout", "layout"),
    Field("vehicles", "forklifts", "d", ratio=False),
    Field("clock", "clock"),
    Field("complete", "recording complete"),
    Field("segments", "recording segments", "d", ratio=False),
    Field("end_time_s", "end time [s]", ".2f"),
    Field("all_parked_s", "all parked [s]", ".2f"),
    Field("stacks_done", "stacks done", "d"),
    Field("subtasks", "subtasks", "d"),
    Field("decision_failures", "decision failures", "d"),
    Field("plans_failed", "  plans failed", "d"),
    Field("waiting_s", "waiting [s]", ".2f"),
    Field("stopped_s", "  stopped [s]", ".2f"),
    Field("postponed_s", "  postponed [s]", ".2f"),
    Field("mean_utilisation", "mean utilisation", ".1%"),
    Field("overlaps", "overlaps", "d", ratio=False),
    Field("outside_reservation", "outside reservation", "d", ratio=False),
    Field("stacks_duplicated", "stacks done twice", "d", ratio=False),
    Field("stacks_lost", "stacks lost", "d", ratio=False),
    Field("messages_lost", "messages lost", "d", ratio=False),
    Field("messages_not_recorded", "messages not recorded", "d", ratio=False),
    Field("passed", "verdicts pass"),
)


def summarize(recording: Recording, record: MissionSummary) -> dict[str, Any]:
    """What is compared of one run, as JSON-able data: the numbers as `fleet analyze` has
    them (docs/metrics.md)."""
    m = record.mission
    info = recording.info
    report = analyze(recording)
    vehicles = report.vehicles
    return {
        "path": str(recording.path),
        "complete": recording.complete,
        "segments": len(recording.segments),
        "mission": m.kind,
        "strategy": m.strategy,
        "layout": m.layout,
        "vehicles": m.vehicles,
        "clock": info.clock if info is not None else "",
        "end_time_s": report.end_time_s,
        "all_parked_s": report.all_parked_s,
        "stacks_done": report.stacks_done,
        "subtasks": report.subtasks,
        "decision_failures": report.decision_failures,
        "plans_failed": report.plans_failed,
        "waiting_s": sum(v.waiting_s for v in vehicles),
        "stopped_s": sum(v.stopped_s for v in vehicles),
        "postponed_s": sum(v.postponed_s for v in vehicles),
        "mean_utilisation": mean(v.utilisation for v in vehicles) if vehicles else 0.0,
        "busy_s": {str(v.vehicle): v.busy_s for v in vehicles},
        "overlaps": len(report.overlaps),
        "outside_reservation": len(report.outside_reservation),
        "stacks_duplicated": len(report.stacks_duplicated),
        "stacks_lost": len(report.stacks_lost),
        "messages_lost": report.messages_lost,
        "messages_not_recorded": report.messages_not_recorded,
        "passed": report.passed,
    }


def fields_of(a: dict[str, Any], b: dict[str, Any]) -> list[Field]:
    """The rows for two summaries: FIELDS, then each forklift of either run."""
    vehicles = sorted(set(a["busy_s"]) | set(b["busy_s"]), key=int)
    return [*FIELDS, *(Field(f"busy_s.{v}", f"forklift {v} busy [s]", ".2f")
                       for v in vehicles)]


def lookup(summary: dict[str, Any], key: str) -> Any:
    """A summary's value for a Field key; None when that run has none (a forklift it lacks)."""
    value: Any = summary
    for part in key.split("."):
        if not isinstance(value, dict) or part not in value:
            return None
        value = value[part]
    return value


def difference(field: Field, a: Any, b: Any) -> tuple[float | None, float | None]:
    """(B - A, B / A) of a numeric row; None where it has no meaning."""
    if not field.numeric or a is None or b is None:
        return None, None
    ratio = b / a if field.ratio and a != 0 else None
    return b - a, ratio


def comparison(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    """Both summaries and, for each numeric row, B - A and B / A (dotted keys nested)."""
    diff: dict[str, Any] = {}
    ratio: dict[str, Any] = {}
    for field in fields_of(a, b):
        d, r = difference(field, lookup(a, field.key), lookup(b, field.key))
        for target, value in ((diff, d), (ratio, r)):
            if value is not None:
                *outer, last = field.key.split(".")
                for part in outer:
                    target = target.setdefault(part, {})
                target[last] = value
    return {"a": a, "b": b, "diff": diff, "ratio": ratio}


def _show(value: Any, fmt: str, sign: bool = False) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if not fmt:
        return str(value)
    try:
        return format(value, ("+" if sign else "") + fmt)
    except (TypeError, ValueError):  # e.g. a count recorded as a float
        return str(value)


def table(a: dict[str, Any], b: dict[str, Any]) -> list[str]:
    """The side-by-side table, one line per row, under the two runs' paths."""
    rows = [("", "A", "B", "B - A", "B / A")]
    for field in fields_of(a, b):
        va, vb = lookup(a, field.key), lookup(b, field.key)
        if field.numeric:
            d, r = difference(field, va, vb)
            change = _show(d, field.fmt, sign=True)
            ratio = "-" if r is None else f"{r:.3f}"
        else:
            change, ratio = ("" if va == vb else "differs"), ""
        rows.append((field.label, _show(va, field.fmt), _show(vb, field.fmt), change, ratio))
    widths = [max(len(row[k]) for row in rows) for k in range(5)]
    lines = [f"A  {a['path']}", f"B  {b['path']}", ""]
    for label, *cells in rows:
        text = f"{label:<{widths[0]}}" + "".join(
            f"  {cell:>{w}}" for cell, w in zip(cells, widths[1:], strict=True))
        lines.append(text.rstrip())
    return lines


def run(args: argparse.Namespace) -> int:
    a = summarize(*read_run(args.a))
    b = summarize(*read_run(args.b))
    if args.json:
        print(json.dumps(comparison(a, b), indent=2))
    else:
        print("\n".join(table(a, b)))
    return 0
