"""Reading recordings (fleet.recording.format): what analysis, plots and the recorder's
restart read.

`read_recording` recovers every complete chunk of a truncated file (a killed recorder) and
says where reading stopped. Of a run recorded in segments (a recorder restarted during the
run: fleet.recording.segments) it reads every segment as one recording and says where no
recorder was running; a segment of another run in the run directory is refused by name,
never merged.
"""

from __future__ import annotations

import heapq
import math
import os
from collections import Counter
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Footer, Metadata, Schema
from mcap.records import Message as McapMessage
from mcap.stream_reader import StreamReader

from fleet.errors import UserError
from fleet.recording.format import (
    LAYOUT_ATTACHMENT,
    MCAP_MAGIC,
    NS,
    RUN_METADATA,
    SEGMENT_METADATA,
    VIEW_PREFIXES,
)
from fleet.recording.rundir import MARKER, run_id_of
from fleet.recording.segments import RUN_FILE, run_dir_of, segment_number, segment_paths
from fleet.wire.protocol import Envelope, Message, MissionDone, MissionInfo, ProtocolError, decode
from fleet.wire.topics import genuine, message_type
from fleet.world.layout import Layout
from fleet.world.layout_file import parse_layout


@dataclass(frozen=True)
class Recorded:
    key: str
    log_ns: int
    publish_ns: int
    envelope: Envelope | None  # None: the payload is not a valid message (see error)
    error: str = ""

    @property
    def message(self) -> Message | None:
        return None if self.envelope is None else self.envelope.message

    @cached_property
    def genuine(self) -> bool:
        """A valid message of the type its key carries, from the one sender of that key
        (worked out once: every question about a recording asks it again)."""
        return self.envelope is not None and genuine(self.key, self.envelope)


@dataclass(frozen=True)
class Segment:
    """One file of a recording: a recorder's output from its start to its end (or its kill)."""

    path: Path
    messages: int = 0  # msgpack records read from it
    first_log_ns: int | None = None  # receive times of its first and last message records
    last_log_ns: int | None = None
    complete: bool = False  # it ends with its footer
    problem: str = ""  # why reading it stopped before its footer
    duplicates: int = 0  # records an overlapping earlier segment already holds (dropped)


@dataclass(frozen=True)
class RecorderGap:
    """A window in which no recorder was running: from the last record of one segment to the
    first record of the next (receive times, Unix nanoseconds)."""

    after: Path  # the segment that ended
    before: Path  # the segment that began
    start_ns: int
    end_ns: int

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / NS


@dataclass
class Recording:
    path: Path  # the (first) file read; its directory is the run's
    messages: list[Recorded] = field(default_factory=list)  # msgpack channels, file order
    # (the segments of a run merged by log time)
    views: dict[str, int] = field(default_factory=dict)  # view topic -> messages
    view_schemas: dict[str, str] = field(default_factory=dict)  # view topic -> schema name
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: dict[str, bytes] = field(default_factory=dict)
    complete: bool = False  # every file ends with its footer
    problem: str = ""  # why reading stopped before a footer (each segment's, named)
    segments: list[Segment] = field(default_factory=list)  # the files read, in order
    _index: tuple[int, dict] | None = field(default=None, repr=False, compare=False)

    @property
    def gaps(self) -> list[RecorderGap]:
        """The windows between segments in which no recorder was running."""
        found: list[RecorderGap] = []
        last: Segment | None = None  # the segment with the latest record so far
        for segment in self.segments:
            if segment.first_log_ns is None or segment.last_log_ns is None:
                continue  # nothing read from it: it says nothing about when it ran
            if last is not None and segment.first_log_ns > last.last_log_ns:
                found.append(RecorderGap(last.path, segment.path, last.last_log_ns,
                                         segment.first_log_ns))
            if last is None or segment.last_log_ns > last.last_log_ns:
                last = segment
        return found

    def of(self, cls: type[Message]) -> list[tuple[Recorded, Any]]:
        """Every genuine message of a type (from its key's sender, on its key), with where
        and when it was recorded, in file order."""
        found = [entry for kind, entries in self._genuine_by_type().items()
                 if issubclass(kind, cls) for entry in entries]
        if len({type(m) for _, (_, m) in found}) > 1:
            found.sort()
        return [(r, m) for _, (r, m) in found]

    def _genuine_by_type(self) -> dict[type, list[tuple[int, tuple[Recorded, Any]]]]:
        """The genuine messages by type, each with its place in the file; sorted once, while
        `messages` stays as it is (an analysis asks for one type after another)."""
        if self._index is None or self._index[0] != len(self.messages):
            index: dict[type, list[tuple[int, tuple[Recorded, Any]]]] = {}
            for k, r in enumerate(self.messages):
                if r.genuine:
                    index.setdefault(type(r.envelope.message), []).append(
                        (k, (r, r.envelope.message)))
            self._index = (len(self.messages), index)
        return self._index[1]

    @property
    def foreign(self) -> list[Recorded]:
        """Valid messages that are not genuine: another type or sender than the key's."""
        return [r for r in self.messages if r.envelope is not None and not r.genuine]

    @property
    def run_id(self) -> str | None:
        """The id of the run it was recorded for (None: written outside a run directory,
        or before recordings had one)."""
        return self.metadata.get(SEGMENT_METADATA, {}).get("run_id")

    @property
    def info(self) -> MissionInfo | None:
        found = self.of(MissionInfo)
        return found[-1][1] if found else None

    @property
    def span_s(self) -> float:
        """Receive-time span of the recorded messages (wall seconds)."""
        if not self.messages:
            return 0.0
        times = [r.log_ns for r in self.messages]
        return (max(times) - min(times)) / NS

    @property
    def last_sim_time(self) -> float:
        """The latest simulation time a recorded message carries."""
        return max((r.envelope.sim_time for r in self.messages if r.genuine
                    and math.isfinite(r.envelope.sim_time)), default=0.0)

    def layout(self) -> Layout:
        data = self.attachments.get(LAYOUT_ATTACHMENT)
        if data is None and self.info is not None:
            data = self.info.layout_toml.encode()
        if data is None:
            raise RecordingError(f"{self.path}: the recording holds no layout (no "
                                 f"layout.toml attachment and no mission message)")
        try:
            text = data.decode()
        except UnicodeDecodeError as exc:
            raise RecordingError(f"{self.path}: the layout.toml attachment is not UTF-8 text "
                                 f"({exc.reason} at byte {exc.start})") from None
        return parse_layout(text, f"{self.path}: layout.toml")


