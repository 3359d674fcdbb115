"""A run directory belongs to one run (docs/runtime.md): it is claimed when the run starts,
by creating it (or taking an empty one) and writing its marker, fleet-run.json, which holds
the run's id. Nothing in it is deleted afterwards; the one exception is `--force`, which
replaces a whole run directory (never a directory a run did not make) before a new run
claims it. Every segment written in the directory carries the marker's run id
(fleet.recording.writer), so a file of another run in it is told apart and refused by name.
"""

from __future__ import annotations

import itertools
import json
import os
import shutil
import sys
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from fleet.errors import UserError

MARKER = "fleet-run.json"  # "this is a run directory, of this run"
RUNS = Path("runs")  # where runs go when no directory is given
SHOWN = 6  # entries named in a message before "and N more"


@dataclass(frozen=True)
class RunDir:
    path: Path
    run_id: str  # uuid4 hex, made once when the directory is claimed


def choose(out: Path | None, force: bool, layout: str, strategy: str,
           say: Callable[[str], None] = lambda line: print(line, file=sys.stderr)) -> RunDir:
    """The directory of a new run: `out` claimed (`force`: an earlier run's replaced), or
    without one a new directory under runs/ named for now, the layout and the strategy."""
    if out is None:
        return claim_new(RUNS, default_name(layout, strategy, time.localtime()))
    return claim(out, force, say)


def default_name(layout: str, strategy: str, now: time.struct_time) -> str:
    """DATE-TIME-LAYOUT-STRATEGY: the name of a run directory when none is given."""
    return f"{time.strftime('%Y%m%d-%H%M%S', now)}-{layout}-{strategy}"


def claim_new(parent: Path, name: str) -> RunDir:
    """A new run directory parent/name, or name-2, name-3, ... when taken: mkdir either
    creates a directory or fails, so two runs started in the same second get one each."""
    parent = Path(parent)
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"cannot create {parent} for the run directory: "
                        f"{exc.strerror}") from None
    for n in itertools.count(1):
        path = parent / (name if n == 1 else f"{name}-{n}")
        try:
            path.mkdir()
            return _mark(path)
        except FileExistsError:
            continue
        except OSError as exc:
            raise UserError(f"cannot create the run directory {path}: {exc.strerror}") from None


def claim(path: Path, force: bool = False,
          say: Callable[[str], None] = lambda line: print(line, file=sys.stderr)) -> RunDir:
    """`path` as the directory of a new run: created, or an empty directory taken. A
    directory with anything in it is refused; with `force`, a run directory (one holding
    its marker) is replaced whole, what was removed said through `say`."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UserError(f"{path} is a file, not a directory: give --out a directory for "
                        f"the run")
    entries = _entries(path) if path.is_dir() else []
    if entries and not force:
        raise UserError(f"{path} is not empty (it holds {_listing(entries)}): a run writes "
                        f"only in a new directory; give another --out, or --force to replace "
                        f"this run directory whole")
    if entries:
        _refuse_to_replace(path, entries)
        return _replace(path, entries, say)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"cannot create the run directory {path}: {exc.strerror}") from None
    return _mark(path)


def fresh(path: Path) -> RunDir:
    """The directory a run is about to write in: one claimed for it a moment ago (nothing
    in it but its marker), or else claimed now (a new or empty directory). A run never
    writes beside the files of another."""
    path = Path(path)
    run_id = run_id_of(path) if path.is_dir() else None
    if run_id is not None and [p.name for p in _entries(path)] == [MARKER]:
        return RunDir(path, run_id)
    return claim(path)


def run_id_of(path: Path) -> str | None:
    """The run id in a directory's marker; None if it has none (not a run directory, or
    one made before run directories had markers)."""
    marker = Path(path) / MARKER
    try:
        text = marker.read_text()
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise UserError(f"cannot read {marker}: {exc.strerror}") from None
    try:
        run_id = json.loads(text)["run_id"]
    except (ValueError, KeyError, TypeError):
        run_id = None
    if not isinstance(run_id, str) or not run_id:
        raise UserError(f"{marker}: not a run marker (it should hold a JSON object with a "
                        f"run_id)")
    return run_id


def marker_of(path: Path) -> dict:
    """Everything the marker says (run_id, started: UTC ISO time); {} without one."""
    try:
        data = json.loads((Path(path) / MARKER).read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _mark(path: Path) -> RunDir:
    """Write the marker of a new run in an empty directory; a marker already there (another
    run claimed the directory meanwhile) is refused."""
    run = RunDir(path, uuid.uuid4().hex)
    data = {"run_id": run.run_id,
            "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    try:
        with open(path / MARKER, "x") as stream:
            json.dump(data, stream)
            stream.write("\n")
    except FileExistsError:
        raise UserError(f"{path}: another run claimed this directory at the same "
                        f"moment; give another --out") from None
    except OSError as exc:
        raise UserError(f"cannot write in the run directory {path}: {exc.strerror}") from None
    return run


def _entries(path: Path) -> list[Path]:
    try:
        return sorted(path.iterdir())
    except OSError as exc:
        raise UserError(f"cannot read the directory {path}: {exc.strerror}") from None


def _listing(entries: list[Path]) -> str:
    names = [p.name + ("/" if p.is_dir() else "") for p in entries]
    more = len(names) - SHOWN
    return ", ".join(names[:SHOWN]) + (f" and {more} more" if more > 0 else "")


def _refuse_to_replace(path: Path, entries: list[Path]) -> None:
    """--force replaces a run directory, never the user's own: not one without a marker,
    nor the current directory, one of its parents, or the home directory, nor a link."""
    if path.is_symlink():
        raise UserError(f"{path} is a symbolic link: --force replaces only a run directory "
                        f"itself; give --out the directory it points to, or another")
    where = path.resolve()
    cwd = Path.cwd().resolve()
    if where == cwd or where in cwd.parents or where == Path.home().resolve():
        what = "your home directory" if where == Path.home().resolve() else \
            "the current directory" if where == cwd else "a parent of the current directory"
        raise UserError(f"{path} is {what}: --force never replaces it; give another --out")
    if run_id_of(path) is None:
        raise UserError(f"{path} is not a run directory (no {MARKER}; it holds "
                        f"{_listing(entries)}): --force replaces only a directory a fleet "
                        f"run claimed; move or delete this one yourself, or give another "
                        f"--out")


def _replace(path: Path, entries: list[Path], say: Callable[[str], None]) -> RunDir:
    """Move the old run aside in one step, claim the directory anew, then delete the old
    run (a failure to delete leaves it aside, named, and the new run still starts)."""
    old_id, removed = run_id_of(path), _listing(entries)
    aside = path.with_name(f".{path.name}.replaced-{uuid.uuid4().hex[:8]}")
    try:
        os.rename(path, aside)
        path.mkdir()
    except OSError as exc:
        if aside.exists() and not path.exists():
            os.rename(aside, path)
        raise UserError(f"--force: cannot replace {path}: {exc.strerror}") from None
    run = _mark(path)
    try:
        shutil.rmtree(aside)
    except OSError as exc:
        say(f"--force: the old run {old_id} is left in {aside} ({exc.strerror})")
    else:
        say(f"--force: replaced the run directory {path}: removed run {old_id} "
            f"({removed})")
    return run
