"""Each process kind's command line, written once: its flags, the frozen config they parse
into, and the argv that gives that config back. A process parses its flags into its config
once and runs from it (`fleet dispatcher` and `python -m dispatcher` alike); `fleet run`
(fleet/runtime/local_run.py) and the compose deployment (fleet/runtime/deploy.py) build the
configs of the processes they start and start them with `argv()`. A flag's default is its
config field's default, so a config built in code runs as the same flags left out would."""

from __future__ import annotations

import argparse
import socket
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

from fleet.errors import UserError
from fleet.mission.spec import ClockMode, Mission
from fleet.planning.trajectory import Pose
from fleet.runtime.access import TlsFiles
from fleet.runtime.args import (
    BusFlags,
    add_bus_arguments,
    add_mission_args,
    mission_argv,
    mission_from_args,
)
from fleet.runtime.argtypes import (
    endpoint,
    key_expr,
    layout_arg,
    mqtt_url,
    port,
    pose,
    positive_float,
    scenario_arg,
    state_interval,
    topic_level,
    writable_dir,
    writable_file,
)
from fleet.runtime.helptext import strategies_epilog

# internal: the dispatcher hands the mission's subtasks to the agents; vda5050: as VDA 5050
# orders through the gateway; external: no mission, a master of the user's gives the orders
DISPATCH_MODES = ("internal", "vda5050", "external")


class ProcessConfig:
    """What every kind's config says about its command line."""

    COMMAND: ClassVar[str]  # the `fleet` subcommand
    SUMMARY: ClassVar[str]  # its line in `fleet --help`
    DESCRIPTION: ClassVar[str]  # what it is for, as its user reads it
    EPILOG: ClassVar[str | None] = None

    @classmethod
    def add_arguments(cls, p: argparse.ArgumentParser) -> None:
        raise NotImplementedError

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> ProcessConfig:
        raise NotImplementedError

    def argv(self) -> list[str]:
        """`fleet` arguments that start this process with this config."""
        raise NotImplementedError


def _flag(name: str, value: object, default: object = None) -> list[str]:
    """`name value`, unless the value is the default (or a set flag: `name` alone)."""
    if value == default:
        return []
    if value is True:
        return [name]
    return [name, repr(value) if isinstance(value, float) else str(value)]


