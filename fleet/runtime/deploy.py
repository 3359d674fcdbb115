"""The compose deployment's configuration (docs/deployment.md): every setting comes from a
FLEET_* environment variable, with its default here and nowhere else, and `service_config`
turns it into the config of each service's process (its command line: `argv()`). Pure: the
environment is passed in, nothing is started here; only the dispatcher's mission, left to
its layout, reads the layout (a lane layout's runs order missions)."""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from fleet.dispatching.decision import Strategy
from fleet.errors import UserError
from fleet.mission.order_work import DEFAULT_ORDERS
from fleet.mission.spec import ClockMode, Mission, MissionKind
from fleet.runtime.access import OPERATOR, Credentials, dictionary_text
from fleet.runtime.args import BusFlags
from fleet.runtime.argtypes import endpoint, topic_level
from fleet.runtime.process_configs import (
    AgentConfig,
    DispatcherConfig,
    GatewayConfig,
    ProcessConfig,
    RecorderConfig,
    ReservationConfig,
    RouterConfig,
)
from fleet.wire.topics import DISPATCHER, GATEWAY, RECORDER, RESERVATION, vehicle_of
from fleet.world.layout_file import load_layout

# The processes of the emulator, then the MQTT broker of an external session (mosquitto)
FLEET_SERVICES = ("router", "reservation", "dispatcher", "vehicle", "recorder", "gateway")
SERVICES = (*FLEET_SERVICES, "broker")
SERVICES_WITH_LOGINS = (DISPATCHER, RESERVATION, RECORDER, OPERATOR, GATEWAY)
ROUTER_PORT = 7447
FOXGLOVE_PORT = 8765
MQTT_PORT = 1883
MOSQUITTO_CONFIG = "/tmp/fleet/mosquitto.conf"


@dataclass(frozen=True)
class DeployConfig:
    run: str = "default"  # keys live under fleet/RUN/
    layout: str = "paper"
    mission: str = ""  # "": orders on a layout with shelf slots or a seed-004 floor, else fill
    strategy: str = ""  # "": nearest for orders, else ann
    orders: int = 0  # an order mission's orders (0: 100)
    order_area: str = ""  # draw them on this shelf area's shelves only
    vehicles: str = "auto"  # "auto": as many as claim an id (docker compose --scale vehicle=N)
    seed: int = 0
    clock: str = "fast"  # a ClockMode's value
    speed: float = 10.0  # sim seconds per wall second, real-time clock
    gather_s: float = 5.0  # "auto" fleets: start once no forklift has claimed for this long
    router: str = "router"  # the router's host name (its compose service)
    # Several docker hosts (docs/deployment.md): this host's router links to the first one's
    router_link: str = ""
    secure: bool = False  # access control; the logins come from compose secrets
    # VDA 5050 (docs/vda5050.md): "external" runs no mission of ours, the forklifts take a
    # master's orders through the gateway (the compose profile vda5050 adds it and the broker)
    dispatch: str = "internal"
    broker: str = "broker"  # the MQTT broker's host name (its compose service)
    interface: str = GatewayConfig.interface
    manufacturer: str = GatewayConfig.manufacturer

    @property
    def endpoint(self) -> str:
        return f"tcp/{self.router}:{ROUTER_PORT}"

    @property
    def mqtt(self) -> str:
        return f"mqtt://{self.broker}:{MQTT_PORT}"


ENV = {f.name: "FLEET_" + f.name.upper() for f in dataclasses.fields(DeployConfig)}
ENV["gather_s"] = "FLEET_GATHER_S"

SECRETS = PurePosixPath("/run/secrets")  # where compose mounts the secrets
ACL_FILE = "/tmp/fleet/acl.json"  # the router writes the run's access control here
MAX_VEHICLES = 16  # logins are made for this many forklifts
JOURNAL = "/data/journal/reservation-{host}.journal"  # a recreated container starts afresh
RECORDINGS = "/data/recordings"
RESTART_MARKER = "/tmp/fleet/dispatcher.started"  # survives a restart, not a re-creation
WORK_JOURNAL = "/tmp/fleet/dispatcher.journal"  # who is down, an order book, beside it
VEHICLE_ID_FILE = "/tmp/fleet/vehicle.id"  # what the vehicle's health check looks for


