"""Fast-mode multi-process run against the in-process reference, side by side: the same
`fleet run` command line with and without --inprocess, alternated, each a fresh process
(so both pay interpreter start-up and imports), and their records compared by digest."""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable

from fleet.errors import UserError


def timed_run(args: list[str]) -> tuple[float, str]:
    """`fleet run ARGS` as a fresh process: its wall time and what it printed. Its recording,
    journal and logs go to a directory of its own, removed after (fleet run would otherwise
    keep them under runs/ in the current directory). A run that fails stops the benchmark,
    saying which and why."""
    with tempfile.TemporaryDirectory(prefix="fleet-bench-run-") as out_dir:
        start = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "fleet", "run", *args, "--out", out_dir],
                              capture_output=True, text=True)
        wall = time.perf_counter() - start  # not counting the removal of the directory
    if done.returncode != 0:
        said = "\n".join(done.stderr.strip().splitlines()[-5:]) or "(nothing on stderr)"
        raise UserError(f"`fleet run {' '.join(args)}` failed (exit {done.returncode}):\n"
                        f"{said}")
    return wall, done.stdout


def _wall(args: list[str]) -> tuple[float, str]:
    wall, out = timed_run(args)
    digest = next(line.split()[-1] for line in out.splitlines() if "record digest" in line)
    return wall, digest


def run(layout: str = "paper", strategy: str = "ann", repeats: int = 3,
        progress: Callable[[str], None] | None = None) -> dict:
    base = ["--layout", layout, "--strategy", strategy, "--mission", "fill"]
    walls: dict[str, list[float]] = {"inprocess": [], "processes": []}
    digests = set()
    for k in range(repeats):
        for name, extra in (("inprocess", ["--inprocess"]), ("processes", [])):
            wall, digest = _wall(base + extra)
            walls[name].append(wall)
            digests.add(digest)
            if progress:
                progress(f"run {k + 1}/{repeats} {name}: {wall:.1f} s")
    inproc, procs = statistics.median(walls["inprocess"]), statistics.median(walls["processes"])
    return {"ratio_layout": layout, "ratio_strategy": strategy, "ratio_repeats": repeats,
            "inprocess_wall_s": round(inproc, 2), "multiprocess_wall_s": round(procs, 2),
            "multiprocess_ratio": round(procs / inproc, 3),
            "same_record": len(digests) == 1}
