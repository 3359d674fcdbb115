"""Append-only journal of accepted reservation changes: one msgpack map per change.

msgpack is self-delimiting, so the file is a plain stream of records. A process killed in the
middle of a write leaves a torn last record; `replay` keeps every complete record before it,
reports the torn tail, and cuts it off so new records follow good ones. The steps of one
amending commit are written at once, and a tail of them without the last (the one carrying
the request id) is cut off with it: an amend replays whole or not at all. Bytes that are not
msgpack at all are an error naming the record, and so is an unfinished record with complete
records after it (damage in the middle is never cut off as if it were a torn tail).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import msgpack

from fleet.wire.protocol import ProtocolError, WireChange, body_of, build_message


class JournalError(ValueError):
    """A journal that cannot be replayed; the message names the record and why."""


@dataclass(frozen=True)
class Replayed:
    changes: list[WireChange]
    torn_bytes: int  # bytes of a torn last record that were cut off (0: none)


class Journal:
    def __init__(self, path: Path) -> None:
        self.path = path
        self._file = None

    def replay(self) -> Replayed:
        """Every complete record, in order; a torn tail is cut off the file."""
        if not self.path.exists():
            return Replayed([], 0)
        data = self.path.read_bytes()
        unpacker = msgpack.Unpacker(raw=False, strict_map_key=True)
        unpacker.feed(data)
        changes: list[WireChange] = []
        starts: list[int] = []  # where each change's record begins
        good = 0
        try:
            for raw in unpacker:
                if not isinstance(raw, dict):
                    raise JournalError(f"{self.path}: record {len(changes) + 1} at byte "
                                       f"{good} is not a map")
                try:
                    change = build_message(WireChange, raw)
                except ProtocolError as exc:
                    raise JournalError(f"{self.path}: record {len(changes) + 1} at byte "
                                       f"{good}: {exc}") from None
                assert isinstance(change, WireChange)
                changes.append(change)
                starts.append(good)
                good = unpacker.tell()
        except JournalError:
            raise
        except (ValueError, msgpack.exceptions.UnpackException) as exc:
            raise JournalError(f"{self.path}: record {len(changes) + 1} at byte {good} is "
                               f"not msgpack: {exc}") from None
        if len(data) > good:
            later = _next_record(data, good)
            if later is not None:  # damage in the middle, not a write cut short at the end
                raise JournalError(f"{self.path}: record {len(changes) + 1} at byte {good} is "
                                   f"not a complete record, yet a complete record follows at "
                                   f"byte {later}")
        while changes and changes[-1].part_of:  # the steps of an amend cut short: none
            changes.pop()
            good = starts.pop()
        torn = len(data) - good
        if torn:
            with open(self.path, "r+b") as f:
                f.truncate(good)
        return Replayed(changes, torn)

    def append(self, *changes: WireChange) -> None:
        """Write the records in one write and hand them to the OS before the change is
        answered (a killed process loses nothing; a power cut may lose the last records: no
        fsync, for speed)."""
        if self._file is None:
            self._file = open(self.path, "ab")  # noqa: SIM115 - kept open for the service's life
        self._file.write(b"".join(msgpack.packb(body_of(c), use_bin_type=True)
                                  for c in changes))
        self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


MAX_PROBE = 1 << 20  # a record longer than this is not looked for after a torn one


def _next_record(data: bytes, start: int) -> int | None:
    """Where a complete, valid record starts after `start`, if one does. A crash tears only
    the last record, so an unfinished record with whole records after it is damage (a length
    prefix that claims the rest of the file), which must not be cut off as a torn tail."""
    for at in range(start + 1, len(data)):
        if not (0x80 <= data[at] <= 0x8F or data[at] in (0xDE, 0xDF)):  # a record is a map
            continue
        unpacker = msgpack.Unpacker(raw=False, strict_map_key=True)
        unpacker.feed(data[at:at + MAX_PROBE])
        try:
            raw = unpacker.unpack()
            if isinstance(raw, dict):
                build_message(WireChange, raw)
                return at
        except Exception:  # msgpack raises several types; not a record here: probe on
            continue
    return None
