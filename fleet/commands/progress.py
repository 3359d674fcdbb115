"""Progress on stderr, as people expect it: on a terminal a tqdm bar that fits the terminal's
width and redraws in place; elsewhere (CI, `| tee`, a file) a plain line every few seconds,
the first and the last among them, never a carriage return. Neither ever runs backwards, and
neither falls silent while no report comes: a ticker thread redraws the bar (its elapsed time
goes on) and says the last state again when a plain line is due."""

from __future__ import annotations

import contextlib
import math
import os
import sys
import threading
import time
from collections.abc import Callable
from typing import TextIO

from tqdm import tqdm
from tqdm.contrib.logging import logging_redirect_tqdm

PLAIN_EVERY_S = 5.0  # wall seconds between two plain lines
TICK_S = 0.5  # wall seconds between two looks of the ticker: a plain line is at most this late
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
    one every `every_s` on a grid from the bar's creation. A terminal's bar is redrawn at most
    every `redraw_s` (None: tqdm's default, 0.1 s, which TQDM_MININTERVAL overrides).

    From the first update on, a daemon thread calls `tick` every `tick_s` until `close`;
    with `tick_s=None` there is none and the owner (a test) calls `tick` itself."""

    def __init__(self, total: int, label: str, stream: TextIO | None = None, *,
                 unit: str = "", enabled: bool = True, every_s: float = PLAIN_EVERY_S,
                 clock: Callable[[], float] = time.monotonic,
                 redraw_s: float | None = None, tick_s: float | None = TICK_S) -> None:
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
        self.tick_s = tick_s
        self.terminal = enabled and _isatty(self.stream)
        # Drawn from the first update on, so that what is said before stays on its own lines.
        self._bar: tqdm | None = None
        self._started = clock()
        self._next_line: float | None = None  # when the next plain line is due
        self._shown = ("", -1)  # the last plain line's (extra, done)
        self._lock = threading.Lock()  # reports and the ticker draw one at a time
        self._ticker: threading.Thread | None = None
        self._stop = threading.Event()
        self._redirected = contextlib.ExitStack()  # log records above the bar, not inside it

    def update(self, done: int, extra: str = "") -> None:
        if not self.enabled:
            return
        with self._lock:
            self.done = max(self.done, done)
            self.extra = extra
            self._show(ticked=False)
            if self._ticker is None and self.tick_s is not None:
                self._ticker = threading.Thread(target=self._tick_until_closed, daemon=True,
                                                name="progress ticker")
                self._ticker.start()

    def tick(self) -> None:
        """The run goes on though no report came: the terminal's bar is redrawn (its elapsed
        time advances); without a terminal, the last state is said again when a line is due.
        Nothing before the first update, nor after the close."""
        with self._lock:
            if self._bar is not None or (not self.terminal and self._next_line is not None):
                self._show(ticked=True)

    def _tick_until_closed(self) -> None:
        try:
            while not self._stop.wait(self.tick_s):
                self.tick()
        except (OSError, ValueError):  # the stream is gone (a closed pipe): nothing to tell
            return

    def _show(self, ticked: bool) -> None:
        if self.terminal:
            bar = self._bar or self._draw()
            bar.ncols = terminal_size(self.stream)[0] - 1  # the terminal may be resized
            bar.set_postfix_str(self.extra, refresh=False)
            if ticked:
                bar.refresh()
            else:
                bar.update(self.done - bar.n)
            return
        now = self.clock()
        if self._next_line is None or now >= self._next_line:
            self._line(now)
            # The next line on the grid of every_s: a late look does not shift the ones after.
            periods = math.floor((now - self._started) / self.every_s) + 1
            self._next_line = self._started + periods * self.every_s

    def _draw(self) -> tqdm:
        # The last column stays free: some terminals wrap a line that fills it. The free text
        # comes after the elapsed time (as in tqdm's own format): cut at the terminal's width,
        # it loses its end, never the time.
        columns, lines = terminal_size(self.stream)
        unit = " {unit}" if self.unit else ""
        redraw = {} if self.redraw_s is None else {"mininterval": self.redraw_s}
        self._redirected.enter_context(logging_redirect_tqdm())
        self._bar = tqdm(total=self.total, desc=self.label, file=self.stream, ncols=columns - 1,
                         nrows=lines, miniters=0, unit=self.unit, initial=self.done,
                         postfix=self.extra or None, **redraw,
                         bar_format="{desc} {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt}"
                         + unit + " [{elapsed}<{remaining}{postfix}]")
        return self._bar

    def close(self) -> None:
        """Stop the ticker and end the bar on its own line; without a terminal, say the last
        state if it is not the line shown last."""
        self._stop.set()
        if self._ticker is not None and self._ticker is not threading.current_thread():
            self._ticker.join()
        with self._lock:
            if self._bar is not None:
                self._bar.close()
                self._bar = None
                self._redirected.close()
            elif self.enabled and not self.terminal and self._next_line is not None and \
                    self._shown != (self.extra, self.done):
                self._line(self.clock())
            self._next_line = None  # closed: a late tick says nothing

    def _line(self, now: float) -> None:
        unit = f" {self.unit}" if self.unit else ""
        extra = f", {self.extra}" if self.extra else ""
        self.stream.write(f"{self.label}: {self.done}/{self.total}{unit}{extra} "
                          f"[{now - self._started:.0f} s]\n")
        self.stream.flush()
        self._shown = (self.extra, self.done)


class MissionProgress:
    """A mission's progress reports (stacks done, the sim time the mission has reached,
    decision failures), which come from several processes and not always in order, on a
    ProgressBar: the most stacks, the latest sim time and the most failures heard so far.
    Before the first report, `status` says what the run is doing."""

    def __init__(self, bar: ProgressBar) -> None:
        self.bar = bar
        self.t = 0.0
        self.failures = 0

    def status(self, text: str) -> None:
        self.bar.update(self.bar.done, text)

    def __call__(self, done: int, t: float, failures: int) -> None:
        self.t = max(self.t, t)
        self.failures = max(self.failures, failures)
        self.bar.update(done, f"t={self.t:.0f} s, {self.failures} decision failures")
