"""`fleet vda5050 map|check|gateway`: the emulated fleet as VDA 5050 vehicles (docs/vda5050.md)."""

from __future__ import annotations

import argparse
import json

from fleet.commands.output import write_or_print
from fleet.errors import UserError
from fleet.runtime.argtypes import layout_arg, text_file, writable_file
from fleet.runtime.process_configs import GatewayConfig
from fleet.vda5050 import TOPICS
from fleet.world.layout_file import load_layout


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("vda5050", help="the fleet as VDA 5050 vehicles: the map a master "
                       "builds orders on, the gateway that takes them",
                       description="The emulated forklifts as VDA 5050 2.0.0 vehicles "
                       "(docs/vda5050.md).")
    which = p.add_subparsers(dest="vda5050_command", required=True, metavar="ACTION")
    export = which.add_parser("map", help="export a layout's nodes and edges as JSON",
                              description="Write a forklift layout's VDA 5050 map as JSON: "
                              "mapId (the layout's name), its nodes (the poses forklifts "
                              "work at: parks, station docks, each side of each stack, with "
                              "stable ids and nodePosition in metres and radians) and edges "
                              "(parks and stations to every stack, parks to stations, both "
                              "ways), so a master can build orders.")
    export.add_argument("layout", type=layout_arg, help="built-in layout name or TOML file")
    export.add_argument("--out", type=writable_file, metavar="FILE",
                        help="write here (default: print to stdout)")
    export.add_argument("--lif", action="store_true",
                        help="as a VDMA LIF file (Layout Interchange Format) instead, for a "
                        "master control that imports layouts")
    export.set_defaults(handler=run_map)
    check = which.add_parser("check", help="check a VDA 5050 message against the official "
                             "schema, and an order against a layout's map",
                             description="Check a VDA 5050 2.0.0 message (a JSON file) against "
                             "its topic's official schema, saying where it is wrong; with "
                             "--layout, an order is also put to a forklift standing at its "
                             "first node, which accepts it or rejects it with the error the "
                             "spec names (unknown nodes, sequence ids, actions a forklift "
                             "lacks, ...). Exit 1 if the message is invalid or rejected.")
    check.add_argument("topic", choices=TOPICS, metavar="TOPIC",
                       help=f"the message's topic: {', '.join(TOPICS)}")
    check.add_argument("file", type=text_file, help="the message, a JSON file")
    check.add_argument("--layout", type=layout_arg,
                       help="for an order: the forklift layout whose map it is built on "
                       "(default: none, the message is checked against the schema only)")
    check.set_defaults(handler=run_check)
    gateway = which.add_parser("gateway", help=GatewayConfig.SUMMARY,
                               description=GatewayConfig.DESCRIPTION)
    GatewayConfig.add_arguments(gateway)
    gateway.set_defaults(handler=run_gateway)


def run_gateway(args: argparse.Namespace) -> int:
    from fleet.commands.processes import serve

    return serve(GatewayConfig.from_args(args))


def run_map(args: argparse.Namespace) -> int:
    from fleet.vda5050.map import vda_map

    if args.lif:
        return run_lif(args)
    found = vda_map(load_layout(args.layout))
    if not write_or_print(json.dumps(found, indent=1) + "\n", args.out):
        return 0
    print(f"wrote {args.out}: map {found['mapId']}, {len(found['nodes'])} nodes, "
          f"{len(found['edges'])} edges")
    return 0


def run_lif(args: argparse.Namespace) -> int:
    from vdma_lif.parser import LIFParser

    from fleet.vda5050.lif import lif_collection

    collection = lif_collection(load_layout(args.layout))
    if not write_or_print(LIFParser.to_json(collection, indent=1) + "\n", args.out):
        return 0
    (layout,) = collection.layouts
    print(f"wrote {args.out}: LIF {collection.meta_information.lif_version} layout "
          f"{layout.layout_id}, {len(layout.nodes)} nodes, {len(layout.edges)} edges, "
          f"{len(layout.stations)} stations")
    return 0


def run_check(args: argparse.Namespace) -> int:
    from fleet.vda5050.map import nodes
    from fleet.vda5050.orders import OrderBook
    from fleet.vda5050.schemas import InvalidMessage, validate

    on_map = args.layout is not None and args.topic == "order"
    known = {n.node_id: n for n in nodes(load_layout(args.layout))} if on_map else {}
    try:
        message = json.loads(args.file.read_text())
    except json.JSONDecodeError as exc:
        raise UserError(f"{args.file}: not JSON: {exc}") from None
    if not isinstance(message, dict):
        raise UserError(f"{args.file}: a VDA 5050 message is a JSON object, not "
                        f"{type(message).__name__}")
    try:
        validate(args.topic, message)
    except InvalidMessage as exc:
        print(exc)
        return 1
    print(f"{args.file}: a valid {args.topic} message")
    if not on_map:
        return 0
    first = min(message["nodes"], key=lambda n: n["sequenceId"])["nodeId"] \
        if message["nodes"] else None
    decision = OrderBook().receive(message, known, at=known.get(first or ""))
    who = f"a forklift standing at {first}" if first else "a forklift"
    if not decision.accepted:
        error = decision.error or {}
        print(f"{who} rejects it: {error.get('errorType')}: {error.get('errorDescription')}")
        return 1
    print(f"{who} accepts it: {len(decision.legs)} edges released to drive")
    return 0
