"""Where a run's processes run (`fleet run --hosts FILE`, docs/deployment.md "Several hosts").

Every host has a zenoh router of its own; each process is a client of its own host's router,
and the router of every other host connects to the first host's, as zenoh is deployed across
machines. The first host is the one `fleet run` runs on: it starts every process, the others
through a command prefix that runs the process there in place (`ip netns exec NS`, `nsenter
...`), so the signals of a stop or a fault reach it. A run without a hosts file is one host,
its router on a loopback port.

A hosts file (TOML):

    [[host]]
    name = "a"                           # the first host: fleet run's own
    address = "10.77.0.1"                # where its router listens, for everyone
    services = ["reservation", "dispatcher"]
    vehicles = [1]

    [[host]]
    name = "b"
    address = "10.77.0.2"
    exec = ["ip", "netns", "exec", "b"]  # how a process is started there
    services = ["recorder"]
    vehicles = [2, 3]

Whatever no host names runs on the first one.
"""

from __future__ import annotations

import ipaddress
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from fleet.errors import UserError
from fleet.mission.faults import Fault, FaultKind, Scenario, ScenarioError, check_overlaps

HOSTED_SERVICES = ("reservation", "dispatcher", "recorder")
DEFAULT_PORT = 7447
HOST_KEYS = ("name", "address", "port", "exec", "services", "vehicles")
NAME = re.compile(r"[a-z0-9][a-z0-9_]{0,15}")
HOST_NAME = re.compile(r"[A-Za-z0-9]([A-Za-z0-9.-]{0,251}[A-Za-z0-9])?")


class HostsError(UserError):
    """A hosts file that cannot be used; the message names the host and the field."""


@dataclass(frozen=True)
class Host:
    name: str
    address: str  # its router listens here, and every other host reaches it here
    port: int = DEFAULT_PORT
    exec: tuple[str, ...] = ()  # the command prefix that starts a process on this host
    services: tuple[str, ...] = ()
    vehicles: tuple[int, ...] = ()

    @property
    def endpoint(self) -> str:
        return f"tcp/{self._host}:{self.port}"

    @property
    def link_port(self) -> int:
        """Where the first host's router takes the other routers' links in a secure run: the
        port after its own."""
        return self.port + 1

    @property
    def link_endpoint(self) -> str:
        return f"tls/{self._host}:{self.link_port}"

    @property
    def _host(self) -> str:
        return f"[{self.address}]" if ":" in self.address else self.address


@dataclass(frozen=True)
class Hosts:
    """The hosts of a run, the first one this machine."""

    hosts: tuple[Host, ...]

    @property
    def first(self) -> Host:
        return self.hosts[0]

    def host(self, name: str) -> Host | None:
        return next((h for h in self.hosts if h.name == name), None)

    def of_process(self, kind: str) -> Host:
        """The host that runs a process kind (`agent-3`, `reservation`, ...): the one that
        names it, else the first."""
        vehicle = int(kind.split("-")[1]) if kind.startswith("agent-") else None
        for host in self.hosts:
            if kind in host.services or vehicle in host.vehicles:
                return host
        return self.first

    def router_name(self, host: Host) -> str:
        """The router's name among the run's processes (its log: logs/NAME.log)."""
        return "router" if host == self.first else f"router-{host.name}"


def one_host(port: int) -> Hosts:
    """A run on this machine alone: its router on a loopback port."""
    return Hosts((Host("local", "127.0.0.1", port),))