def config_from_env(env: Mapping[str, str]) -> DeployConfig:
    """The configuration the environment gives; an unset or empty variable keeps its
    default, a bad value is an error naming the variable."""
    values: dict[str, object] = {}
    for f in dataclasses.fields(DeployConfig):
        text = env.get(ENV[f.name], "").strip()
        if not text:
            continue
        values[f.name] = _parse(f.name, text, f.default)
    if values.get("dispatch") == "external":  # a master's forklifts drive in real time,
        values.setdefault("clock", ClockMode.REALTIME.value)  # at their own speed
        values.setdefault("speed", 1.0)
    config = DeployConfig(**values)
    _check(config)
    return config


def _parse(name: str, text: str, default: object) -> object:
    var = ENV[name]
    if isinstance(default, bool):
        if text.lower() not in ("0", "1", "true", "false", "yes", "no"):
            raise UserError(f"{var}={text!r}: give 1 or 0")
        return text.lower() in ("1", "true", "yes")
    if isinstance(default, int):
        try:
            return int(text)
        except ValueError:
            raise UserError(f"{var}={text!r}: not an integer") from None
    if isinstance(default, float):
        try:
            value = float(text)
        except ValueError:
            raise UserError(f"{var}={text!r}: not a number") from None
        if not (math.isfinite(value) and value > 0):
            raise UserError(f"{var}={text!r}: must be a positive number")
        return value
    return text


def _check(config: DeployConfig) -> None:
    choices = {"mission": [k.value for k in MissionKind], "dispatch": ["internal", "external"],
               "strategy": [s.value for s in Strategy], "clock": [m.value for m in ClockMode]}
    for name, allowed in choices.items():
        if name in ("mission", "strategy") and getattr(config, name) == "":
            continue  # left to the layout, and to the mission
        if getattr(config, name) not in allowed:
            raise UserError(f"{ENV[name]}={getattr(config, name)!r}: one of "
                            f"{', '.join(allowed)}")
    if config.vehicles != "auto" and not (config.vehicles.isdigit() and
                                          int(config.vehicles) >= 1):
        raise UserError(f"FLEET_VEHICLES={config.vehicles!r}: 'auto' or a fleet size")
    if config.orders < 0:
        raise UserError(f"FLEET_ORDERS={config.orders}: a number of orders, 1 or more")
    if config.dispatch == "external" and config.clock != ClockMode.REALTIME.value:
        raise UserError(f"FLEET_CLOCK={config.clock}: FLEET_DISPATCH=external drives the "
                        "forklifts on the real-time clock (leave FLEET_CLOCK unset)")
    if config.router_link:
        try:
            endpoint(config.router_link)
        except argparse.ArgumentTypeError as exc:
            raise UserError(f"FLEET_ROUTER_LINK: {exc}") from None
        if config.secure:
            raise UserError("FLEET_ROUTER_LINK with FLEET_SECURE=1: compose's routers have "
                            "no logins or certificates of their own yet (fleet run --hosts "
                            "--secure has them); a secure compose deployment runs on one "
                            "docker host")
    for name in ("interface", "manufacturer"):
        try:
            topic_level(getattr(config, name))
        except argparse.ArgumentTypeError as exc:
            raise UserError(f"{ENV[name]}: {exc}") from None