@dataclass(frozen=True)
class RouterConfig(ProcessConfig):
    COMMAND = "router"
    SUMMARY = "run a zenoh router for the other processes"
    DESCRIPTION = ("Run a zenoh router (in Python: there is no zenohd to install). Every other "
                   "process of a run connects to it as a client. `fleet run` starts one on a "
                   "free loopback port (one per host with --hosts, linked to the first "
                   "host's); the compose deployment runs it as its router service.")
    DEFAULT_LISTEN: ClassVar[str] = "tcp/0.0.0.0:7447"

    listen: tuple[str, ...] = ()  # none: DEFAULT_LISTEN
    connect: tuple[str, ...] = ()  # other routers
    acl: Path | None = None  # access control (a JSON file), with ...
    users: Path | None = None  # ... the dictionary that authenticates sessions
    exit_when_idle_s: float | None = None
    user: str = ""  # logs in to the routers it connects to as this user ...
    password_file: Path | None = None  # ... with the password in this file
    tls: TlsFiles | None = None  # its TLS links to other routers: CA, certificate, key
    # A liveliness token it holds while it routes: another host's router, announced on the
    # first host's once it has linked to it (`fleet run --hosts` waits for that).
    announce: str = ""

    @property
    def endpoints(self) -> tuple[str, ...]:
        return self.listen or (self.DEFAULT_LISTEN,)

    @classmethod
    def add_arguments(cls, p: argparse.ArgumentParser) -> None:
        p.add_argument("--listen", action="append", default=[], type=endpoint,
                       metavar="ENDPOINT", help=f"endpoint to listen on (default "
                       f"{cls.DEFAULT_LISTEN}; repeatable)")
        p.add_argument("--connect", action="append", default=[], type=endpoint,
                       metavar="ENDPOINT",
                       help="another router to connect to (default none; repeatable)")
        p.add_argument("--acl", type=Path, metavar="FILE",
                       help="enforce this access control (a JSON file: the access_control "
                       "section fleet/runtime/access.py writes); needs --users (default: "
                       "none, everyone may do everything)")
        p.add_argument("--users", type=Path, metavar="FILE",
                       help="authenticate every session against this user:password dictionary "
                       "(default: no logins)")
        p.add_argument("--exit-when-idle", type=positive_float, metavar="SECONDS",
                       help="exit once sessions have come and every one has gone for this long "
                       "(a deployment whose processes exit when the mission ends; default: run "
                       "until stopped)")
        p.add_argument("--user", default="", metavar="NAME",
                       help="log in to the routers it connects to as this user (needs "
                       "--password-file; default: no login)")
        p.add_argument("--password-file", type=Path, metavar="FILE",
                       help="the password of --user, alone in this file (default: none)")
        p.add_argument("--tls", nargs=3, type=Path, metavar=("CA", "CERTIFICATE", "KEY"),
                       help="its tls/ links, listened on or connected to, show this "
                       "certificate (with its private key) and take only peers whose "
                       "certificate the CA signed (PEM files; default: no tls/ links)")
        p.add_argument("--announce", type=key_expr, metavar="KEY",
                       help="hold a liveliness token on this key while routing: the routers "
                       "it links to learn it once linked (fleet run --hosts waits for each "
                       "other host's router so; default: none)")

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> RouterConfig:
        if args.password_file is not None and not args.user:
            raise UserError("--password-file needs --user: the password is that user's")
        return cls(tuple(args.listen), tuple(args.connect), args.acl, args.users,
                   args.exit_when_idle, args.user, args.password_file,
                   TlsFiles(*args.tls) if args.tls else None, args.announce or "")

    def argv(self) -> list[str]:
        return [self.COMMAND, *(a for e in self.listen for a in ("--listen", e)),
                *(a for e in self.connect for a in ("--connect", e)),
                *_flag("--acl", self.acl), *_flag("--users", self.users),
                *_flag("--exit-when-idle", self.exit_when_idle_s),
                *_flag("--user", self.user, ""), *_flag("--password-file", self.password_file),
                *(["--tls", str(self.tls.ca), str(self.tls.certificate),
                   str(self.tls.private_key)] if self.tls else []),
                *_flag("--announce", self.announce or None)]


@dataclass(frozen=True)
class ReservationConfig(ProcessConfig):
    COMMAND = "reservation"
    SUMMARY = "run the reservation service process"
    DESCRIPTION = ("Run the reservation service: the run's authoritative space-time "
                   "reservation table. Forklifts commit the cells their plans need through it; "
                   "it journals every change (and replays the journal when it starts again) "
                   "and publishes each one.")

    bus: BusFlags
    journal: Path = Path("reservation.journal")
    exit_when_done: bool = False

    @classmethod
    def add_arguments(cls, p: argparse.ArgumentParser) -> None:
        add_bus_arguments(p)
        p.add_argument("--journal", type=Path, default=cls.journal, metavar="FILE",
                       help="append-only journal (replayed on start); '{host}' in it stands "
                       "for the host name, so a restarted container replays its own journal "
                       "and a new one starts afresh (default reservation.journal)")
        p.add_argument("--exit-when-done", action="store_true",
                       help="exit once the dispatcher publishes the mission's result")

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> ReservationConfig:
        return cls(BusFlags.from_args(args), args.journal, args.exit_when_done)

    def argv(self) -> list[str]:
        return [self.COMMAND, *self.bus.argv(), "--journal", str(self.journal),
                *_flag("--exit-when-done", self.exit_when_done, False)]