class RecordingError(UserError, ValueError):
    """A file that is not a readable recording; the message says why. The user's to fix (a
    UserError), and still the ValueError it always was to whoever catches that."""


def recording_file(path: Path) -> Path:
    """The MCAP file a path names: the file itself, or DIR's first segment (DIR/run.mcap).
    The retired mission.json and anything else that is not MCAP are refused, saying which it
    is; of a run in segments, one readable segment is enough."""
    path = Path(path)
    segments = segment_paths(path)
    if not segments:
        old = (" (it holds a mission.json: that format is retired, only MCAP recordings "
               "are read)") if (path / "mission.json").exists() else ""
        raise RecordingError(f"{path}: no {RUN_FILE} in this directory{old}")
    errors = []
    for segment in segments:
        try:
            _check_magic(segment)
            return segments[0]
        except RecordingError as exc:
            errors.append(exc)
    raise errors[0]


def _check_magic(path: Path) -> None:
    try:
        with open(path, "rb") as stream:
            head = stream.read(len(MCAP_MAGIC))
    except OSError as exc:
        raise RecordingError(f"cannot read {path}: {exc.strerror}") from None
    if head == MCAP_MAGIC:
        return
    if path.suffix.lower() == ".json" or head.lstrip()[:1] in (b"{", b"["):
        raise RecordingError(f"{path}: a JSON file, not an MCAP recording; mission.json "
                             f"records are retired: give the run's recording ({RUN_FILE})")
    raise RecordingError(f"{path}: not an MCAP recording (it does not start with the MCAP "
                         f"magic)")


def read_description(path: Path, within_records: int = 100_000) -> dict[str, dict[str, str]]:
    """A recording's metadata records (`segment`: its run id; `run`: the run's description)
    without reading the rest: they come near the start, so reading stops once both are in,
    or after `within_records` records. Cheap enough to list many runs."""
    _check_magic(path)
    found: dict[str, dict[str, str]] = {}
    with open(path, "rb") as stream:
        records = StreamReader(stream, record_size_limit=1 << 30).records
        try:
            for _, record in zip(range(within_records), records, strict=False):
                if isinstance(record, Metadata):
                    found[record.name] = dict(record.metadata)
                    if RUN_METADATA in found:  # the segment's own comes first, when it has one
                        break
        except Exception as exc:  # mcap raises its own, struct and decompression errors
            if not found:
                raise RecordingError(f"{path}: not a readable MCAP recording "
                                     f"({type(exc).__name__})") from None
    return found


OVERLAP_SLACK_NS = NS  # two recorders stamp one message within this of each other


