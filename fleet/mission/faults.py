"""Fault scenarios as data (docs/faults.md): a TOML file listing faults at simulation times.

A scenario is pure data: loading checks every field and names the fault and the field that is
wrong. What each kind does to a run lives elsewhere (the injector in `fleet run` applies the
process faults, the dispatcher detects and recovers, fleet/mission/freeze.py decides who stops).
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass
from enum import StrEnum
from importlib import resources
from pathlib import Path

from fleet.errors import UserError
from fleet.planning.geometry import Cell
from fleet.world.lanes import floor_cells
from fleet.world.layout import Layout
from fleet.world.layout_file import parse_cells


class ScenarioError(UserError):
    """A scenario file that cannot be used; the message names the fault and the field."""


class FaultKind(StrEnum):
    KILL_VEHICLE = "kill_vehicle"
    STALL_VEHICLE = "stall_vehicle"
    CUT_LINK = "cut_link"
    CUT_HOST = "cut_host"
    SLOW_PLANNER = "slow_planner"
    KILL_SERVICE = "kill_service"
    CLOSE_ZONE = "close_zone"
    VEHICLE_BREAKDOWN = "vehicle_breakdown"


SERVICES = ("reservation", "dispatcher", "recorder")
# The kinds that stop forklifts until their fault ends.
STOPS = (FaultKind.KILL_VEHICLE, FaultKind.STALL_VEHICLE, FaultKind.CUT_LINK,
         FaultKind.CUT_HOST, FaultKind.VEHICLE_BREAKDOWN)


@dataclass(frozen=True)
class KindSpec:
    summary: str
    required: tuple[str, ...]
    optional: tuple[str, ...] = ()


KINDS: dict[FaultKind, KindSpec] = {
    FaultKind.KILL_VEHICLE: KindSpec(
        "SIGKILL the forklift's agent process; with `duration`, start a new one that many "
        "sim seconds later", ("vehicle",), ("duration",)),
    FaultKind.STALL_VEHICLE: KindSpec(
        "SIGSTOP the agent process for `duration` sim seconds, then SIGCONT",
        ("vehicle", "duration")),
    FaultKind.CUT_LINK: KindSpec(
        "the agent loses its zenoh link silently for `duration` sim seconds; its process "
        "keeps running", ("vehicle", "duration")),
    FaultKind.CUT_HOST: KindSpec(
        "a run on several hosts (--hosts): the link between `host` and the first host goes "
        "silent for `duration` sim seconds, every forklift there cut off at once",
        ("host", "duration")),
    FaultKind.SLOW_PLANNER: KindSpec(
        "the agent's planning takes `factor` times longer for `duration` sim seconds",
        ("vehicle", "duration", "factor")),
    FaultKind.KILL_SERVICE: KindSpec(
        "SIGKILL the reservation service, the dispatcher or the recorder and start "
        "a new one `downtime` wall seconds later (default 1)", ("service",), ("downtime",)),
    FaultKind.CLOSE_ZONE: KindSpec(
        "cells unusable (a spill) for `duration` sim seconds: `cells` as in layouts, e.g. "
        "\"10,4..12,5\"", ("cells", "duration")),
    FaultKind.VEHICLE_BREAKDOWN: KindSpec(
        "the forklift stops (its process alive) and reports it; repaired after `duration` "
        "sim seconds if given", ("vehicle",), ("duration",)),
}
VEHICLE_KINDS = {k for k, spec in KINDS.items() if "vehicle" in spec.required}
DEFAULT_DOWNTIME_S = 1.0
# A killed service's clients retry their requests for 15 s (Requester.retry_s in
# fleet/runtime/bus.py): a longer downtime would fail the run, not test its recovery.
MAX_DOWNTIME_S = 10.0
# A fault the dispatcher has not seen this many wall seconds after it happened was not
# detected: the run fails (and `fleet bench faults` counts no sighting later than that).
DETECT_TIMEOUT_S = 20.0


@dataclass(frozen=True)
class Fault:
    kind: FaultKind
    at: float  # sim seconds
    vehicle: int | None = None
    duration: float | None = None  # sim seconds the fault lasts (None: for good)
    factor: float = 1.0
    service: str | None = None
    downtime: float = DEFAULT_DOWNTIME_S  # wall seconds a killed service stays down
    cells: tuple[Cell, ...] = ()
    host: str | None = None  # a host of a run on several (fleet/runtime/hosts.py)

    @property
    def until(self) -> float:
        """When the fault ends (infinity: it does not)."""
        return math.inf if self.duration is None else self.at + self.duration

    @property
    def over(self) -> float:
        """When what it strikes is free of it (a killed service's downtime counted as sim
        seconds: it is wall time, and no second fault may strike the service before)."""
        return self.at + self.downtime if self.kind is FaultKind.KILL_SERVICE else self.until

    def describe(self, noun: str = "forklift") -> str:
        """The fault in a few words (`noun`: what the run's vehicles are called)."""
        who = f"{noun} {self.vehicle}" if self.vehicle is not None else \
            f"host {self.host}" if self.host is not None else \
            self.service or f"{len(self.cells)} cells"
        span = f" for {self.duration:g} s" if self.duration is not None else ""
        return f"{self.kind.value} of {who} at {self.at:g} s{span}"


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    faults: tuple[Fault, ...]

    def instants(self) -> list[float]:
        """Every sim time at which a fault starts or ends: the fast clock stops there."""
        times = {f.at for f in self.faults} | {f.until for f in self.faults}
        return sorted(t for t in times if math.isfinite(t))


def builtin_scenarios() -> list[str]:
    """The shipped scenarios' names (a layout may ship its own version of each)."""
    files = resources.files("fleet.mission.scenarios")
    return sorted(p.name[:-5] for p in files.iterdir() if p.name.endswith(".toml"))


def shipped_source(name: str, layout: str | None = None) -> str:
    """A shipped scenario's TOML: the layout's own version where it ships one (its faults
    name its vehicles and cells: `scenarios/<layout>/<name>.toml`), else the one written for
    seed 000's paper warehouse."""
    files = resources.files("fleet.mission.scenarios")
    own = files.joinpath(layout, f"{name}.toml") if layout else None
    return (own if own is not None and own.is_file() else
            files.joinpath(f"{name}.toml")).read_text()


def load_scenario(name_or_path: str | Path, layout: str | None = None) -> Scenario:
    """A shipped scenario by name (`kill_vehicle`, `mixed`, ...; for `layout`, its own
    version where it has one) or a TOML file by path."""
    text = str(name_or_path)
    if text in builtin_scenarios():
        return parse_scenario(shipped_source(text, layout), f"scenario {text}")
    path = Path(text)
    if not path.is_file():
        raise ScenarioError(f"scenario {text!r} is neither a shipped scenario "
                            f"({', '.join(builtin_scenarios())}) nor a file")
    return parse_scenario(path.read_text(), text)


def parse_scenario(source: str, where: str) -> Scenario:
    try:
        data = tomllib.loads(source)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{where}: not valid TOML: {exc}") from None
    unknown = sorted(set(data) - {"name", "description", "fault"})
    if unknown:
        raise ScenarioError(f"{where}: unknown key {unknown[0]!r} (expected name, "
                            f"description and [[fault]] tables)")
    name = _text(data.get("name", Path(where).stem), f"{where}: name")
    description = _text(data.get("description", ""), f"{where}: description")
    raw = data.get("fault", [])
    if not isinstance(raw, list) or not all(isinstance(f, dict) for f in raw):
        raise ScenarioError(f"{where}: faults must be [[fault]] tables")
    faults = tuple(_fault(f, f"{where}: fault {i + 1}") for i, f in enumerate(raw))
    check_overlaps(faults, where)
    return Scenario(name, description, faults)


def _fault(data: dict, where: str) -> Fault:
    kind_text = data.get("kind")
    try:
        kind = FaultKind(kind_text)
    except ValueError:
        raise ScenarioError(f"{where}: kind {kind_text!r} is not one of "
                            f"{', '.join(k.value for k in FaultKind)}") from None
    spec = KINDS[kind]
    where = f"{where} ({kind.value})"
    allowed = {"kind", "at", *spec.required, *spec.optional}
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise ScenarioError(f"{where}: unknown field {unknown[0]!r} (it takes "
                            f"{', '.join(sorted(allowed - {'kind'}))})")
    missing = [k for k in ("at", *spec.required) if k not in data]
    if missing:
        raise ScenarioError(f"{where}: missing field {missing[0]!r}")
    fields: dict = {"kind": kind, "at": _seconds(data["at"], f"{where}: at", zero=True)}
    if "vehicle" in data:
        vehicle = data["vehicle"]
        if not isinstance(vehicle, int) or isinstance(vehicle, bool) or vehicle < 1:
            raise ScenarioError(f"{where}: vehicle must be a forklift number (1, 2, ...), "
                                f"not {vehicle!r}")
        fields["vehicle"] = vehicle
    if "duration" in data:
        fields["duration"] = _seconds(data["duration"], f"{where}: duration")
    if "downtime" in data:
        fields["downtime"] = _seconds(data["downtime"], f"{where}: downtime", zero=True)
        if fields["downtime"] > MAX_DOWNTIME_S:
            raise ScenarioError(f"{where}: downtime must be at most {MAX_DOWNTIME_S:g} wall "
                                f"seconds (the clients of a killed service retry for 15 s), "
                                f"not {fields['downtime']:g}")
    if "factor" in data:
        factor = _number(data["factor"], f"{where}: factor")
        if not 1.0 <= factor <= 1000.0:
            raise ScenarioError(f"{where}: factor must be between 1 and 1000, not {factor}")
        fields["factor"] = factor
    if "service" in data:
        if data["service"] not in SERVICES:
            raise ScenarioError(f"{where}: service {data['service']!r} is not one of "
                                f"{', '.join(SERVICES)}")
        fields["service"] = data["service"]
    if "cells" in data:
        fields["cells"] = _cells(data["cells"], f"{where}: cells")
    if "host" in data:
        fields["host"] = _text(data["host"], f"{where}: host")
    return Fault(**fields)


def _text(value: object, where: str) -> str:
    if not isinstance(value, str):
        raise ScenarioError(f"{where} must be a string, not {value!r}")
    return value


def _number(value: object, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or \
            not math.isfinite(value):
        raise ScenarioError(f"{where} must be a finite number, not {value!r}")
    return float(value)


def _seconds(value: object, where: str, zero: bool = False) -> float:
    seconds = _number(value, where)
    if seconds < 0 or (seconds == 0 and not zero) or seconds > 1e6:
        raise ScenarioError(f"{where} must be {'at least 0' if zero else 'positive'} and at "
                            f"most 1e6 seconds, not {value!r}")
    return seconds


def _cells(value: object, where: str) -> tuple[Cell, ...]:
    items = [value] if isinstance(value, str) else value
    if not isinstance(items, list) or not items or \
            not all(isinstance(v, str) for v in items):
        raise ScenarioError(f"{where} must be a cell \"c,r\", a range \"c0,r0..c1,r1\" or a "
                            f"list of them, not {value!r}")
    cells: list[Cell] = []
    for text in items:
        try:
            cells += parse_cells(text, where)
        except UserError as exc:
            raise ScenarioError(str(exc)) from None
    if len(cells) > 10_000:
        raise ScenarioError(f"{where}: {len(cells)} cells is more than a zone can be")
    return tuple(dict.fromkeys(cells))


def check_overlaps(faults: tuple[Fault, ...], where: str) -> None:
    """One fault at a time per forklift, per service and per host: a second one on top of the
    first would have no clear meaning (kill a stalled process?)."""
    seen: dict[object, tuple[int, Fault]] = {}
    order = sorted(enumerate(faults), key=lambda p: p[1].at)
    for i, fault in order:
        who = fault.vehicle if fault.kind in VEHICLE_KINDS else fault.service or \
            (f"host {fault.host}" if fault.host else None)
        if who is None:
            continue
        if who in seen:
            j, before = seen[who]
            if fault.at <= before.over:
                raise ScenarioError(f"{where}: fault {i + 1} ({fault.describe()}) starts "
                                    f"before fault {j + 1} ({before.describe()}) is over")
        seen[who] = (i, fault)


def scenario_toml(scenario: Scenario, header: str = "") -> str:
    """The scenario as a file `load_scenario` reads back into an equal scenario (every time
    written exactly, as Python writes floats); `header` goes first, as comment lines."""
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    lines += [f"name = {_quoted(scenario.name)}",
              f"description = {_quoted(scenario.description)}"]
    for fault in scenario.faults:
        lines += ["", "[[fault]]", f"kind = {_quoted(fault.kind.value)}", f"at = {fault.at!r}"]
        spec = KINDS[fault.kind]
        fields = {"vehicle": fault.vehicle, "duration": fault.duration,
                  "factor": fault.factor, "service": fault.service,
                  "downtime": fault.downtime, "cells": fault.cells, "host": fault.host}
        for key in (*spec.required, *spec.optional):
            value = fields[key]
            if value is None:
                continue  # an optional field left out: its default
            if key == "cells":
                lines.append("cells = [" + ", ".join(f'"{c},{r}"' for c, r in value) + "]")
            elif isinstance(value, str):
                lines.append(f"{key} = {_quoted(value)}")
            else:
                lines.append(f"{key} = {value!r}")
    return "\n".join(lines) + "\n"


def _quoted(text: str) -> str:
    """A TOML basic string (JSON's escapes are TOML's for these)."""
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")


def check_against(scenario: Scenario, layout: Layout, vehicles: int) -> None:
    """Refuse faults that name a forklift the run does not have, cells off the map (on a
    lane layout, off the floor its AGVs drive on: lanes, access cells, slots, stations and
    piles), or a kill of the dispatcher at the instant a forklift goes down (the injector
    applies both at one tick, and the dispatcher dies before it sees the forklift go: its
    successor could not tell where it stopped)."""
    floor = floor_cells(layout) if layout.has_lanes else None
    noun = layout.vehicle_kind.noun
    for i, fault in enumerate(scenario.faults):
        where = f"scenario {scenario.name}: fault {i + 1} ({fault.describe(noun)})"
        if fault.vehicle is not None and fault.vehicle > vehicles:
            raise ScenarioError(f"{where}: the run has {noun}s 1 to {vehicles}")
        if fault.kind is FaultKind.KILL_SERVICE and fault.service == "dispatcher":
            for j, other in enumerate(scenario.faults):
                if other.kind in STOPS and other.at == fault.at:
                    raise ScenarioError(
                        f"{where}: fault {j + 1} ({other.describe(noun)}) starts at the same "
                        f"instant, and the dispatcher would die before it saw the {noun} "
                        f"stop: give them different times")
        off = [c for c in fault.cells if not (0 <= c[0] < layout.cols and
                                              0 <= c[1] < layout.rows)]
        if off:
            raise ScenarioError(f"{where}: cell {off[0]} is off the {layout.cols}x"
                                f"{layout.rows} map")
        off = [c for c in fault.cells if floor is not None and c not in floor]
        if off:
            raise ScenarioError(f"{where}: cell {off[0]} is off the floor of layout "
                                f"{layout.name} (no lane, access cell, slot, station or "
                                f"pile: a zone closes floor its AGVs drive on)")

