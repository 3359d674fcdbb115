"""`fleet plot RECORD`: the filling sequence, a Gantt chart and snapshots as PNG files."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from fleet.errors import UserError
from fleet.layout import load_layout


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plot", help="draw a mission record (fleet run --out DIR)")
    p.add_argument("record", type=Path, help="mission.json, or the directory holding it")
    p.add_argument("--out", type=Path, help="directory for the PNG files (default: beside "
                   "the record)")
    p.add_argument("--at", type=float, action="append", default=[],
                   help="also draw a snapshot at this time in seconds (repeatable; default: "
                   "at a quarter, half and three quarters of the end time)")
    p.add_argument("--layout", help="layout name or file (default: the one in the record)")
    p.set_defaults(handler=run)


def load_record(path: Path) -> dict:
    if path.is_dir():
        path = path / "mission.json"
    try:
        record = json.loads(path.read_text())
    except OSError as exc:
        raise UserError(f"cannot read {path}: {exc.strerror}") from None
    except json.JSONDecodeError as exc:
        raise UserError(f"{path}: not a mission record (invalid JSON: {exc})") from None
    missing = {"mission", "subtasks", "stacks_done", "end_time_s", "starts"} - set(record) \
        if isinstance(record, dict) else {"everything"}
    if missing:
        raise UserError(f"{path}: not a mission record (missing {', '.join(sorted(missing))})")
    return record


def run(args: argparse.Namespace) -> int:
    from fleet import mission_plots

    record = load_record(args.record)
    layout = load_layout(args.layout or record["mission"]["layout"])
    out = args.out or (args.record if args.record.is_dir() else args.record.parent)
    out.mkdir(parents=True, exist_ok=True)
    end = record["end_time_s"]
    written = [out / "filling.png", out / "gantt.png"]
    mission_plots.filling_sequence(str(written[0]), layout, record)
    mission_plots.gantt(str(written[1]), record)
    for t in args.at or [end / 4, end / 2, 3 * end / 4]:
        if t < 0:
            raise UserError(f"--at {t}: time must not be negative")
        path = out / f"snapshot_{t:08.2f}.png"
        mission_plots.snapshot(str(path), layout, record, t)
        written.append(path)
    print(f"stacks per quarter of the end time: {mission_plots.quarters(record)}")
    for path in written:
        print(f"wrote {path}")
    return 0
