"""Missions as data: what the fleet must do, on which layout, with which strategy and seed;
and the clock a run of them keeps."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum, StrEnum

from fleet.dispatching.decision import Strategy
from fleet.params import LOOKAHEAD_S
from fleet.planning.trajectory import Pose

# The kind a recording names for a run with no mission of ours (fleet run --dispatch
# external): a VDA 5050 master gave the orders (docs/vda5050.md).
EXTERNAL = "external"


class MissionKind(Enum):
    FILL = "fill"  # goods picked at stations, delivered to stacks in fill order
    EMPTY = "empty"  # goods fetched from stacks in reverse fill order, dropped at stations
    ORDERS = "orders"  # seed 002: shelves fetched to packing stations and put back in slots


STACK_KINDS = (MissionKind.FILL, MissionKind.EMPTY)  # seed 000's, on layouts with stacks


class ClockMode(StrEnum):
    """How sim time runs in a run of processes; the wire and the recordings carry the value."""

    FAST = "fast"  # discrete events: the clock jumps to each decision, deterministic
    REALTIME = "realtime"  # sim time = speed x wall time since the start


@dataclass(frozen=True)
class Mission:
    layout: str = "paper"
    kind: MissionKind = MissionKind.FILL
    strategy: Strategy = Strategy.ANN
    vehicles: int | None = None  # None: as many as the layout has start poses
    seed: int = 0
    starts: tuple[Pose, ...] = field(default=())  # empty: the layout's start poses
    orders: int = 0  # how many orders an order mission releases (drawn with `seed`)
    order_area: str = ""  # draw them only on this area's shelves ("lower-left": Figure 19)
    shelves: tuple[str, ...] = ()  # the orders given, each its shelf (then nothing is drawn)
    # Seed 002's batteries, as `fleet run --battery` gives them ("": the defaults):
    # fleet/mission/battery.py, `parse_battery`.
    battery: str = ""
    # Seed 004's heat cost: w_heat (0: off), on T_value from the mission's history run
    # (fleet/mission/heat004.py, `history_heat`).
    heat: float = 0.0
    # Algorithm 1's lookahead (fleet/params.py; inf: none), for fill and empty missions.
    lookahead: float = LOOKAHEAD_S
