"""The map a VDA 5050 master builds orders on: a layout's places as nodes with stable ids and
poses, and the drives between them as edges (`fleet vda5050 map LAYOUT`).

On a forklift layout (seed 000) nodes are the poses a forklift stands at to work:

- `park-N`: the N-th start pose (where a fleet of N or more forklifts parks);
- `station-NAME`: the station's dock, the pose that works it;
- `stack-CLUSTER-INDEX-H`: a pose whose forks point at that stack from side H (E N W S),
  one node for each side a forklift can stand on with its whole body on the empty floor.

On a lane layout (seed 002) they are the places an AGV drives onto, each its own cell:
`slot-NAME` (a shelf's home, `NAME` its `s-COL-ROW`), `station-NAME` (a packing station),
`pile-NAME` (a charging pile, where the AGVs start).

Positions are the vehicle's reference point at rest in the layout's metres (its origin is
the centre of cell (0, 0)), theta in radians from +x, counter-clockwise, as the Foxglove views
draw it. Edges are the drives a warehouse's work is made of, both ways: on a forklift layout
every park and station node to every stack node and every park to every station; on a lane
layout every station and pile to every slot and every pile to every station. A vehicle plans
each edge itself against the reservation store (a forklift anywhere on the floor, an AGV on
the lanes), so an order may join any two nodes: the edges say what the work drives, not the
only ways.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any

from fleet.errors import UserError
from fleet.planning.geometry import Cell
from fleet.planning.maneuvers import HEADINGS
from fleet.planning.trajectory import Pose
from fleet.vehicles.agv import EAST
from fleet.world.layout import Layout

PARK, STATION, STACK = "park", "station", "stack"
SLOT, PACKING, PILE = "slot", "packing", "pile"  # a lane layout's
HOLDS_GOODS = frozenset({STACK, SLOT})  # places whose goods a pick takes and a drop puts
HANDLED = HOLDS_GOODS | {STATION}  # places a vehicle picks and drops at (a forklift station
# gives and takes goods without end; a packing station works the shelf the AGV stands with)


@dataclass(frozen=True)
class Node:
    node_id: str
    place: str  # park, station or stack; slot, packing or pile
    pose: Pose
    x: float
    y: float
    theta: float
    of: str  # what it works: the station's name, the stack's cluster-index, the slot's or
    # pile's name, or ""
    cell: Cell | None = None  # the cell whose goods a pick or drop there moves (HOLDS_GOODS)


def at_rest(layout: Layout, pose: Pose) -> tuple[float, float, float]:
    """Where a vehicle standing at `pose` is, x and y in the layout's metres and theta in
    radians: as the vehicles' states say it (fleet/mission/driving.py)."""
    at, (ox, oy) = layout.vehicle_kind.at_rest(pose), layout.origin
    return round(at.x + ox, 6), round(at.y + oy, 6), _theta(at.theta)


def nodes(layout: Layout) -> list[Node]:
    """The layout's nodes: parks first, then stations, then stacks in fill order; on a lane
    layout stations, slots, then piles."""
    if layout.floor is not None:
        raise UserError(f"layout {layout.name} is a seed-004 floor: its lifting AGVs are not "
                        f"VDA 5050 vehicles yet (docs/vda5050.md)")

    def node(node_id: str, place: str, pose: Pose, of: str = "", cell: Cell | None = None
             ) -> Node:
        return Node(node_id, place, pose, *at_rest(layout, pose), of, cell)

    if layout.has_lanes:
        return ([node(f"station-{p.name}", PACKING, Pose(p.cell, EAST), p.name)
                 for p in layout.packing]
                + [node(f"slot-{s.name}", SLOT, Pose(s.cell, EAST), s.name, s.cell)
                   for s in layout.slots]
                + [node(f"pile-{p.name}", PILE, Pose(p.cell, EAST), p.name)
                   for p in layout.piles])
    out = [node(f"park-{i}", PARK, pose) for i, pose in enumerate(layout.vehicle_starts, 1)]
    out += [node(f"station-{s.name}", STATION, s.dock, s.name) for s in layout.stations]
    for stack in layout.stacks:
        of = f"{stack.cluster}-{stack.index}"
        out += [node(f"stack-{of}-{HEADINGS[pose.heading]}", STACK, pose, of, stack.cell)
                for pose in layout.unload_poses(stack.cell)]
    return out


