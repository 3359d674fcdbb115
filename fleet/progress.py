"""A one-line progress bar on stderr (no dependency; quiet when stderr is not a terminal
unless forced)."""

from __future__ import annotations

import sys
from typing import TextIO


class ProgressBar:
    def __init__(self, total: int, label: str, stream: TextIO | None = None,
                 width: int = 30) -> None:
        self.total = max(total, 1)
        self.label = label
        self.stream = stream or sys.stderr
        self.width = width
        self.enabled = self.stream.isatty() or stream is not None
        self._last = ""

    def update(self, done: int, extra: str = "") -> None:
        if not self.enabled:
            return
        filled = round(self.width * done / self.total)
        line = (f"\r{self.label} [{'#' * filled}{'.' * (self.width - filled)}] "
                f"{done}/{self.total} {extra}")
        if line != self._last:
            self.stream.write(line)
            self.stream.flush()
            self._last = line

    def close(self) -> None:
        if self.enabled and self._last:
            self.stream.write("\n")
            self.stream.flush()