def load_hosts(path: Path, vehicles: int) -> Hosts:
    """The hosts of a run of `vehicles` forklifts, from a TOML file, every field checked."""
    where = str(path)
    try:
        data = tomllib.loads(path.read_text())
    except OSError as exc:
        raise HostsError(f"--hosts {where}: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise HostsError(f"--hosts {where}: not valid TOML: {exc}") from None
    if set(data) != {"host"} or not isinstance(data["host"], list) or not data["host"] or \
            not all(isinstance(h, dict) for h in data["host"]):
        raise HostsError(f"--hosts {where}: expected [[host]] tables and nothing else")
    hosts = tuple(_host(h, f"--hosts {where}: host {i + 1}", vehicles)
                  for i, h in enumerate(data["host"]))
    _check_unique(hosts, where)
    if hosts[0].exec:
        raise HostsError(f"--hosts {where}: host {hosts[0].name}: the first host is the one "
                         f"fleet run runs on; it takes no exec")
    return Hosts(hosts)


def _host(data: dict, where: str, vehicles: int) -> Host:
    unknown = sorted(set(data) - set(HOST_KEYS))
    if unknown:
        raise HostsError(f"{where}: unknown field {unknown[0]!r} (a host takes "
                         f"{', '.join(HOST_KEYS)})")
    for key in ("name", "address"):
        if not isinstance(data.get(key), str) or not data[key]:
            raise HostsError(f"{where}: {key} must be given as a non-empty string")
    name = data["name"]
    if not NAME.fullmatch(name):
        raise HostsError(f"{where}: name {name!r} must be 1 to 16 lower-case letters, digits "
                         f"or _ (it names the host's router and logs)")
    where = f"{where} ({name})"
    port = data.get("port", DEFAULT_PORT)
    if isinstance(port, bool) or not isinstance(port, int) or not 1 <= port <= 65535:
        raise HostsError(f"{where}: port must be a TCP port (1 to 65535), not {port!r}")
    command = data.get("exec", [])
    if not isinstance(command, list) or not all(isinstance(a, str) and a for a in command):
        raise HostsError(f"{where}: exec must be a list of strings, the command prefix that "
                         f"starts a process there (\"ip\", \"netns\", \"exec\", \"NS\")")
    services = data.get("services", [])
    if not isinstance(services, list) or any(s not in HOSTED_SERVICES for s in services):
        raise HostsError(f"{where}: services must be a list of {', '.join(HOSTED_SERVICES)}, "
                         f"not {services!r}")
    numbers = data.get("vehicles", [])
    if not isinstance(numbers, list) or not all(
            isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in numbers):
        raise HostsError(f"{where}: vehicles must be a list of forklift numbers (1, 2, ...), "
                         f"not {numbers!r}")
    beyond = [v for v in numbers if v > vehicles]
    if beyond:
        raise HostsError(f"{where}: vehicle {beyond[0]}: the run has forklifts 1 to {vehicles}")
    if not _is_address(data["address"]):
        raise HostsError(f"{where}: address {data['address']!r} is neither an IP address nor "
                         f"a host name (its port is the field port)")
    return Host(name, data["address"], port, tuple(command), tuple(services), tuple(numbers))


def _is_address(text: str) -> bool:
    try:
        ipaddress.ip_address(text)
        return True
    except ValueError:
        return HOST_NAME.fullmatch(text) is not None


def _check_unique(hosts: tuple[Host, ...], where: str) -> None:
    """Each name, router endpoint, service and forklift once."""
    seen: dict[object, str] = {}
    for host in hosts:
        for what, key in ((f"name {host.name!r}", ("name", host.name)),
                          (f"router {host.endpoint}", ("endpoint", host.endpoint)),
                          *((f"service {s}", ("service", s)) for s in host.services),
                          *((f"forklift {v}", ("vehicle", v)) for v in host.vehicles)):
            if key in seen:
                raise HostsError(f"--hosts {where}: {what} is on host {seen[key]} and on "
                                 f"host {host.name}")
            seen[key] = host.name


def cut_links(scenario: Scenario, hosts: Hosts | None) -> Scenario:
    """The scenario as each forklift lives it: a `cut_host` is a `cut_link` of every forklift
    on that host at once (the dispatcher detects and recovers those, and the in-process
    reference replays them). Refused, naming the fault, where a host cannot be cut alone."""
    faults: list[Fault] = []
    for i, fault in enumerate(scenario.faults):
        if fault.kind is not FaultKind.CUT_HOST:
            faults.append(fault)
            continue
        where = f"scenario {scenario.name}: fault {i + 1} ({fault.describe()})"
        host = hosts.host(fault.host or "") if hosts is not None else None
        if hosts is None or len(hosts.hosts) < 2:
            raise ScenarioError(f"{where}: only a run spread over several hosts (--hosts "
                                f"FILE) has links between hosts to cut")
        if host is None:
            raise ScenarioError(f"{where}: no host is named {fault.host!r} (the hosts are "
                                f"{', '.join(h.name for h in hosts.hosts)})")
        if host == hosts.first:
            raise ScenarioError(f"{where}: {host.name} is the first host, every other "
                                f"host's link ends there; cut another")
        if host.services or not host.vehicles:
            what = ", ".join(host.services) or "no forklift"
            raise ScenarioError(f"{where}: host {host.name} runs {what}: only a host of "
                                f"forklift agents can be cut off (the mission stands still "
                                f"without its services)")
        faults += [Fault(FaultKind.CUT_LINK, fault.at, v, fault.duration)
                   for v in host.vehicles]
    out = Scenario(scenario.name, scenario.description, tuple(faults))
    check_overlaps(out.faults, f"scenario {scenario.name} (each host cut as its forklifts' "
                                f"links)")
    return out


def hosts_for(path: Path | None, vehicles: int, secure: bool) -> Hosts | None:
    """The hosts of `fleet run --hosts FILE` (None: this machine alone); a secure run's
    first host needs the port after its router's for the other routers' links."""
    if path is None:
        return None
    hosts = load_hosts(path, vehicles)
    first = hosts.first
    if secure and len(hosts.hosts) > 1 and (first.link_port > 65535 or any(
            (h.address, h.port) == (first.address, first.link_port) for h in hosts.hosts)):
        raise HostsError(f"--hosts {path}: host {first.name}: with --secure its router takes "
                         f"the other routers' links on the port after its own ({first.port} "
                         f"+ 1), which is {'no port' if first.link_port > 65535 else 'taken'}"
                         f"; give it another port")
    return hosts