def forklift_id(text: str) -> int | None:
    """A forklift id (1, 2, ...), or None for 'auto'."""
    if text == "auto":
        return None
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is neither a number nor 'auto'") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"forklift ids start at 1, not {value}")
    return value


@dataclass(frozen=True)
class AgentConfig(ProcessConfig):
    COMMAND = "agent"
    SUMMARY = "run one forklift's agent process"
    DESCRIPTION = ("Run one forklift: it plans every subtask the dispatcher hands it with the "
                   "improved hybrid A* against its copy of the reservation table, commits the "
                   "plan through the reservation service, drives it and publishes its state. "
                   "Give it its id, or `--id auto` to claim one from a dispatcher started with "
                   "--claims.")

    bus: BusFlags
    vehicle: int | None = None  # None: claim an id from the dispatcher
    # The name to claim under: the host name, which a restarted container keeps.
    claim_as: str = field(default_factory=socket.gethostname)
    claim_timeout_s: float = 120.0
    layout: str | None = None  # None: the layout of the dispatcher's mission
    start: Pose | None = None  # None: the start pose the layout (or mission) gives the id
    logins: Path | None = None  # the forklifts' logins: claim as any, run as vehicle-ID
    id_file: Path | None = None  # the id, once known (a container's health check)
    exit_when_done: bool = False

    @classmethod
    def add_arguments(cls, p: argparse.ArgumentParser) -> None:
        add_bus_arguments(p)
        p.add_argument("--id", type=forklift_id, required=True,
                       help="forklift id (1, 2, ...), or 'auto': claim one from the dispatcher "
                       "(started with --claims) under this host's name")
        p.add_argument("--claim-as", default=socket.gethostname(),
                       help="--id auto: the name to claim under (default: the host name, which "
                       "a restarted container keeps, so it gets its forklift back)")
        p.add_argument("--claim-timeout", type=positive_float, default=cls.claim_timeout_s,
                       metavar="SECONDS",
                       help="--id auto: seconds to keep asking for an id (default 120)")
        p.add_argument("--layout", type=layout_arg,
                       help="layout name or TOML file (default: the one the dispatcher's "
                       "mission runs on, which it says on dispatch/mission)")
        p.add_argument("--start", type=pose, metavar="POSE",
                       help="start pose 'col,row,H' (default: the layout's start pose for --id)")
        p.add_argument("--logins", type=Path, metavar="FILE",
                       help="the forklifts' logins, a 'user:password' line each (the compose "
                       "deployment's secret): claim an id logged in as any of them, then run "
                       "as vehicle-ID (instead of --user and --password-file; default none)")
        p.add_argument("--id-file", type=Path, metavar="FILE",
                       help="write the forklift's id here once it is known (a container's "
                       "health check reads it; default: nowhere)")
        p.add_argument("--exit-when-done", action="store_true",
                       help="exit once the dispatcher publishes the mission's result")

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> AgentConfig:
        return cls(BusFlags.from_args(args), args.id, args.claim_as, args.claim_timeout,
                   args.layout, args.start, args.logins, args.id_file, args.exit_when_done)

    def argv(self) -> list[str]:
        claiming = self.vehicle is None
        return [self.COMMAND, *self.bus.argv(), *_flag("--logins", self.logins),
                "--id", "auto" if claiming else str(self.vehicle),
                *(_flag("--claim-as", self.claim_as, socket.gethostname()) if claiming else []),
                *_flag("--claim-timeout", self.claim_timeout_s, AgentConfig.claim_timeout_s),
                *_flag("--layout", self.layout), *_flag("--start", self.start),
                *_flag("--id-file", self.id_file),
                *_flag("--exit-when-done", self.exit_when_done, False)]


