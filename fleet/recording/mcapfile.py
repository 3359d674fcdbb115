"""Recordings of runs as MCAP files (docs/recording.md): the one format analysis and plots
read, written by the recorder process and by the in-process engine alike.

Each zenoh key is a channel whose messages are the raw msgpack payloads as they travelled
(message encoding `msgpack`, a JSON schema per message type); log time is when the message
was received, publish time its simulation time. The run's description is a metadata record
and the layout a TOML attachment, so a recording stands on its own. View channels under
/view/ carry Foxglove scene messages (protobuf) for Foxglove to display.

Small chunks flushed about once a second bound what a killed recorder loses; `read_recording`
recovers every complete chunk of a truncated file and says where reading stopped. A recorder
restarted during a run writes a new segment of the same run (run-2.mcap, run-3.mcap, ...);
`read_recording` of the run reads every segment as one recording and says where no recorder
was running. Each segment carries the id of the run directory it was written in (metadata
`segment`), so a file of another run in the directory is refused by name, never merged.
"""

from __future__ import annotations

import functools
import heapq
import json
import math
import os
import platform
import re
import sys
import types
import typing
from collections import Counter
from collections.abc import Callable
from dataclasses import MISSING, dataclass, field, fields, replace
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import IO, Any

from mcap.records import Attachment, Channel, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from fleet import __version__
from fleet.errors import UserError
from fleet.mission.spec import Mission
from fleet.recording.rundir import MARKER, run_id_of
from fleet.wire.protocol import (
    ClockAck,
    ClockTick,
    DecisionFailure,
    Envelope,
    Halt,
    MissionDone,
    MissionInfo,
    Progress,
    ProtocolError,
    RecorderStatus,
    Resume,
    StackDone,
    StackReopened,
    SubtaskEvent,
    VehicleFault,
    VehicleState,
    WireChange,
    ZoneClosed,
    decode,
)
from fleet.wire.protocol import Message as WireMessage
from fleet.world.layout import Layout, layout_source, parse_layout

PROFILE = "forklift-fleet"
SEGMENT_METADATA = "segment"  # {"run_id": the run directory's}: which run a file is of
RUN_FILE = "run.mcap"  # a run directory's recording (its first segment)
SEGMENT_FILE = re.compile(r"run-([2-9]|[1-9]\d+)\.mcap")  # later segments: run-2.mcap, ...
MCAP_MAGIC = b"\x89MCAP0\r\n"  # every MCAP file starts with it
MESSAGE_ENCODING = "msgpack"
VIEW_PREFIX = "/view/"
CHUNK_BYTES = 64 * 1024  # small chunks: a crash loses at most the one being filled
NS = 1_000_000_000

# What each key under fleet/<run>/ carries and who may send it ({0}: the key's vehicle id).
# The channel's schema is chosen by key, not by content, so a hostile payload is recorded on
# the channel it arrived on, as it was; analysis believes a message only from its sender.
KEY_TYPES: tuple[tuple[re.Pattern, type[WireMessage], str], ...] = tuple(
    (re.compile(rf"fleet/[^/]+/{pattern}"), cls, sender) for pattern, cls, sender in (
        (r"vehicle/(\d+)/state", VehicleState, "vehicle-{0}"),
        (r"reservation/change", WireChange, "reservation"),
        (r"clock", ClockTick, "clock"),
        (r"clock/ack/(\d+)", ClockAck, "vehicle-{0}"),
        (r"dispatch/progress", Progress, "dispatcher"),
        (r"dispatch/done", MissionDone, "dispatcher"),
        (r"dispatch/mission", MissionInfo, "dispatcher"),
        (r"dispatch/subtask", SubtaskEvent, "dispatcher"),
        (r"dispatch/stack", StackDone, "dispatcher"),
        (r"dispatch/failure", DecisionFailure, "dispatcher"),
        (r"recorder/status", RecorderStatus, "recorder"),
        (r"dispatch/halt", Halt, "dispatcher"),
        (r"dispatch/resume", Resume, "dispatcher"),
        (r"dispatch/reopen", StackReopened, "dispatcher"),
        (r"dispatch/zone", ZoneClosed, "dispatcher"),
        (r"vehicle/(\d+)/fault", VehicleFault, "vehicle-{0}"),
        (r"clock/ack/injector", ClockAck, "injector"),
    ))


def message_type(key: str) -> type[WireMessage] | None:
    found = _key_type(key)
    return found[0] if found else None


