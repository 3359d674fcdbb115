"""`fleet faults list|show|check`: the fault kinds, the shipped scenarios, and a scenario
file's check before a run (docs/faults.md)."""

from __future__ import annotations

import argparse

from fleet.mission.faults import (
    KINDS,
    Scenario,
    builtin_scenarios,
    check_against,
    load_scenario,
    shipped_source,
)
from fleet.mission.faults004 import check_faults004, taken004
from fleet.runtime.args import fleet_of
from fleet.runtime.argtypes import layout_arg, positive_int, scenario_arg
from fleet.world.layout_file import load_layout


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("faults", help="fault kinds and scenarios for fleet run --faults",
                       description="Fault scenarios (docs/faults.md): TOML files listing "
                       "faults at simulation times, applied by fleet run --faults.")
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    listing = actions.add_parser("list", help="the fault kinds and the shipped scenarios",
                                 description="List the fault kinds with their fields, and the "
                                 "shipped scenarios with what each does.")
    show = actions.add_parser("show", help="print a shipped scenario (a start for your own)",
                              description="Print a shipped scenario's TOML, to copy and edit.")
    show.add_argument("scenario", choices=builtin_scenarios(), help="the scenario's name")
    for action in (listing, show):
        action.add_argument("--layout", default="paper", type=layout_arg,
                            help="the layout's own versions where it ships them (paper002 "
                            "does: its AGVs and lane cells; default paper)")
    check = actions.add_parser("check", help="check a scenario against a layout and fleet",
                               description="Check a scenario the way fleet run --faults "
                               "does before it starts anything: every field, and every "
                               "forklift and cell it names against the layout and fleet.")
    check.add_argument("scenario", type=scenario_arg,
                       help="a shipped scenario's name or a TOML file")
    check.add_argument("--layout", default="paper", type=layout_arg,
                       help="layout name or TOML file (default paper)")
    check.add_argument("--vehicles", type=positive_int,
                       help="fleet size (default: every start pose of the layout; on a lane "
                       "layout, the order mission's ten AGVs)")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    layout = load_layout(args.layout)
    if args.action == "list":
        print("fault kinds (fields besides `kind` and `at`, sim seconds unless said):")
        for kind, spec in KINDS.items():
            fields = ", ".join([*spec.required, *(f"[{o}]" for o in spec.optional)])
            print(f"  {kind.value:<18} {fields}")
            print(f"  {'':<18} {spec.summary}")
        print(f"shipped scenarios for {layout.name} (fleet run --faults NAME; fleet faults "
              f"show NAME):")
        for name in builtin_scenarios():
            scenario = load_scenario(name, layout.name)
            if layout.floor is not None and not _fits004(scenario):
                continue  # a kind a seed-004 run does not take
            print(f"  {name:<18} {scenario.description}")
        return 0
    if args.action == "show":
        print(shipped_source(args.scenario, layout.name), end="")
        return 0
    scenario = load_scenario(args.scenario, layout.name)
    vehicles = fleet_of(layout, args.vehicles)
    if layout.floor is not None:
        check_faults004(scenario.faults, layout.floor, vehicles, scenario.name)
    else:
        check_against(scenario, layout, vehicles)
    noun = "AGV" if layout.floor else layout.vehicle_kind.noun  # 004's kind is not built
    print(f"scenario {scenario.name}: {len(scenario.faults)} faults, fine for {layout.name} "
          f"with {vehicles} {'lifting ' if layout.floor else ''}{noun}s")
    for fault in sorted(scenario.faults, key=lambda f: f.at):
        print(f"  {fault.describe(noun)}")
    return 0


def _fits004(scenario: Scenario) -> bool:
    """Whether a seed-004 run takes every fault of the scenario."""
    return all(taken004(f) for f in scenario.faults)
