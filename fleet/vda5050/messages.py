"""The messages a VDA 5050 2.0.0 vehicle sends, built from what the gateway knows, pure: the
header (headerId counted per topic, 6.2), `connection`, `factsheet` (6.15), `state` (6.10)
and `visualization` (6.13). The gateway validates each against the official schema before it
goes out. Each builder gives a message's body; `Headers.next` its header."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from fleet.params import ManeuverTimes
from fleet.vda5050.orders import INSTANT_ACTIONS, Position
from fleet.vehicles.kind import VehicleKind

VERSION = "2.0.0"


def timestamp(unix: float) -> str:
    """ISO 8601 in UTC with milliseconds, as the schema's examples write it."""
    return datetime.fromtimestamp(unix, UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


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


def factsheet(kind: VehicleKind, cell_size: float,
              state_interval_s: float, visualization_interval_s: float) -> dict[str, Any]:
    """What the vehicle is and does (6.15), from its kind: a forklift that navigates freely on
    the grid, its outline, its top speed, pick and drop on nodes, the instant actions."""
    outline, top = kind.outline, kind.max_speed_mps
    t2 = ManeuverTimes().T2  # zero to mid speed over one cell
    accel = round(2 * cell_size / t2 ** 2, 3)
    node_action = [{"key": "stationType", "valueDataType": "STRING", "isOptional": True,
                    "description": "ignored: the node says what the forks work"}]
    actions = [
        {"actionType": "pick", "actionScopes": ["NODE"], "actionParameters": node_action,
         "actionDescription": "take the goods of the stack or station the node faces"},
        {"actionType": "drop", "actionScopes": ["NODE"], "actionParameters": node_action,
         "actionDescription": "put the goods on the stack or station the node faces"},
        *({"actionType": a, "actionScopes": ["INSTANT"]} for a in INSTANT_ACTIONS),
    ]
    return {
        "typeSpecification": {
            "seriesName": f"fleet-emulator-{kind.name}",
            "seriesDescription": f"an emulated {kind.noun} (forklift fleet emulator)",
            "agvKinematic": "THREEWHEEL", "agvClass": "FORKLIFT", "maxLoadMass": 1000.0,
            "localizationTypes": ["GRID"], "navigationTypes": ["AUTONOMOUS"]},
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
        "loadSpecification": {"loadPositions": ["forks"]},
    }


@dataclass(frozen=True)
class Motion:
    """Where the vehicle is and how it moves (from its last state heard)."""

    position: Position
    driving: bool
    speed_mps: float = 0.0
    battery: float | None = None  # % (None: no battery is modelled)


def agv_position(position: Position, map_id: str) -> dict[str, Any]:
    return {"x": position.x, "y": position.y,
            "theta": math.remainder(position.theta, math.tau), "mapId": map_id,
            "positionInitialized": True}


def velocity(motion: Motion) -> dict[str, float]:
    """Along the heading, at the speed level's speed (a forklift does not slide)."""
    theta = motion.position.theta
    return {"vx": round(motion.speed_mps * math.cos(theta), 3),
            "vy": round(motion.speed_mps * math.sin(theta), 3), "omega": 0.0}


def state(order_fields: dict[str, Any], motion: Motion, map_id: str,
          loaded: bool, information: list[dict[str, Any]]) -> dict[str, Any]:
    """6.10: the order book's fields and the vehicle's motion, load, battery and safety.
    Always AUTOMATIC, no emergency stop (faults are the emulator's, not the master's)."""
    out = {
        **order_fields,
        "agvPosition": agv_position(motion.position, map_id),
        "velocity": velocity(motion),
        "driving": motion.driving,
        "loads": [{"loadPosition": "forks"}] if loaded else [],
        "batteryState": {"batteryCharge": 100.0 if motion.battery is None else motion.battery,
                         "charging": False},
        "operatingMode": "AUTOMATIC",
        "information": information,
        "safetyState": {"eStop": "NONE", "fieldViolation": False},
    }
    return out


def visualization(motion: Motion, map_id: str) -> dict[str, Any]:
    return {"agvPosition": agv_position(motion.position, map_id),
            "velocity": velocity(motion)}