def read_recording(path: Path) -> Recording:
    """Everything a recording holds: of a file, or of every segment of a run (its directory
    or its run.mcap) merged in log-time order. A truncated file (a killed recorder) gives its
    complete chunks, with `complete` False and `problem` saying where reading stopped; a
    segment that cannot be read at all is skipped (named in `problem`) if another can."""
    paths = segment_paths(path)
    if not paths:
        raise RecordingError(f"{path}: no {RUN_FILE} in this directory")
    if len(paths) == 1:
        recording = _read_segment(paths[0])[0]
        _check_one_run(run_dir_of(path), [recording])
        return recording
    parts: list[tuple[Recording, list[int]]] = []
    errors: list[RecordingError] = []
    for segment_path in paths:
        try:
            parts.append(_read_segment(segment_path))
        except RecordingError as exc:
            errors.append(exc)
            parts.append((Recording(segment_path, segments=[Segment(
                segment_path, problem=f"not read: {exc}")]), []))
    if len(errors) == len(paths):
        raise errors[0]
    _check_one_run(run_dir_of(path), [part for part, _ in parts])
    return _merge(parts)


# What a run's description says that its segments must agree on (older recordings carry no
# run id: this still tells a segment of another mission apart).
SAME_RUN = ("layout", "mission", "strategy", "vehicles", "seed", "clock", "speed")


def _check_one_run(folder: Path | None, segments: list[Recording]) -> None:
    """Every segment read from a run directory is of the directory's run: the id of its
    marker (fleet-run.json) or, without one, of its run.mcap; and all describe the same
    mission. A file of another run is refused by name: merged, it would give false
    verdicts (or no analysis at all); dropped, nobody would learn it is there."""
    if folder is None:
        return
    try:
        marked = run_id_of(folder)
    except UserError as exc:
        raise RecordingError(str(exc)) from None
    read = [s for s in segments if s.metadata or s.messages]  # an unread one says nothing
    if not read:
        return
    expected, source = (marked, MARKER) if marked is not None else \
        (read[0].run_id, read[0].path.name)
    for segment in read:
        if segment.run_id != expected:
            raise RecordingError(
                f"{segment.path}: a recording of another run (run id "
                f"{segment.run_id or 'none'}; this directory's run is {expected or 'without one'}, "
                f"from {source}): a run directory holds one run's segments only; move "
                f"{segment.path.name} out of {folder} to read the run")
    described = [s for s in read if RUN_METADATA in s.metadata]
    for segment in described[1:]:
        first, this = described[0].metadata[RUN_METADATA], segment.metadata[RUN_METADATA]
        differ = [f"{k} {this.get(k)!r}, not {first.get(k)!r}" for k in SAME_RUN
                  if this.get(k) != first.get(k)]
        if differ:
            raise RecordingError(
                f"{segment.path}: a recording of another run than "
                f"{described[0].path.name} ({'; '.join(differ)}): a run directory holds one "
                f"run's segments only; move {segment.path.name} out of {folder} to read the "
                f"run")


def _merge(parts: list[tuple[Recording, list[int]]]) -> Recording:
    """One recording of a run's segments: messages merged by log time (a message that two
    overlapping recorders both recorded, once), metadata and attachments from the first
    segment that has them."""
    merged = Recording(parts[0][0].path, complete=True)
    streams: list[list[Recorded]] = []
    earlier: list[tuple[Recorded, int]] = []  # every kept record so far, with its payload hash
    for part, digests in parts:
        (segment,) = part.segments
        kept = list(zip(part.messages, digests, strict=True))
        last = max((r.log_ns for r, _ in earlier), default=None)
        if kept and last is not None and segment.first_log_ns <= last + OVERLAP_SLACK_NS:
            seen = Counter((r.key, d) for r, d in earlier
                           if r.log_ns >= segment.first_log_ns - OVERLAP_SLACK_NS)
            unique = []
            for r, d in kept:
                if r.log_ns <= last + OVERLAP_SLACK_NS and seen[r.key, d] > 0:
                    seen[r.key, d] -= 1
                else:
                    unique.append((r, d))
            segment = replace(segment, duplicates=len(kept) - len(unique))
            kept = unique
        earlier += kept
        streams.append([r for r, _ in kept])
        merged.segments.append(segment)
        for topic, n in part.views.items():
            merged.views[topic] = merged.views.get(topic, 0) + n
        for target, source in ((merged.view_schemas, part.view_schemas),
                               (merged.metadata, part.metadata),
                               (merged.attachments, part.attachments)):
            for name, value in source.items():
                target.setdefault(name, value)
        merged.complete = merged.complete and part.complete
    merged.messages = list(heapq.merge(*streams, key=lambda r: r.log_ns))
    merged.problem = "; ".join(f"{s.path.name}: {s.problem}" for s in merged.segments
                               if not s.complete)
    return merged