def expected_sender(key: str) -> str | None:
    found = _key_type(key)
    return found[1] if found else None


@functools.lru_cache(maxsize=4096)
def _key_type(key: str) -> tuple[type[WireMessage], str] | None:
    for pattern, cls, sender in KEY_TYPES:
        match = pattern.fullmatch(key)
        if match:
            return cls, sender.format(*match.groups())
    return None


def _json_type(hint: Any) -> dict:
    origin = typing.get_origin(hint)
    if origin in (types.UnionType, typing.Union):
        return {"anyOf": [_json_type(h) for h in typing.get_args(hint)]}
    if hint is type(None):
        return {"type": "null"}
    simple = {bool: "boolean", int: "integer", float: "number", str: "string", dict: "object"}
    if hint in simple:
        return {"type": simple[hint]}
    if origin is list:
        return {"type": "array", "items": _json_type(typing.get_args(hint)[0])}
    if origin is tuple:
        items = [_json_type(h) for h in typing.get_args(hint)]
        return {"type": "array", "prefixItems": items, "minItems": len(items),
                "maxItems": len(items)}
    raise TypeError(f"no JSON schema for {hint!r}")  # pragma: no cover


def json_schema(cls: type[WireMessage]) -> dict:
    """The JSON schema of a message in its envelope (fleet/wire/protocol.py), msgpack-encoded."""
    hints = typing.get_type_hints(cls)
    body = {"type": "object", "additionalProperties": False,
            "properties": {f.name: _json_type(hints[f.name]) for f in fields(cls)},
            "required": [f.name for f in fields(cls)
                         if f.default is MISSING and f.default_factory is MISSING]}
    return {"title": cls.TYPE, "type": "object",
            "properties": {"v": {"const": 1}, "type": {"const": cls.TYPE},
                           "sender": {"type": "string"}, "seq": {"type": "integer"},
                           "t": {"type": "number"}, "body": body},
            "required": ["v", "type", "sender", "seq", "t", "body"]}


MAX_NS = 2**63 - 1  # MCAP times are unsigned 64-bit; Foxglove's are signed


def _ns(seconds: float) -> int:
    """Seconds as MCAP nanoseconds; a time that does not fit (a forged one) becomes 0."""
    if not math.isfinite(seconds) or not 0 <= seconds <= MAX_NS / NS:
        return 0
    return round(seconds * NS)


def mission_info(mission: Mission, layout: Layout, vehicles: int, clock: str,
                 speed: float = 1.0, command: str = "") -> MissionInfo:
    """What a recording says about its run (the dispatcher publishes it)."""
    starts = list(mission.starts or layout.vehicle_starts)[:vehicles]
    versions = {"python": platform.python_version(), "zenoh": _package_version("eclipse-zenoh"),
                "mcap": _package_version("mcap")}
    return MissionInfo(layout.name, layout_source(mission.layout), mission.kind.value,
                       mission.strategy.value, vehicles, mission.seed, clock, speed,
                       [str(p) for p in starts], command or " ".join(sys.argv), versions)


def _package_version(name: str) -> str:
    try:
        return version(name)
    except PackageNotFoundError:
        return "unknown"


def run_metadata(info: MissionInfo) -> dict[str, str]:
    """The run's description as MCAP metadata (strings only)."""
    data = {"layout": info.layout, "mission": info.kind, "strategy": info.strategy,
            "vehicles": str(info.vehicles), "seed": str(info.seed), "clock": info.clock,
            "speed": repr(info.speed), "starts": " ".join(info.starts),
            "command": info.command, "fleet_version": __version__}
    data.update({f"version_{k}": str(v) for k, v in info.versions.items()})
    return data


