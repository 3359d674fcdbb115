"""The messages a VDA 5050 2.0.0 vehicle sends, built from what the gateway knows, pure: the
header (headerId counted per topic, 6.2), `connection`, `factsheet` (6.15), `state` (6.10)
and `visualization` (6.13). The gateway validates each against the official schema before it
goes out. Each builder gives a message's body; `Headers.next` its header."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from fleet.params import ManeuverTimes
from fleet.vda5050.orders import INSTANT_ACTIONS, Position
from fleet.vehicles.agv import SPEED_CELLS_PER_S
from fleet.vehicles.kind import VehicleKind

VERSION = "2.0.0"


def timestamp(unix: float) -> str:
    """ISO 8601 in UTC with milliseconds, as the schema's examples write it."""
    return datetime.fromtimestamp(unix, UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def serial_number(kind: str, vehicle: int) -> str:
    """The vehicle's serialNumber, its kind's name and its number: forklift-1, agv-3."""
    return f"{kind}-{vehicle}"


@dataclass
class Headers:
    """One vehicle's header: manufacturer, serial number and a headerId per topic, each
    counting up by one from 0 (6.2)."""

    manufacturer: str
    serial_number: str
    counts: dict[str, int] = field(default_factory=dict)

    def next(self, topic: str, unix: float) -> dict[str, Any]:
        header_id = self.counts.get(topic, -1) + 1
        self.counts[topic] = header_id
        return {"headerId": header_id, "timestamp": timestamp(unix), "version": VERSION,
                "manufacturer": self.manufacturer, "serialNumber": self.serial_number}


@dataclass(frozen=True)
class VehicleType:
    """What the factsheet and the states say a kind of vehicle is, in VDA 5050's terms."""

    kinematic: str  # agvKinematic
    agv_class: str  # agvClass
    navigation: str  # navigationTypes' first
    load_position: str  # where a load sits (loadSpecification, a state's loads)
    works: str  # what a pick takes, for the actions' descriptions
    puts: str  # where a drop puts it
    acceleration: Callable[[float], float]  # m/s^2, of the cell size
    speed: Callable[[int, float], float]  # m/s at a state's speed level, of the cell size


_FORKLIFT = ManeuverTimes()
# A forklift steers its rear wheel (THREEWHEEL) and reaches mid speed over one cell in T2.
# Seed 002's AGV moves to its eight neighbours without turning (OMNI) along the lanes, at one
# constant speed it takes up at once: the seed gives no acceleration, so the factsheet says
# 10 m/s^2, speed reached within 0.1 s, the states' own period.
VEHICLE_TYPES: dict[str, VehicleType] = {
    "forklift": VehicleType("THREEWHEEL", "FORKLIFT", "AUTONOMOUS", "forks",
                            "the goods of the stack or station the node faces",
                            "on the stack or station the node faces",
                            lambda cell: 2 * cell / _FORKLIFT.T2 ** 2,
                            lambda level, cell: {1: cell / _FORKLIFT.T3,
                                                 2: cell / _FORKLIFT.T5}.get(level, 0.0)),
    "agv": VehicleType("OMNI", "CARRIER", "VIRTUAL_LINE_GUIDED", "lift",
                       "the shelf of the slot the AGV stands in",
                       "(the shelf) down in the slot the AGV stands in", lambda cell: 10.0,
                       lambda level, cell: SPEED_CELLS_PER_S * cell if level else 0.0),
}


def factsheet(kind: VehicleKind, cell_size: float,
              state_interval_s: float, visualization_interval_s: float) -> dict[str, Any]:
    """What the vehicle is and does (6.15), from its kind: how it drives on the grid, its
    outline, its top speed, pick and drop on nodes, the instant actions."""
    outline, top, of = kind.outline, kind.max_speed_mps, VEHICLE_TYPES[kind.name]
    accel = round(of.acceleration(cell_size), 3)
    node_action = [{"key": "stationType", "valueDataType": "STRING", "isOptional": True,
                    "description": "ignored: the node says what is worked"}]
    actions = [
        {"actionType": "pick", "actionScopes": ["NODE"], "actionParameters": node_action,
         "actionDescription": f"take {of.works}"},
        {"actionType": "drop", "actionScopes": ["NODE"], "actionParameters": node_action,
         "actionDescription": f"put the goods {of.puts}"},
        *({"actionType": a, "actionScopes": ["INSTANT"]} for a in INSTANT_ACTIONS),
    ]
    return {
        "typeSpecification": {
            "seriesName": f"fleet-emulator-{kind.name}",
            "seriesDescription": f"an emulated {kind.noun} (forklift fleet emulator)",
            "agvKinematic": of.kinematic, "agvClass": of.agv_class, "maxLoadMass": 1000.0,
            "localizationTypes": ["GRID"], "navigationTypes": [of.navigation]},
        "physicalParameters": {
            "speedMin": 0.0, "speedMax": round(top, 3), "accelerationMax": accel,
            "decelerationMax": accel, "heightMax": 2.0,
            "width": round(outline.width, 3), "length": round(outline.front + outline.rear, 3)},
        "protocolLimits": {
            "maxStringLens": {}, "maxArrayLens": {},
            "timing": {"minOrderInterval": 0.1, "minStateInterval": 0.1,
                       "defaultStateInterval": state_interval_s,
                       "visualizationInterval": visualization_interval_s}},
        "protocolFeatures": {"optionalParameters": [], "agvActions": actions},
        "agvGeometry": {},
        "loadSpecification": {"loadPositions": [of.load_position]},
    }


@dataclass(frozen=True)
class Motion:
    """Where the vehicle is and how it moves (from its last state heard)."""

    position: Position
    driving: bool
    speed_mps: float = 0.0
    battery: float | None = None  # % (None: no battery is modelled)
    direction: float | None = None  # of travel, radians (None: along the heading)
    charging: bool = False


def agv_position(position: Position, map_id: str) -> dict[str, Any]:
    return {"x": position.x, "y": position.y,
            "theta": math.remainder(position.theta, math.tau), "mapId": map_id,
            "positionInitialized": True}


def velocity(motion: Motion) -> dict[str, float]:
    """At the speed level's speed along the heading (a forklift does not slide) or the
    direction of travel (an AGV that moves without turning)."""
    theta = motion.position.theta if motion.direction is None else motion.direction
    return {"vx": round(motion.speed_mps * math.cos(theta), 3),
            "vy": round(motion.speed_mps * math.sin(theta), 3), "omega": 0.0}


def state(order_fields: dict[str, Any], motion: Motion, map_id: str,
          load_position: str | None, information: list[dict[str, Any]]) -> dict[str, Any]:
    """6.10: the order book's fields and the vehicle's motion, load (where it sits, None:
    unloaded), battery and safety.
    Always AUTOMATIC, no emergency stop (faults are the emulator's, not the master's)."""
    out = {
        **order_fields,
        "agvPosition": agv_position(motion.position, map_id),
        "velocity": velocity(motion),
        "driving": motion.driving,
        "loads": [{"loadPosition": load_position}] if load_position else [],
        "batteryState": {"batteryCharge": 100.0 if motion.battery is None else motion.battery,
                         "charging": motion.charging},
        "operatingMode": "AUTOMATIC",
        "information": information,
        "safetyState": {"eStop": "NONE", "fieldViolation": False},
    }
    return out


def visualization(motion: Motion, map_id: str) -> dict[str, Any]:
    return {"agvPosition": agv_position(motion.position, map_id),
            "velocity": velocity(motion)}