def _read_segment(path: Path) -> tuple[Recording, list[int]]:
    """One file, and a hash of each message record's payload (to tell a message two
    recorders both recorded)."""
    recording = Recording(Path(path))
    digests: list[int] = []
    channels: dict[int, Channel] = {}
    schemas: dict[int, Schema] = {}
    try:
        stream = open(path, "rb")  # noqa: SIM115 - closed below
    except OSError as exc:
        raise RecordingError(f"cannot read {path}: {exc.strerror}") from None
    with stream:
        records = StreamReader(stream, record_size_limit=1 << 30).records
        while True:
            try:
                record = next(records)
            except StopIteration:
                break
            except Exception as exc:  # mcap raises its own, struct and decompression errors
                if not channels and not recording.messages:
                    raise RecordingError(f"{path}: not an MCAP recording "
                                         f"({type(exc).__name__}: {exc})") from None
                what = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
                recording.problem = f"the file ends in a torn record ({what}) after " \
                    f"{os.path.getsize(path)} bytes"
                recording.complete = False  # cut after its footer, before the closing magic
                break
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, McapMessage):
                if _add_message(recording, channels, schemas, record):
                    digests.append(hash(record.data))
            elif isinstance(record, Metadata):
                recording.metadata[record.name] = dict(record.metadata)
            elif isinstance(record, Attachment):
                recording.attachments[record.name] = bytes(record.data)
            elif isinstance(record, Footer):
                recording.complete = True
    if not recording.complete and not recording.problem:
        recording.problem = "the file ends before its footer"
    times = [r.log_ns for r in recording.messages]
    recording.segments = [Segment(recording.path, len(times), min(times, default=None),
                                  max(times, default=None), recording.complete,
                                  recording.problem)]
    return recording, digests


def _add_message(recording: Recording, channels: dict[int, Channel],
                 schemas: dict[int, Schema], record: McapMessage) -> bool:
    """Add a record; True if it is a message of a msgpack channel."""
    channel = channels.get(record.channel_id)
    if channel is None:
        return False  # a message whose channel was lost with a torn chunk
    if channel.topic.startswith(VIEW_PREFIXES):
        recording.views[channel.topic] = recording.views.get(channel.topic, 0) + 1
        schema = schemas.get(channel.schema_id)
        recording.view_schemas[channel.topic] = schema.name if schema else ""
        return False
    try:
        envelope, error = decode(record.data), ""
    except ProtocolError as exc:
        envelope, error = None, str(exc)
    recording.messages.append(Recorded(channel.topic, record.log_time, record.publish_time,
                                       envelope, error))
    return True


def result_recorded(segment: Path) -> bool | None:
    """Whether a recording holds the dispatcher's result (dispatch/done), from the summary
    section at its end alone; None when it has none (a torn file: its recorder killed)."""
    try:
        with open(segment, "rb") as stream:
            stream.seek(-len(MCAP_MAGIC), os.SEEK_END)
            if stream.read() != MCAP_MAGIC:
                return None
            stream.seek(0)
            summary = make_reader(stream).get_summary()
    except Exception:  # OSError, and mcap's own, struct and decompression errors
        return None
    if summary is None or summary.statistics is None:
        return None
    counts = summary.statistics.channel_message_counts
    return any(message_type(channel.topic) is MissionDone and counts.get(number, 0) > 0
               for number, channel in summary.channels.items())


def unbroken_run(numbers: set[int]) -> int:
    """The last of 1, 2, ... that `numbers` holds without a gap (0: not 1): what a
    restarted recorder asks after, since a predecessor killed during its own catch-up may
    hold later numbers and miss earlier ones."""
    return next(n for n in range(len(numbers) + 1) if n + 1 not in numbers)


def numbers_before(segment: Path, key: str) -> set[int]:
    """The numbers of the genuine messages on `key` in the segments of the run that come
    before `segment` (a restarted recorder's: what its predecessors wrote). Only that key's
    messages are decoded, and each file is read up to a torn end."""
    number = segment_number(segment) or 1
    held: set[int] = set()
    for path in segment_paths(segment.parent):
        if (segment_number(path) or 1) >= number:
            continue
        try:
            with open(path, "rb") as stream:
                channels: set[int] = set()
                for record in StreamReader(stream, record_size_limit=1 << 30).records:
                    if isinstance(record, Channel) and record.topic == key:
                        channels.add(record.id)
                    elif isinstance(record, McapMessage) and record.channel_id in channels:
                        try:
                            envelope = decode(record.data)
                        except ProtocolError:
                            continue
                        if genuine(key, envelope):
                            held.add(envelope.seq)
        except Exception:  # mcap, struct, zstd or OS errors: a torn file, what was read counts
            continue
    return held
