"""A run's recording as files: run.mcap in its run directory, and run-2.mcap, run-3.mcap, ...
for each recorder restarted during the run (docs/recording.md, segments)."""

from __future__ import annotations

import re
from pathlib import Path

RUN_FILE = "run.mcap"  # a run directory's recording (its first segment)
SEGMENT_FILE = re.compile(r"run-([2-9]|[1-9]\d+)\.mcap")  # later segments: run-2.mcap, ...


def segment_number(path: Path) -> int | None:
    """1 for run.mcap, N for run-N.mcap, None for any other name."""
    if path.name == RUN_FILE:
        return 1
    match = SEGMENT_FILE.fullmatch(path.name)
    return int(match[1]) if match else None


def segment_paths(path: Path) -> list[Path]:
    """Every segment of a run, in order (run.mcap, run-2.mcap, ..., run-10.mcap), given its
    directory or its run.mcap; any other file is a recording of its own. A directory with
    no segment gives an empty list."""
    path = Path(path)
    if path.is_dir():
        folder = path
    elif path.name == RUN_FILE:
        folder = path.parent
    else:
        return [path]
    try:
        names = [entry for entry in folder.iterdir() if SEGMENT_FILE.fullmatch(entry.name)]
    except OSError:
        names = []
    first = [folder / RUN_FILE] if path.name == RUN_FILE or (folder / RUN_FILE).exists() else []
    return first + sorted(names, key=segment_number)


def next_segment(run_dir: Path) -> Path:
    """Where a recorder (re)started for the run in `run_dir` writes: run.mcap in a directory
    without segments, else run-N.mcap after the last one (never an existing file, never a
    number before one already written)."""
    run_dir = Path(run_dir)
    existing = segment_paths(run_dir) if run_dir.is_dir() else []
    if not existing:
        return run_dir / RUN_FILE
    return run_dir / f"run-{max(segment_number(p) or 1 for p in existing) + 1}.mcap"


def run_dir_of(path: Path) -> Path | None:
    """The run directory a path names (itself, or its run.mcap's); None for a lone file."""
    path = Path(path)
    if path.is_dir():
        return path
    return path.parent if path.name == RUN_FILE else None