@dataclass(frozen=True)
class DispatcherConfig(ProcessConfig):
    COMMAND = "dispatcher"
    SUMMARY = "run the dispatcher process"
    DESCRIPTION = ("Run the dispatcher: it waits for the reservation service and the forklifts, "
                   "then runs the mission, picking each forklift's next goal by the strategy "
                   "and handing it over, and publishes the progress and, at the end, the "
                   "mission's record.")
    EPILOG = strategies_epilog()

    bus: BusFlags
    mission: Mission
    weights: Path | None = None  # MLP weights (default: those shipped for the layout)
    clock: ClockMode = ClockMode.FAST
    speed: float = 1.0  # real-time clock: sim seconds per wall second
    startup_timeout_s: float = 120.0  # for the reservation service and every agent
    command: str = ""  # the command line that started the run ("": this process's)
    faults: str | None = None  # a fault scenario's name or file
    recorded: bool = False  # fast clock: sim time stands still while no recorder runs
    recover: bool = False  # a restarted dispatcher: pick the mission up
    exit_when_done: bool = False
    claims: bool = False  # hand out forklift ids to agents started with --id auto
    gather_s: float = 5.0  # claims without a fleet size: start once no claim came this long
    restart_marker: Path | None = None
    journal: Path | None = None  # an order mission's inputs (seed 004: its fault instants)
    dispatch: str = "internal"  # DISPATCH_MODES
    mqtt: str = "mqtt://127.0.0.1:1883"  # --dispatch vda5050: the gateway's broker

    @classmethod
    def add_arguments(cls, p: argparse.ArgumentParser) -> None:
        add_bus_arguments(p)
        add_mission_args(p)
        p.add_argument("--dispatch", choices=DISPATCH_MODES, default=cls.dispatch,
                       help="internal: run the mission; vda5050: run it as VDA 5050 orders "
                       "through the gateway (on the real-time clock); external: run no "
                       "mission, only the real-time clock, while a VDA 5050 master gives the "
                       "forklifts their orders through the gateway (docs/vda5050.md; default "
                       "internal)")
        p.add_argument("--mqtt", type=mqtt_url, default=cls.mqtt, metavar="URL",
                       help=f"--dispatch vda5050: the gateway's MQTT broker, mqtt://HOST[:PORT] "
                       f"(default {cls.mqtt})")
        p.add_argument("--clock", choices=[m.value for m in ClockMode], default=cls.clock.value,
                       help="fast: discrete events, deterministic; realtime: sim time = speed "
                       "x wall time (default fast)")
        p.add_argument("--speed", type=positive_float, default=cls.speed,
                       help="real-time clock: sim seconds per wall second (default 1)")
        p.add_argument("--startup-timeout", type=positive_float,
                       default=cls.startup_timeout_s, metavar="SECONDS",
                       help="seconds to wait for the reservation service and every agent "
                       "(default 120)")
        p.add_argument("--command", default=cls.command,
                       help="the command line that started the run, for its recording "
                       "(default: this process's)")
        p.add_argument("--faults", metavar="SCENARIO", type=scenario_arg,
                       help="fault scenario (docs/faults.md): the fast clock stops at its "
                       "instants until each fault is detected; the real-time clock closes its "
                       "zones when their time comes (default: no faults)")
        p.add_argument("--recorded", action="store_true",
                       help="fast clock: hold sim time while no recorder runs, so a recorder "
                       "killed and restarted misses nothing that happened meanwhile")
        p.add_argument("--recover", action="store_true",
                       help="a restarted dispatcher: pick the mission up from what the "
                       "reservation service and the forklifts hold")
        p.add_argument("--exit-when-done", action="store_true",
                       help="exit after publishing the result (once the recorder has it, with "
                       "--recorded) instead of waiting to be stopped")
        p.add_argument("--claims", action="store_true",
                       help="hand out forklift ids to agents started with --id auto; without "
                       "--vehicles the fleet is whoever claimed one before claims stopped for "
                       "--gather seconds (docs/deployment.md)")
        p.add_argument("--gather", type=positive_float, default=cls.gather_s,
                       metavar="SECONDS",
                       help="--claims without --vehicles: start once no new forklift has "
                       "claimed an id for this many seconds (default 5)")
        p.add_argument("--restart-marker", type=Path,
                       help="create this file when the mission starts; if it is already "
                       "there, this is a restart: pick the mission up as --recover does (a "
                       "container keeps its files across restarts, not across re-creation; "
                       "default: none)")
        p.add_argument("--journal", type=Path, metavar="FILE",
                       help="journal where each forklift that goes down stops, and what "
                       "an order mission's book is fed (on a seed-004 floor: each service "
                       "fault's instant), to this file, from which a restarted dispatcher "
                       "(--recover, the same FILE) picks the mission up (default: none: "
                       "an order mission, or one with a forklift down, is not picked up)")

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> DispatcherConfig:
        return cls(BusFlags.from_args(args), mission_from_args(args), args.weights,
                   ClockMode(args.clock), args.speed, args.startup_timeout, args.command,
                   args.faults, args.recorded, args.recover, args.exit_when_done, args.claims,
                   args.gather, args.restart_marker, args.journal, args.dispatch, args.mqtt)

    def argv(self) -> list[str]:
        d = DispatcherConfig
        return [self.COMMAND, *self.bus.argv(), *mission_argv(self.mission),
                *_flag("--weights", self.weights), "--clock", self.clock.value,
                "--speed", repr(self.speed),
                *_flag("--startup-timeout", self.startup_timeout_s, d.startup_timeout_s),
                *_flag("--faults", self.faults), *_flag("--recorded", self.recorded, False),
                *_flag("--recover", self.recover, False),
                *_flag("--claims", self.claims, False),
                *_flag("--gather", self.gather_s, d.gather_s),
                *_flag("--restart-marker", self.restart_marker),
                *_flag("--journal", self.journal),
                *_flag("--dispatch", self.dispatch, d.dispatch),
                *_flag("--mqtt", self.mqtt, d.mqtt),
                *_flag("--exit-when-done", self.exit_when_done, False),
                *_flag("--command", self.command, "")]


