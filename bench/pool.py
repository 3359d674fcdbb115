"""Missions of a benchmark spread over worker processes."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import TypeVar

Job = TypeVar("Job")
Result = TypeVar("Result")


def run_all(jobs: Sequence[Job], run: Callable[[Job], Result],
            progress: Callable[[int, int], None] | None = None,
            workers: int | None = None) -> dict[Job, Result]:
    """Each job's result, run in `workers` processes (default: one a core), saying how many
    are done as they come."""
    results: dict[Job, Result] = {}
    with ProcessPoolExecutor(max_workers=workers or os.cpu_count() or 1) as pool:
        for job, result in zip(jobs, pool.map(run, jobs), strict=True):
            results[job] = result
            if progress is not None:
                progress(len(results), len(jobs))
    return results
