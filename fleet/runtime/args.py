"""The flag groups several commands share: how a process reaches the bus (every process and
`fleet table`), and which mission to run with which weights (`fleet run` and the dispatcher).
Each group parses into a frozen value and renders back into the flags that give it, so whoever
starts a process (`fleet run`, the compose deployment) writes its command line from the same
value."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from fleet.dispatching.decision import Strategy
from fleet.errors import UserError
from fleet.mission.battery import BATTERY_KEYS
from fleet.mission.order_work import DEFAULT_ORDERS, order_fleet
from fleet.mission.orders004 import fleet004
from fleet.mission.spec import Mission, MissionKind
from fleet.params import LOOKAHEAD_S
from fleet.runtime.argtypes import (
    battery_arg,
    endpoint,
    integer,
    layout_arg,
    lookahead_arg,
    lookahead_text,
    non_negative_float,
    orders_arg,
    positive_float,
    positive_int,
    text_file,
)
from fleet.runtime.bus import DEFAULT_ROUTER, BusConfig
from fleet.world.layout import Layout
from fleet.world.reachability import fleet_size

CONNECT_TIMEOUT_S = 60.0  # a process started alone waits this long for its router


def add_bus_arguments(p: argparse.ArgumentParser,
                      connect_timeout_s: float = CONNECT_TIMEOUT_S) -> None:
    """The flags every process shares: which run, and how to reach the others."""
    p.add_argument("--run", default="default",
                   help="run name: the run's keys live under fleet/RUN/ (default default)")
    p.add_argument("--mode", choices=["client", "peer"], default="client",
                   help="zenoh mode (default client of a router)")
    p.add_argument("--connect", action="append", default=[], type=endpoint,
                   metavar="ENDPOINT", help=f"zenoh endpoint to connect to, e.g. "
                   f"tcp/HOST:PORT (default {DEFAULT_ROUTER}; repeatable)")
    p.add_argument("--listen", action="append", default=[], type=endpoint,
                   metavar="ENDPOINT", help="zenoh endpoint to listen on (default none; "
                   "repeatable)")
    p.add_argument("--connect-timeout", type=positive_float, default=connect_timeout_s,
                   metavar="SECONDS", help=f"give up when no router answers at --connect "
                   f"within this many seconds (default {connect_timeout_s:g})")
    p.add_argument("--user", default="", help="log in to a router that runs access control "
                   "as this principal (fleet run --secure makes one per process; default: "
                   "no login)")
    p.add_argument("--password-file", type=Path, metavar="FILE",
                   help="the password of --user, in a file (never on the command line; "
                   "default none)")


@dataclass(frozen=True)
class BusFlags:
    """How a process reaches the others, as its flags say (add_bus_arguments)."""

    run: str = "default"  # the run's keys live under fleet/RUN/
    mode: str = "client"
    connect: tuple[str, ...] = ()  # none: DEFAULT_ROUTER, unless the process listens
    listen: tuple[str, ...] = ()
    connect_timeout_s: float = CONNECT_TIMEOUT_S
    user: str = ""  # log in as this principal ...
    password_file: Path | None = None  # ... with the password in this file

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> BusFlags:
        return cls(args.run, args.mode, tuple(args.connect), tuple(args.listen),
                   args.connect_timeout, args.user, args.password_file)

    def argv(self) -> list[str]:
        """The flags that give these values (a default is left out)."""
        out = ["--run", self.run]
        if self.mode != "client":
            out += ["--mode", self.mode]
        for flag, endpoints in (("--connect", self.connect), ("--listen", self.listen)):
            for each in endpoints:
                out += [flag, each]
        if self.connect_timeout_s != CONNECT_TIMEOUT_S:
            out += ["--connect-timeout", repr(self.connect_timeout_s)]
        if self.user:
            out += ["--user", self.user]
        if self.password_file is not None:
            out += ["--password-file", str(self.password_file)]
        return out

    def config(self) -> BusConfig:
        """The session's configuration (it reads the password file)."""
        connect = self.connect or (() if self.listen else BusConfig().connect)
        user, password = self.login()
        return BusConfig(self.mode, connect, self.listen,
                         connect_timeout_ms=int(self.connect_timeout_s * 1000), user=user,
                         password=password)

    def login(self) -> tuple[str, str]:
        """The (user, password) the flags name; a user without its password is refused."""
        return read_login(self.user, self.password_file)