def service_config(service: str, config: DeployConfig) -> ProcessConfig:
    """The config of one service's process."""
    if service not in FLEET_SERVICES:
        raise UserError(f"unknown service {service!r}: one of {', '.join(FLEET_SERVICES)}")
    if service == "router":
        secure = {"acl": Path(ACL_FILE), "users": Path(SECRETS / "fleet_users")} \
            if config.secure else {}
        return RouterConfig((f"tcp/0.0.0.0:{ROUTER_PORT}",),
                            (config.router_link,) if config.router_link else (),
                            exit_when_idle_s=5.0, **secure)
    if service == "vehicle":  # logged in as any forklift, then as the one it claimed
        logins = Path(SECRETS / "fleet_vehicle_logins") if config.secure else None
        return AgentConfig(_bus(config, ""), None, logins=logins, id_file=Path(VEHICLE_ID_FILE),
                           exit_when_done=True)
    if service == "reservation":
        return ReservationConfig(_bus(config, service), Path(JOURNAL), exit_when_done=True)
    if service == "recorder":
        return RecorderConfig(_bus(config, service), out_dir=Path(RECORDINGS),
                              exit_when_done=True, foxglove=FOXGLOVE_PORT,
                              foxglove_host="0.0.0.0")
    if service == "gateway":
        return GatewayConfig(_bus(config, GATEWAY), config.mqtt, config.interface,
                             config.manufacturer)
    mission = dispatcher_mission(config)
    return DispatcherConfig(
        _bus(config, service), mission, clock=ClockMode(config.clock), speed=config.speed,
        command=f"docker compose (FLEET_LAYOUT={config.layout} "
        f"FLEET_STRATEGY={mission.strategy.value} FLEET_SEED={config.seed}"
        + (f" FLEET_ORDERS={mission.orders}" if mission.orders else "")
        + (" FLEET_DISPATCH=external" if config.dispatch == "external" else "") + ")",
        recorded=True, exit_when_done=True, claims=True, gather_s=config.gather_s,
        dispatch=config.dispatch,
        restart_marker=Path(RESTART_MARKER),
        journal=Path(WORK_JOURNAL))


def dispatcher_mission(config: DeployConfig) -> Mission:
    """The mission the settings give, as `fleet run` has it: what they leave open follows
    the layout (one with shelf slots runs order missions); a mismatch names the variables."""
    if config.mission:
        kind = MissionKind(config.mission)
    elif config.orders or config.order_area:
        kind = MissionKind.ORDERS
    else:
        layout = load_layout(config.layout)  # shelf slots or a seed-004 floor: orders
        kind = MissionKind.ORDERS if layout.slots or layout.floor else MissionKind.FILL
    orders = kind is MissionKind.ORDERS
    if (config.orders or config.order_area) and not orders:
        raise UserError(f"FLEET_ORDERS and FLEET_ORDER_AREA are for order missions, not "
                        f"FLEET_MISSION={kind.value}")
    strategy = Strategy(config.strategy) if config.strategy else \
        Strategy.NEAREST if orders else Strategy.ANN
    if (strategy is Strategy.NEAREST) != orders:
        raise UserError(f"FLEET_STRATEGY={strategy.value} does not dispatch {kind.value} "
                        f"missions: order missions take nearest, fill and empty the others")
    fleet = None if config.vehicles == "auto" else int(config.vehicles)
    return Mission(config.layout, kind, strategy, fleet, config.seed,
                   orders=(config.orders or DEFAULT_ORDERS) if orders else 0,
                   order_area=config.order_area)


def _bus(config: DeployConfig, principal: str) -> BusFlags:
    """How a service reaches the router: by its host name, logged in as `principal` in a
    secure deployment ("": no login of its own)."""
    if not (config.secure and principal):
        return BusFlags(config.run, connect=(config.endpoint,))
    return BusFlags(config.run, connect=(config.endpoint,), user=principal,
                    password_file=Path(password_file(principal)))


def password_file(principal: str) -> PurePosixPath:
    return SECRETS / f"fleet_{principal}_password"


def secret_files(credentials: Credentials) -> dict[str, str]:
    """What `fleet compose secrets` writes, file name -> text: the router's dictionary, a
    password per service (and the operator's, for tools on the host), and the forklifts'
    logins, which every forklift container gets (it learns its id only by claiming one)."""
    files = {"users": dictionary_text(credentials.logins.values()),
             "vehicle_logins": dictionary_text(
                 login for name, login in credentials.logins.items()
                 if vehicle_of(name) is not None)}
    for principal in SERVICES_WITH_LOGINS:
        files[f"{principal}_password"] = credentials[principal].password + "\n"
    return files
