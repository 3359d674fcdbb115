"""Progress on stderr, as people expect it: on a terminal a tqdm bar that fits the terminal's
width and redraws in place; elsewhere (CI, `| tee`, a file) a plain line every few seconds,
the first and the last among them, never a carriage return. Neither ever runs backwards."""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from typing import TextIO

from tqdm import tqdm

PLAIN_EVERY_S = 5.0  # wall seconds between two plain lines
REDRAW_S = 0.1  # wall seconds between two redraws of a terminal's bar at most
FALLBACK_SIZE = (80, 24)


def terminal_size(stream: TextIO) -> tuple[int, int]:
    """Columns and lines of the stream's terminal: COLUMNS and LINES when set (as
    shutil.get_terminal_size has them), else what the terminal says, else 80 by 24."""
    try:
        size = os.get_terminal_size(stream.fileno())
        columns, lines = size.columns, size.lines
    except (AttributeError, OSError, ValueError):
        columns, lines = 0, 0
    env_columns, env_lines = os.environ.get("COLUMNS", ""), os.environ.get("LINES", "")
    columns = int(env_columns) if env_columns.isdigit() else columns
    lines = int(env_lines) if env_lines.isdigit() else lines
    return columns if columns > 0 else FALLBACK_SIZE[0], lines if lines > 0 else FALLBACK_SIZE[1]


def _isatty(stream: TextIO) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


class ProgressBar:
    """`done` of `total` (counted in `unit`s) under a label, with a free text after it
    (`extra`). A count lower than one already shown is taken as the higher one (reports may
    come out of order). Not `enabled`: silent. `clock` (wall seconds) paces the plain lines,
    one every `every_s`; a terminal's bar is redrawn at most every `redraw_s`."""

    def __init__(self, total: int, label: str, stream: TextIO | None = None, *,
                 unit: str = "", enabled: bool = True, every_s: float = PLAIN_EVERY_S,
                 clock: Callable[[], float] = time.monotonic,
                 redraw_s: float = REDRAW_S) -> None:
        self.total = max(total, 1)
        self.label = label
        self.unit = unit
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.done = 0
        self.extra = ""
        self.every_s = every_s
        self.clock = clock
        self.redraw_s = redraw_s
        self.terminal = enabled and _isatty(self.stream)
        # Drawn from the first update on, so that what is said before stays on its own lines.
        self._bar: tqdm | None = None
        self._started = clock()
        self._next_line: float | None = None  # when the next plain line is due
        self._shown = ("", -1)  # the last plain line's (extra, done)

    def update(self, done: int, extra: str = "") -> None:
        if not self.enabled:
            return
        self.done = max(self.done, done)
        self.extra = extra
        if self.terminal:
            bar = self._bar or self._draw()
            bar.ncols = terminal_size(self.stream)[0] - 1  # the terminal may be resized
            bar.set_postfix_str(extra, refresh=False)
            bar.update(self.done - bar.n)
            return
        now = self.clock()
        if self._next_line is None or now >= self._next_line:
            self._line(now)
            self._next_line = now + self.every_s

    def _draw(self) -> tqdm:
        # The last column stays free: some terminals wrap a line that fills it.
        columns, lines = terminal_size(self.stream)
        unit = " {unit}" if self.unit else ""
        self._bar = tqdm(total=self.total, desc=self.label, file=self.stream, ncols=columns - 1,
                         nrows=lines, miniters=0, mininterval=self.redraw_s, unit=self.unit,
                         bar_format="{desc} {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt}"
                         + unit + "{postfix} [{elapsed}<{remaining}]")
        return self._bar

    def close(self) -> None:
        """End the bar on its own line; without a terminal, say the last state if it is not
        the line shown last."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        elif self.enabled and self._next_line is not None and \
                self._shown != (self.extra, self.done):
            self._line(self.clock())

    def _line(self, now: float) -> None:
        unit = f" {self.unit}" if self.unit else ""
        extra = f", {self.extra}" if self.extra else ""
        self.stream.write(f"{self.label}: {self.done}/{self.total}{unit}{extra} "
                          f"[{now - self._started:.0f} s]\n")
        self.stream.flush()
        self._shown = (self.extra, self.done)


class MissionProgress:
    """A mission's progress reports (stacks done, sim time, decision failures), which come from
    several processes and not always in order, on a ProgressBar: the most stacks, the latest
    sim time and the most failures heard so far."""

    def __init__(self, bar: ProgressBar) -> None:
        self.bar = bar
        self.t = 0.0
        self.failures = 0

    def __call__(self, done: int, t: float, failures: int) -> None:
        self.t = max(self.t, t)
        self.failures = max(self.failures, failures)
        self.bar.update(done, f"t={self.t:.0f} s, {self.failures} decision failures")
