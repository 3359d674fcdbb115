"""The dispatcher's journal of what it fed an order mission's book (fleet/mission/order_log.py):
one msgpack record per input, handed to the OS before the input is acted on, so a new
dispatcher replays the book exactly as the dead one left it (docs/faults.md).

A dispatcher killed in the middle of a write leaves a torn last record: `records` keeps every
complete one and cuts the tail off, so new records follow good ones. Bytes that are no
msgpack at all are an error naming where, and the file is left alone.
"""

from __future__ import annotations

from pathlib import Path

import msgpack

from fleet.errors import UserError


class WorkJournal:
    def __init__(self, path: Path) -> None:
        self.path = path
        self._file = None

    def records(self) -> list[object]:
        """Every complete record, in order; a torn tail is cut off the file."""
        if not self.path.exists():
            return []
        data = self.path.read_bytes()
        unpacker = msgpack.Unpacker(raw=False, strict_map_key=True)
        unpacker.feed(data)
        records: list[object] = []
        good = 0
        try:
            for record in unpacker:
                records.append(record)
                good = unpacker.tell()
        except (ValueError, msgpack.exceptions.UnpackException) as exc:
            raise UserError(f"{self.path}: record {len(records) + 1} at byte {good} is not "
                            f"msgpack: {exc}") from None
        if len(data) > good:  # a write cut short: what follows the last good record goes
            with open(self.path, "r+b") as f:
                f.truncate(good)
        return records

    def append(self, record: list) -> None:
        if self._file is None:
            self._file = open(self.path, "ab")  # noqa: SIM115 - kept open for the mission
        self._file.write(msgpack.packb(record, use_bin_type=True))
        self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