def _theta(theta: float) -> float:
    """In [-pi, pi] as the schema bounds it, rounded to 6 places (a rounded pi would pass
    it by 3e-7)."""
    return min(math.pi, max(-math.pi, round(math.remainder(theta, math.tau), 6)))


def edges(found: list[Node]) -> list[tuple[str, str]]:
    """(start node, end node) of each edge, both ways of each pair."""
    by_place = {place: [n.node_id for n in found if n.place == place]
                for place in (PARK, STATION, STACK, SLOT, PACKING, PILE)}
    # forklifts: parks and stations to stacks, parks to stations; AGVs: stations and piles
    # to slots, piles to stations
    pairs = itertools.chain(itertools.product(by_place[PARK] + by_place[STATION],
                                              by_place[STACK]),
                            itertools.product(by_place[PARK], by_place[STATION]),
                            itertools.product(by_place[PACKING] + by_place[PILE],
                                              by_place[SLOT]),
                            itertools.product(by_place[PILE], by_place[PACKING]))
    return [way for a, b in pairs for way in ((a, b), (b, a))]


def edge_id(start: str, end: str) -> str:
    return f"{start}>{end}"


def node_position(node: Node, map_id: str) -> dict[str, Any]:
    """The node's `nodePosition` as an order carries it (VDA 5050 2.0.0, 6.6)."""
    return {"x": node.x, "y": node.y, "theta": node.theta, "mapId": map_id,
            "allowedDeviationXY": 0.0, "allowedDeviationTheta": 0.0}


def released_order(order_id: str, update_id: int, stops: list[Node], map_id: str,
                   first_sequence: int = 0, last_actions: list[dict[str, Any]] | None = None
                   ) -> dict[str, Any]:
    """The body of an order (6.6, no header) along `stops`, every node and edge released,
    each node with its position, `last_actions` on the last node: what a master of ours (the
    dispatcher of --dispatch vda5050, the bench) sends."""
    def node(k: int, at: Node) -> dict[str, Any]:
        return {"nodeId": at.node_id, "sequenceId": first_sequence + 2 * k, "released": True,
                "nodePosition": node_position(at, map_id),
                "actions": list(last_actions or []) if k == len(stops) - 1 else []}

    return {"orderId": order_id, "orderUpdateId": update_id,
            "nodes": [node(k, at) for k, at in enumerate(stops)],
            "edges": [{"edgeId": edge_id(a.node_id, b.node_id),
                       "sequenceId": first_sequence + 2 * k + 1, "released": True,
                       "startNodeId": a.node_id, "endNodeId": b.node_id, "actions": []}
                      for k, (a, b) in enumerate(itertools.pairwise(stops))]}


def vda_map(layout: Layout) -> dict[str, Any]:
    """The map as JSON-ready data: `mapId` the layout's name, its nodes and edges."""
    found = nodes(layout)
    what, who = ("places AGVs drive onto", "An AGV") if layout.has_lanes else \
        ("poses forklifts work at", "A forklift")
    return {
        "mapId": layout.name,
        "description": f"Nodes are the {what}; positions in metres and radians in the "
                       "layout's frame (origin at the centre of cell (0, 0)). "
                       f"{who} plans every edge itself: an order may join any two nodes.",
        "cellSize": layout.cell_size,
        "nodes": [{"nodeId": n.node_id, "place": n.place, "pose": str(n.pose), "of": n.of,
                   "nodePosition": node_position(n, layout.name)} for n in found],
        "edges": [{"edgeId": edge_id(a, b), "startNodeId": a, "endNodeId": b}
                  for a, b in edges(found)],
    }