def read_login(user: str, password_file: Path | None) -> tuple[str, str]:
    """The (user, password) that `--user` and `--password-file` name ("", "": no login); a
    user without its password is refused."""
    if not user:
        return "", ""
    if password_file is None:
        raise UserError(f"--user {user} needs --password-file")
    try:
        return user, password_file.read_text().strip()
    except OSError as exc:
        raise UserError(f"--password-file {password_file}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise UserError(f"--password-file {password_file}: not UTF-8 text") from None


def add_mission_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--layout", default="paper", type=layout_arg,
                   help="layout name or TOML file (default paper)")
    p.add_argument("--mission", choices=[k.value for k in MissionKind], default=None,
                   help="fill: goods from the stations to the stacks, in each cluster's fill "
                   "order; empty: from the stacks back to the stations, in reverse; orders "
                   "(seed 002's lane layouts): shelves fetched to packing stations and put "
                   "back (default: orders on a layout with shelf slots, else fill)")
    p.add_argument("--orders", type=orders_arg, default=None, metavar="N|FILE|SHELVES",
                   help=f"an order mission of N orders, released at once on shelves drawn "
                   f"with --seed; or these orders, released at once: a file of shelf names "
                   f"(one a line, # for comments) or the names, comma-separated (default "
                   f"{DEFAULT_ORDERS} drawn, for an order mission)")
    p.add_argument("--order-area", default="", metavar="AREA",
                   help="draw the orders on this shelf area's shelves only: a shelf area of "
                   "the layout, or lower-left (seed 002's Figure 19; default: every shelf)")
    p.add_argument("--battery", type=battery_arg, default="", metavar="KEY=VALUE,...",
                   help="seed 002's batteries in an order mission: " + "; ".join(
                       f"{key}: {text}" for key, text in BATTERY_KEYS.items()).replace("%", "%%")
                   + " (e.g. start=15..40,n_op=6; default: the defaults of each)")
    p.add_argument("--strategy", choices=[s.value for s in Strategy], default=None,
                   help="how the dispatcher picks each vehicle's next goal (default ann; "
                   "nearest, the only one, for order missions; each is described below)")
    p.add_argument("--vehicles", type=positive_int, default=None,
                   help="fleet size (default: every start pose of the layout)")
    p.add_argument("--seed", type=integer, default=0,
                   help="the mission's seed, kept in its record: it draws an order "
                   "mission's orders and start charges (the dispatching itself draws no "
                   "random numbers: a mission gives the same record every time; default 0)")
    p.add_argument("--heat", type=non_negative_float, default=0.0, metavar="W",
                   help="seed 004's heat cost: w_heat, on the T_value of a history run with "
                   "the orders of --seed + 1000 (the seed's runs: 2; default 0, off)")
    p.add_argument("--lookahead", type=lookahead_arg, default=LOOKAHEAD_S, metavar="SECONDS",
                   help=f"fill and empty missions: decide for a forklift only when it is free "
                   f"at most this long after the earliest one with work (not seed 000's: "
                   f"docs/dispatching.md); none: no bound, as Algorithm 1 alone (default "
                   f"{LOOKAHEAD_S:g})")
    p.add_argument("--weights", type=text_file, metavar="FILE",
                   help="MLP weights for --strategy ann (default: the weights shipped for the "
                   "layout)")


def fleet_of(layout: Layout, vehicles: int | None) -> int:
    """The fleet a run on the layout has: `vehicles` or its default, checked against the
    places its vehicles start on (forklift parks; the piles of a lane layout's AGVs; a
    seed-004 floor's parking)."""
    if layout.floor is not None:
        return fleet004(layout.floor, vehicles)
    return order_fleet(layout, vehicles) if layout.has_lanes else fleet_size(layout, vehicles)


def mission_from_args(args: argparse.Namespace, layout: Layout | None = None) -> Mission:
    """The mission the flags give; what they leave open follows the layout when given (a
    layout with shelf slots runs order missions)."""
    if args.mission is not None:
        kind = MissionKind(args.mission)
    elif args.orders is not None or (layout is not None and (layout.slots or layout.floor)):
        kind = MissionKind.ORDERS
    else:
        kind = MissionKind.FILL
    orders = kind is MissionKind.ORDERS
    given_shelves = isinstance(args.orders, tuple)
    if given_shelves and args.order_area:
        raise UserError("--order-area draws orders: give it with --orders N, not with the "
                        "orders themselves")
    for flag, given in (("--orders", args.orders is not None), ("--order-area", args.order_area),
                        ("--battery", args.battery)):
        if given and not orders:
            raise UserError(f"{flag} is for order missions, not --mission {kind.value}")
    if args.heat and layout is not None and layout.floor is None:
        raise UserError(f"--heat is seed 004's heat cost, for its lifting AGVs on a seed-004 "
                        f"floor (paper004), not for layout {layout.name}")
    if args.lookahead != LOOKAHEAD_S and orders:
        raise UserError("--lookahead is Algorithm 1's, for fill and empty missions: an order "
                        "mission's dispatcher does not rank forklifts")
    if args.strategy is None:
        strategy = Strategy.NEAREST if orders else Strategy.ANN
    else:
        strategy = Strategy(args.strategy)
    if (strategy is Strategy.NEAREST) != orders:
        raise UserError(f"--strategy {strategy.value} does not dispatch {kind.value} missions: "
                        f"order missions take nearest, fill and empty the other strategies")
    return Mission(layout=args.layout, kind=kind, strategy=strategy, vehicles=args.vehicles,
                   seed=args.seed,
                   orders=0 if not orders else len(args.orders) if given_shelves
                   else args.orders or DEFAULT_ORDERS,
                   order_area=args.order_area, battery=args.battery,
                   shelves=args.orders if given_shelves else (), heat=args.heat,
                   lookahead=args.lookahead)


def mission_argv(mission: Mission) -> list[str]:
    """The flags that give `mission` (its layout's start poses: it has no others)."""
    fleet = [] if mission.vehicles is None else ["--vehicles", str(mission.vehicles)]
    orders = [] if mission.kind is not MissionKind.ORDERS else \
        ["--orders", ",".join(mission.shelves) if mission.shelves else str(mission.orders)]
    if mission.order_area:
        orders += ["--order-area", mission.order_area]
    if mission.battery:
        orders += ["--battery", mission.battery]
    if mission.heat:
        orders += ["--heat", repr(mission.heat)]
    if mission.lookahead != LOOKAHEAD_S:
        orders += ["--lookahead", lookahead_text(mission.lookahead)]
    return ["--layout", mission.layout, "--mission", mission.kind.value, *orders,
            "--strategy", mission.strategy.value, *fleet, "--seed", str(mission.seed)]