@dataclass(frozen=True)
class RecorderConfig(ProcessConfig):
    COMMAND = "recorder"
    SUMMARY = "record a run to an MCAP file"
    DESCRIPTION = ("Record everything a run publishes (its keys under fleet/RUN/) to an MCAP "
                   "file that fleet analyze, fleet plot and Foxglove read; with --foxglove, "
                   "also serve a live view of the run. Start it before the mission's other "
                   "processes, so it hears everything.")

    bus: BusFlags
    out: Path = Path("run.mcap")
    out_dir: Path | None = None  # instead of out: a run directory of this host's in it
    exit_when_done: bool = False
    foxglove: int | None = None  # serve the live view on this port
    foxglove_host: str = "127.0.0.1"

    @classmethod
    def add_arguments(cls, p: argparse.ArgumentParser) -> None:
        add_bus_arguments(p)
        p.add_argument("--out", type=writable_file, default=cls.out, metavar="FILE",
                       help="MCAP file to write (default run.mcap; never overwritten: a "
                       "recorder restarted for a run writes its next segment, "
                       "RUN_DIR/run-2.mcap, ...)")
        p.add_argument("--out-dir", type=writable_dir, metavar="DIR",
                       help="instead of --out: write DIR/<UTC date-time>-<host name>/run.mcap, "
                       "or the next segment in this host's latest directory there when it "
                       "restarts (a container keeps its host name across restarts; default: "
                       "use --out)")
        p.add_argument("--exit-when-done", action="store_true",
                       help="close the file and exit once the mission's result is recorded")
        p.add_argument("--foxglove", type=port, metavar="PORT",
                       help="also serve the live view over the Foxglove WebSocket protocol on "
                       "127.0.0.1:PORT (open ws://localhost:PORT in Foxglove; default: no live "
                       "view)")
        p.add_argument("--foxglove-host", default=cls.foxglove_host, metavar="HOST",
                       help="the address the live view listens on (0.0.0.0 in a container, "
                       "whose published port is what the host reaches; default 127.0.0.1)")

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> RecorderConfig:
        return cls(BusFlags.from_args(args), args.out, args.out_dir, args.exit_when_done,
                   args.foxglove, args.foxglove_host)

    def argv(self) -> list[str]:
        place = ["--out-dir", str(self.out_dir)] if self.out_dir is not None else \
            ["--out", str(self.out)]
        return [self.COMMAND, *self.bus.argv(), *place,
                *_flag("--exit-when-done", self.exit_when_done, False),
                *_flag("--foxglove", self.foxglove),
                *_flag("--foxglove-host", self.foxglove_host, RecorderConfig.foxglove_host)]


