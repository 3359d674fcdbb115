"""Writing a run's recording (fleet.recording.format): the recorder process and the
in-process run alike.

Small chunks flushed about once a second bound what a killed recorder loses. Each file
carries the id of the run directory it was written in (metadata `segment`), so a file of
another run in the directory is refused by name, never merged (fleet.recording.reader).
"""

from __future__ import annotations

import json
import math
import platform
import sys
from collections.abc import Callable
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import IO, Any

from mcap.writer import CompressionType, Writer

from fleet import __version__
from fleet.mission.battery import start_piles
from fleet.mission.heat004 import history_heat
from fleet.mission.order_work import mission_battery, mission_charges, mission_orders
from fleet.mission.spec import Mission, MissionKind
from fleet.params import LOOKAHEAD_S
from fleet.planning.trajectory import Pose
from fleet.recording.format import (
    LAYOUT_ATTACHMENT,
    MESSAGE_ENCODING,
    NS,
    PROFILE,
    RUN_METADATA,
    SEGMENT_METADATA,
)
from fleet.recording.rundir import run_id_of
from fleet.recording.schemas import json_schema
from fleet.wire.protocol import MissionInfo
from fleet.wire.topics import message_type
from fleet.world.layout import Layout
from fleet.world.layout_file import layout_source

CHUNK_BYTES = 64 * 1024  # small chunks: a crash loses at most the one being filled
MAX_NS = 2**63 - 1  # MCAP times are unsigned 64-bit; Foxglove's are signed


def _ns(seconds: float) -> int:
    """Seconds as MCAP nanoseconds; a time that does not fit (a forged one) becomes 0."""
    if not math.isfinite(seconds) or not 0 <= seconds <= MAX_NS / NS:
        return 0
    return round(seconds * NS)


def mission_info(mission: Mission, layout: Layout, vehicles: int, clock: str,
                 speed: float = 1.0, command: str = "") -> MissionInfo:
    """What a recording says about its run (the dispatcher publishes it): with this
    process's package versions and, without `command`, its command line."""
    versions = {"python": platform.python_version(), "zenoh": _package_version("eclipse-zenoh"),
                "mcap": _package_version("mcap")}
    if layout.floor is not None:  # seed 004: its AGVs start on the parking places, in order
        parked = [Pose(layout.floor.cell(xy), 0) for xy in layout.floor.parking[:vehicles]]
        heat = history_heat(layout.floor, vehicles, mission.orders, mission.seed) \
            if mission.heat else {}
        return MissionInfo(layout.name, layout_source(mission.layout), mission.kind.value,
                           mission.strategy.value, vehicles, mission.seed, clock, speed,
                           [str(p) for p in parked], command or " ".join(sys.argv), versions,
                           mission.orders, heat_w=mission.heat,
                           heat=[(x, y, v) for (x, y), v in sorted(heat.items())])
    starts = list(mission.starts or layout.vehicle_starts)[:vehicles]
    if mission.kind is MissionKind.ORDERS and not mission.starts:
        starts = [Pose(p.cell, 0) for p in start_piles(layout, vehicles)]
    orders = mission.kind is MissionKind.ORDERS
    released = [o.shelf for o in mission_orders(mission, layout)] if orders else []
    _, battery = mission_battery(mission)
    return MissionInfo(layout.name, layout_source(mission.layout), mission.kind.value,
                       mission.strategy.value, vehicles, mission.seed, clock, speed,
                       [str(p) for p in starts], command or " ".join(sys.argv), versions,
                       mission.orders, mission.order_area, released,
                       list(mission_charges(mission, vehicles)) if orders else [],
                       battery.drain_per_s, battery.charge_per_s, battery.threshold,
                       lookahead=None if math.isinf(mission.lookahead) else mission.lookahead)


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
    if info.lookahead != LOOKAHEAD_S:
        data["lookahead"] = repr(info.lookahead_s)
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

    def write_json(self, topic: str, text: str, schema_name: str, schema: str,
                   log_ns: int, sim_time: float) -> None:
        """A JSON message on a channel of its own with its JSON schema (a VDA 5050 message,
        so Foxglove shows it)."""
        channel = self._channel(topic, "json", lambda: self._schema(
            schema_name, "jsonschema", lambda: schema.encode()))
        self._writer.add_message(channel, log_time=log_ns, data=text.encode(),
                                 publish_time=_ns(sim_time))

    def describe(self, info: MissionInfo) -> None:
        """The run's metadata and its layout attachment, once."""
        if self.described:
            return
        self._writer.add_metadata(RUN_METADATA, run_metadata(info))
        self._writer.add_attachment(0, 0, LAYOUT_ATTACHMENT, "application/toml",
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
