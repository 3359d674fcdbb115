"""Hosts made of Linux network namespaces, for the tests of a run spread over several hosts:
each host a namespace with one interface (eth0, 10.77.0.N/24), all plugged into a bridge that
lives in a namespace of its own (the switch), so nothing touches this machine's network.
Needs root (`ip netns`); with FLEET_REQUIRE_NETNS=1 (set by .ci/run) a machine without it
fails the tests instead of skipping them."""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass

import pytest

SUBNET = "10.77.0"


@dataclass(frozen=True)
class NetnsHost:
    name: str
    namespace: str
    address: str
    port: str  # the switch's port of this host: set down, the host is cut off
    switch: str  # the switch's namespace

    @property
    def exec(self) -> list[str]:
        return ["ip", "netns", "exec", self.namespace]


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


def netns_problem() -> str | None:
    """Why this machine cannot make network namespaces (None: it can)."""
    if shutil.which("ip") is None:
        return "no `ip` command (iproute2)"
    probe = f"fleet-probe-{os.getpid()}"
    try:
        _ip("netns", "add", probe)
        _ip("netns", "del", probe)
    except subprocess.CalledProcessError as exc:
        return f"`ip netns add` failed: {exc.stderr.strip()}"
    return None


def require_netns() -> None:
    problem = netns_problem()
    if problem is None:
        return
    if os.environ.get("FLEET_REQUIRE_NETNS") == "1":
        raise RuntimeError(f"FLEET_REQUIRE_NETNS=1 but {problem}")
    pytest.skip(f"network namespaces are not available here: {problem}")


@contextlib.contextmanager
def namespace_hosts(names: list[str]) -> Iterator[list[NetnsHost]]:
    """One namespace per name, linked through a switch namespace; all removed afterwards."""
    tag = f"fl{os.getpid()}"
    switch = f"{tag}-switch"
    made = [switch]
    try:
        _ip("netns", "add", switch)
        _ip("-n", switch, "link", "add", "br0", "type", "bridge")
        _ip("-n", switch, "link", "set", "br0", "up")
        hosts = []
        for i, name in enumerate(names):
            namespace = f"{tag}-{name}"
            _ip("netns", "add", namespace)
            made.append(namespace)
            port = f"port{i}"
            _ip("-n", switch, "link", "add", port, "type", "veth", "peer", "name", "eth0",
                "netns", namespace)
            _ip("-n", switch, "link", "set", port, "master", "br0", "up")
            address = f"{SUBNET}.{i + 1}"
            _ip("-n", namespace, "addr", "add", f"{address}/24", "dev", "eth0")
            _ip("-n", namespace, "link", "set", "eth0", "up")
            _ip("-n", namespace, "link", "set", "lo", "up")
            hosts.append(NetnsHost(name, namespace, address, port, switch))
        yield hosts
    finally:
        for namespace in reversed(made):
            subprocess.run(["ip", "netns", "del", namespace], capture_output=True)


def cut_off(host: NetnsHost) -> None:
    """Unplug the host from the switch: it reaches no other host."""
    _ip("-n", host.switch, "link", "set", host.port, "down")


def hosts_toml(hosts: list[NetnsHost], services: dict[str, list[str]],
               vehicles: dict[str, list[int]]) -> str:
    """The `fleet run --hosts` file for these hosts (the first runs fleet run itself)."""
    out = []
    for i, host in enumerate(hosts):
        out += ["[[host]]", f'name = "{host.name}"', f'address = "{host.address}"',
                *([f"exec = {host.exec!r}".replace("'", '"')] if i else []),
                f"services = {services.get(host.name, [])!r}".replace("'", '"'),
                f"vehicles = {vehicles.get(host.name, [])!r}", ""]
    return "\n".join(out)