@dataclass(frozen=True)
class GatewayConfig(ProcessConfig):
    COMMAND = "vda5050"  # `fleet vda5050 gateway`
    SUMMARY = "run the VDA 5050 gateway process"
    DESCRIPTION = ("Run the VDA 5050 gateway: every forklift of the run as a VDA 5050 2.0.0 "
                   "AGV on MQTT (its connection with a last will, factsheet, state and "
                   "visualization), taking a master's orders and instant actions and having "
                   "each released edge planned and committed by the forklift's agent; the "
                   "layout and the fleet are those of the run's dispatcher, started with "
                   "--dispatch external (docs/vda5050.md).")

    bus: BusFlags  # the layout and the fleet: the run's dispatcher says (dispatch/mission)
    mqtt: str = "mqtt://127.0.0.1:1883"
    interface: str = "uagv"
    manufacturer: str = "fleet-emulator"
    state_interval_s: float = 10.0  # a state at least this often (the spec: at most 30 s)
    visualization_interval_s: float = 0.5
    startup_timeout_s: float = 120.0

    @classmethod
    def add_arguments(cls, p: argparse.ArgumentParser) -> None:
        add_bus_arguments(p)
        p.add_argument("--mqtt", type=mqtt_url, default=cls.mqtt, metavar="URL",
                       help=f"the MQTT broker, mqtt://HOST[:PORT] (default {cls.mqtt})")
        p.add_argument("--interface", type=topic_level, default=cls.interface,
                       help="interfaceName, the topics' first level (default uagv)")
        p.add_argument("--manufacturer", type=topic_level, default=cls.manufacturer,
                       help="the AGVs' manufacturer, the topics' third level (default "
                       "fleet-emulator); each serial number is forklift-ID")
        p.add_argument("--state-interval", type=state_interval, default=cls.state_interval_s,
                       metavar="SECONDS", help="a state at least this often besides those "
                       "events bring (at most 30, as the spec asks; default 10)")
        p.add_argument("--visualization-interval", type=positive_float,
                       default=cls.visualization_interval_s, metavar="SECONDS",
                       help="a visualization message this often (default 0.5)")
        p.add_argument("--startup-timeout", type=positive_float,
                       default=cls.startup_timeout_s, metavar="SECONDS",
                       help="seconds to wait for the reservation service, every agent and "
                       "the clock (default 120)")

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> GatewayConfig:
        return cls(BusFlags.from_args(args), args.mqtt,
                   args.interface, args.manufacturer, args.state_interval,
                   args.visualization_interval, args.startup_timeout)

    def argv(self) -> list[str]:
        g = GatewayConfig
        return [self.COMMAND, "gateway", *self.bus.argv(), *_flag("--mqtt", self.mqtt, g.mqtt),
                *_flag("--interface", self.interface, g.interface),
                *_flag("--manufacturer", self.manufacturer, g.manufacturer),
                *_flag("--state-interval", self.state_interval_s, g.state_interval_s),
                *_flag("--visualization-interval", self.visualization_interval_s,
                       g.visualization_interval_s),
                *_flag("--startup-timeout", self.startup_timeout_s, g.startup_timeout_s)]


KINDS: tuple[type[ProcessConfig], ...] = (RouterConfig, ReservationConfig, AgentConfig,
                                           DispatcherConfig, RecorderConfig)