class RecordingWriter:
    """Writes one run's MCAP file. Not thread-safe: one thread writes."""

    def __init__(self, path: Path, chunk_bytes: int = CHUNK_BYTES) -> None:
        self.path = path
        path.parent.mkdir(parents=True, exist_ok=True)
        self.run_id = run_id_of(path.parent)  # of the run directory it is in (None: none)
        self._file: IO[bytes] = open(path, "wb")  # noqa: SIM115 - closed by close()
        self._writer = Writer(self._file, chunk_size=chunk_bytes,
                              compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library=f"forklift-fleet {__version__}")
        if self.run_id is not None:  # first, before any chunk: a torn file still says it
            self._writer.add_metadata(SEGMENT_METADATA, {"run_id": self.run_id})
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self.messages = 0
        self.described = False

    def _schema(self, name: str, encoding: str, data: Callable[[], bytes]) -> int:
        if name not in self._schemas:
            self._schemas[name] = self._writer.register_schema(name, encoding, data())
        return self._schemas[name]

    def _channel(self, topic: str, encoding: str, schema_id: Callable[[], int]) -> int:
        if topic not in self._channels:
            self._channels[topic] = self._writer.register_channel(topic, encoding,
                                                                  schema_id())
        return self._channels[topic]

    def _raw_schema(self, key: str) -> int:
        cls = message_type(key)
        if cls is None:
            return 0
        return self._schema(cls.TYPE, "jsonschema", lambda: _dumps(json_schema(cls)))

    def write(self, key: str, payload: bytes, log_ns: int, sim_time: float) -> None:
        """One message as it travelled on `key`."""
        channel = self._channel(key, MESSAGE_ENCODING, lambda: self._raw_schema(key))
        self._writer.add_message(channel, log_time=log_ns, data=payload,
                                 publish_time=_ns(sim_time), sequence=self.messages)
        self.messages += 1

    def write_view(self, topic: str, message: Any, log_ns: int) -> None:
        """A Foxglove message (foxglove.messages.*) on a view channel."""
        channel = self._channels.get(topic)
        if channel is None:
            schema = message.get_schema()
            channel = self._channel(topic, schema.encoding, lambda: self._schema(
                schema.name, schema.encoding, lambda: bytes(schema.data)))
        self._writer.add_message(channel, log_time=log_ns, data=message.encode(),
                                 publish_time=log_ns)

    def describe(self, info: MissionInfo) -> None:
        """The run's metadata and its layout attachment, once."""
        if self.described:
            return
        self._writer.add_metadata("run", run_metadata(info))
        self._writer.add_attachment(0, 0, "layout.toml", "application/toml",
                                    info.layout_toml.encode())
        self.described = True

    def flush(self) -> None:
        """Close the chunk in progress and push everything to the file."""
        self._writer.flush()

    def close(self) -> None:
        self._writer.finish()
        self._file.close()


def _dumps(data: dict) -> bytes:
    return json.dumps(data, sort_keys=True).encode()


# -------------------------------------------------------------------------------- reading


@dataclass(frozen=True)
class Recorded:
    key: str
    log_ns: int
    publish_ns: int
    envelope: Envelope | None  # None: the payload is not a valid message (see error)
    error: str = ""

    @property
    def message(self) -> WireMessage | None:
        return None if self.envelope is None else self.envelope.message

    @property
    def genuine(self) -> bool:
        """A valid message of the type its key carries, from the one sender of that key."""
        found = _key_type(self.key)
        return (self.envelope is not None and found is not None
                and type(self.envelope.message) is found[0]
                and self.envelope.sender == found[1])


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

    def of(self, cls: type[WireMessage]) -> list[tuple[Recorded, Any]]:
        """Every genuine message of a type (from its key's sender, on its key), with where
        and when it was recorded."""
        return [(r, r.envelope.message) for r in self.messages
                if r.genuine and isinstance(r.envelope.message, cls)]

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
        data = self.attachments.get("layout.toml")
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
                    if "run" in found:  # the segment's own comes first, when it has one
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
        _check_one_run(_run_dir(path), [recording])
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
    _check_one_run(_run_dir(path), [part for part, _ in parts])
    return _merge(parts)


# What a run's description says that its segments must agree on (older recordings carry no
# run id: this still tells a segment of another mission apart).
SAME_RUN = ("layout", "mission", "strategy", "vehicles", "seed", "clock", "speed")


def _run_dir(path: Path) -> Path | None:
    """The run directory a path names (itself, or its run.mcap's); None for a lone file."""
    path = Path(path)
    if path.is_dir():
        return path
    return path.parent if path.name == RUN_FILE else None


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
    described = [s for s in read if "run" in s.metadata]
    for segment in described[1:]:
        first, this = described[0].metadata["run"], segment.metadata["run"]
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
                break
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
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
                 schemas: dict[int, Schema], record: Message) -> bool:
    """Add a record; True if it is a message of a msgpack channel."""
    channel = channels.get(record.channel_id)
    if channel is None:
        return False  # a message whose channel was lost with a torn chunk
    if channel.topic.startswith(VIEW_PREFIX):
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
