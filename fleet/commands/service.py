"""`fleet service NAME`: what each container of the compose deployment runs. The settings
come from FLEET_* environment variables (fleet/runtime/deploy.py, docs/deployment.md); `--health` is
the container's health check."""

from __future__ import annotations

import argparse
import os
import shlex
import socket
import sys
from pathlib import Path

from fleet.commands.processes import serve
from fleet.runtime.deploy import (
    ACL_FILE,
    MAX_VEHICLES,
    MOSQUITTO_CONFIG,
    MQTT_PORT,
    ROUTER_PORT,
    SECRETS,
    SERVICES,
    VEHICLE_ID_FILE,
    config_from_env,
    password_file,
    service_config,
)
from fleet.runtime.mqtt_broker import mosquitto_binary, mosquitto_config

HEALTH_TIMEOUT_S = 3.0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("service", help="run one service of the compose deployment, set up "
                       "from FLEET_* environment variables",
                       description="What each container of the compose deployment runs: "
                       "the service's process, set up from FLEET_* environment variables "
                       "(fleet/runtime/deploy.py, docs/deployment.md); --health is the container's "
                       "health check.")
    p.add_argument("name", choices=SERVICES, help="the service (broker: the MQTT broker of a "
                   "VDA 5050 session, mosquitto)")
    p.add_argument("--health", action="store_true",
                   help="check that the service is up (exit 0) instead of running it")
    p.add_argument("--print", action="store_true",
                   help="print the command line the service runs and exit")
    p.set_defaults(handler=run_service)


def run_service(args: argparse.Namespace) -> int:
    config = config_from_env(os.environ)
    if args.name == "broker":
        return run_broker(args)
    process = service_config(args.name, config)
    if args.print:
        print(shlex.join(["fleet", *process.argv()]))
        return 0
    if args.health:
        return 0 if healthy(args.name, config) else 1
    if args.name == "router" and config.secure:  # the run's rules; the logins are secrets
        import json

        from fleet.errors import UserError
        from fleet.runtime.access import router_acl
        from fleet.wire.topics import Keys
        from fleet.world.layout_file import load_layout

        try:  # a seed-004 floor's lifting AGVs get their own, narrower grants
            lifting = load_layout(config.layout).floor is not None
        except UserError as exc:  # a layout file only the dispatcher's container holds
            print(f"fleet service router: {exc}; the vehicles get a forklift's grants",
                  file=sys.stderr)
            lifting = False
        Path(ACL_FILE).parent.mkdir(parents=True, exist_ok=True)
        Path(ACL_FILE).write_text(json.dumps(router_acl(Keys(config.run).root, MAX_VEHICLES,
                                                        lifting)))
    return serve(process)


def run_broker(args: argparse.Namespace) -> int:
    """mosquitto on every interface of the container, in place of this process (so the
    container's init signals it directly)."""
    command = [mosquitto_binary(), "-c", MOSQUITTO_CONFIG]
    if args.print:
        print(shlex.join(command))
        return 0
    if args.health:
        return 0 if _listening(MQTT_PORT) else 1
    Path(MOSQUITTO_CONFIG).parent.mkdir(parents=True, exist_ok=True)
    Path(MOSQUITTO_CONFIG).write_text(mosquitto_config(MQTT_PORT, "0.0.0.0"))
    os.execv(command[0], command)


def _listening(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), HEALTH_TIMEOUT_S):
            return True
    except OSError:
        return False


def healthy(name: str, config) -> bool:
    """The router takes connections; any other service's liveliness token is on the bus (a
    forklift's once it has claimed its id)."""
    if name == "router":
        return _listening(ROUTER_PORT)
    from fleet.runtime.access import read_dictionary
    from fleet.runtime.bus import BusConfig, open_session, wait_alive
    from fleet.wire.topics import Keys, vehicle_sender

    keys = Keys(config.run)
    user, password = "", ""
    if name == "vehicle":
        try:
            vehicle = int(Path(VEHICLE_ID_FILE).read_text())
        except (OSError, ValueError):
            return False  # no id claimed yet
        token = keys.vehicle_alive(vehicle)
        if config.secure:
            user = vehicle_sender(vehicle)
            password = read_dictionary(Path(SECRETS / "fleet_vehicle_logins"))[user]
    else:
        token = {"reservation": keys.reservation_alive, "dispatcher": keys.dispatcher_alive,
                 "recorder": keys.recorder_alive, "gateway": keys.vda5050_alive}[name]
        if config.secure:
            user, password = name, Path(password_file(name)).read_text().strip()
    try:
        session = open_session(BusConfig("client", (config.endpoint,),
                                         connect_timeout_ms=int(HEALTH_TIMEOUT_S * 1000),
                                         user=user, password=password))
    except Exception as exc:  # zenoh raises its own error type when the router is away
        print(f"cannot reach the router: {exc}", file=sys.stderr)
        return False
    try:
        return wait_alive(session, token, HEALTH_TIMEOUT_S)
    finally:
        session.close()
