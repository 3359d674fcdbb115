"""The VDA 5050 map of a layout as a VDMA LIF file (Layout Interchange Format, the layout a
master control imports), written with the `vdma-lif` package's models (generated from the LIF
schema): `fleet vda5050 map LAYOUT --lif`.

One layout, its id the layout's name (the `mapId` of every node); the nodes and edges of
`fleet.vda5050.map` for the layout's vehicle type (`forklift`, or `agv` on a lane layout),
each node with the heading the vehicle stands at there and the actions it takes there
(`pick` and `drop` at station docks and stack sides, or at shelf slots); every place a LIF
station, whose interaction nodes are its nodes (a stack's sides; the one node of a dock, a
slot, a packing station or a pile).
"""

from __future__ import annotations

from datetime import UTC, datetime

from vdma_lif.models import (
    BlockingType,
    Edge,
    LIFLayoutCollection,
    MetaInformation,
    NodePosition,
    Station,
    StationPosition,
    VehicleTypeEdgeProperty,
    VehicleTypeNodeProperty,
    VehicleTypeNodePropertyAction,
)
from vdma_lif.models import Layout as LifLayout
from vdma_lif.models import Node as LifNode

from fleet.vda5050.map import HANDLED, PARK, STACK, edge_id, edges, nodes
from fleet.world.layout import Layout

LIF_VERSION = "1.0.0"
CREATOR = "forklift-fleet emulator (fleet vda5050 map --lif)"


def lif_collection(layout: Layout, exported: datetime | None = None) -> LIFLayoutCollection:
    """The layout's map as one LIF layout, exported now (or at `exported`)."""
    found = nodes(layout)
    vehicle_type = layout.vehicle_kind.name

    def node(n) -> LifNode:
        acts = [VehicleTypeNodePropertyAction(kind, BlockingType.HARD)
                for kind in ("pick", "drop")] if n.place in HANDLED else []
        return LifNode(n.node_id, NodePosition(n.x, n.y),
                       [VehicleTypeNodeProperty(vehicle_type, acts or None, n.theta)],
                       map_id=layout.name, node_name=n.node_id)

    places: dict[str, list] = {}
    for n in found:
        if n.place != PARK:
            places.setdefault(f"{n.place}-{n.of}", []).append(n)
    stations = [Station([n.node_id for n in at], station_id,
                        station_name=f"{at[0].place} {at[0].of}",
                        station_position=StationPosition(at[0].x, at[0].y, at[0].theta)
                        if at[0].place != STACK else None)
                for station_id, at in places.items()]
    lif_edges = [Edge(edge_id=edge_id(a, b), start_node_id=a, end_node_id=b,
                      vehicle_type_edge_properties=[VehicleTypeEdgeProperty(vehicle_type)])
                 for a, b in edges(found)]
    lif_layout = LifLayout(lif_edges, layout.name, "1", [node(n) for n in found], stations,
                           layout_description=f"the emulator's {vehicle_type} layout: nodes "
                           f"are the places its vehicles work at; a vehicle plans every edge "
                           "itself",
                           layout_name=layout.name)
    meta = MetaInformation(CREATOR, exported or datetime.now(UTC), LIF_VERSION, layout.name)
    return LIFLayoutCollection([lif_layout], meta)
