"""`fleet vda5050 map`: the emulated fleet as VDA 5050 vehicles (docs/vda5050.md)."""

from __future__ import annotations

import argparse
import json

from fleet.commands.output import write_or_print
from fleet.runtime.argtypes import layout_arg, writable_file
from fleet.world.layout_file import load_layout


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("vda5050", help="the fleet as VDA 5050 vehicles: the map a master "
                       "builds orders on",
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
    export.set_defaults(handler=run_map)


def run_map(args: argparse.Namespace) -> int:
    from vda5050.map import vda_map

    found = vda_map(load_layout(args.layout))
    if not write_or_print(json.dumps(found, indent=1) + "\n", args.out):
        return 0
    print(f"wrote {args.out}: map {found['mapId']}, {len(found['nodes'])} nodes, "
          f"{len(found['edges'])} edges")
    return 0
