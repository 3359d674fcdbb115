"""`fleet run --secure` on several hosts (fleet/runtime/access.py `LinkedRouter`, the run's
`Secrets`, fleet/runtime/certificates.py): each host's router still checks its own clients,
and the routers take each other's links only over TLS with a certificate the run signed (and
at the first host's, the linking router's login). Two router processes on loopback ports
stand for two hosts here, configured as `fleet run` configures them;
tests/test_multi_host.py runs a whole secure mission on network-namespace hosts."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import zenoh
from test_access import Inbox, ask

from fleet.runtime.access import TlsFiles
from fleet.runtime.bus import BusConfig, free_port, open_session
from fleet.runtime.certificates import RunAuthority
from fleet.runtime.hosts import Host, Hosts, load_hosts
from fleet.runtime.local_run import Secrets
from fleet.runtime.process_configs import RouterConfig
from fleet.wire.topics import DISPATCHER, RECORDER, RESERVATION, Keys, vehicle_sender

HOSTS = """
[[host]]
name = "a"
address = "127.0.0.1"
port = {a}
vehicles = [1]

[[host]]
name = "b"
address = "127.0.0.1"
port = {b}
services = ["recorder"]
vehicles = [2]
"""
ROUTE_S = 20.0  # a route across both routers is up within this (some 100 ms here)


def until(done: Callable[[], bool], what: str) -> None:
    """Try `done` until it holds: the routers tell each other of subscribers and queryables
    on their own time, and a put before that reaches no one."""
    deadline = time.monotonic() + ROUTE_S
    while not done():
        assert time.monotonic() < deadline, f"not within {ROUTE_S} s: {what}"
        time.sleep(0.05)  # a refused get ends at once: spare the routers a busy loop


@dataclass
class Linked:
    hosts: Hosts
    secrets: Secrets
    keys: Keys
    sessions: list[zenoh.Session]

    def login(self, principal: str, host: Host) -> zenoh.Session:
        """A client of the host's router, logged in as `principal`."""
        session = open_session(BusConfig(
            "client", (host.endpoint,), connect_timeout_ms=10_000, user=principal,
            password=self.secrets.logins[principal].password))
        self.sessions.append(session)
        return session


@pytest.fixture
def linked(tmp_path: Path) -> Iterator[Linked]:
    path = tmp_path / "hosts.toml"
    path.write_text(HOSTS.format(a=free_port(), b=free_port()))
    hosts = load_hosts(path, 2)
    keys = Keys("securehosts")
    secrets = Secrets(tmp_path / "secrets", keys.run, keys.root, 2, hosts)
    a, b = hosts.hosts
    routers = []
    for host, connect in ((a, ()), (b, (a.link_endpoint,))):
        config = secrets.router(host, RouterConfig((host.endpoint,), connect))
        with open(tmp_path / f"router-{host.name}.log", "wb") as log:
            routers.append(subprocess.Popen([sys.executable, "-m", "fleet", *config.argv()],
                                            stdout=log, stderr=subprocess.STDOUT))
    running = Linked(hosts, secrets, keys, [])
    try:
        yield running
    finally:
        for session in running.sessions:  # before the routers: see fleet/runtime/router.py
            session.close()
        for router in routers:
            router.terminate()
            assert router.wait(timeout=30) == 0


def forged_then_own(sender: zenoh.Session, forged: str, own: str, inbox: Inbox) -> None:
    """`sender` puts on a key it may not, then on its own, until the latter reaches `inbox`
    (the routers link in their own time); its router dropped every forged one: zenoh keeps
    one session's messages in order, so had one passed it would have come first."""
    n = 0

    def once() -> bool:
        nonlocal n
        n += 1
        sender.put(forged, f"forged {n}")
        sender.put(own, f"own {n}")
        return inbox.wait_for(f"own {n}")

    until(once, f"{own} across the routers")
    assert not [p for p in inbox.payloads() if p.startswith("forged")]


def test_secure_routers_of_two_hosts_carry_the_run_both_ways_and_still_check_their_clients(
        linked: Linked):
    a, b = linked.hosts.hosts
    keys = linked.keys
    dispatcher = linked.login(DISPATCHER, a)
    states_on_a = Inbox()
    dispatcher.declare_subscriber(f"{keys.root}/vehicle/*/state", states_on_a)
    dispatcher.declare_queryable(keys.dispatch_mission,
                                 lambda q: q.reply(keys.dispatch_mission, "the mission"))
    # From host b to host a: a query and its reply; forklift 2's states, never as another's.
    recorder = linked.login(RECORDER, b)
    until(lambda: ask(recorder, keys.dispatch_mission) == ["the mission"],
          "the recorder on b asks the dispatcher on a")
    forklift_2 = linked.login(vehicle_sender(2), b)
    forged_then_own(forklift_2, keys.vehicle_state(1), keys.vehicle_state(2), states_on_a)
    # From host a to host b: forklift 1's states, never as another's; the table's changes.
    states_on_b = Inbox()
    recorder.declare_subscriber(f"{keys.root}/vehicle/*/state", states_on_b)
    forklift_1 = linked.login(vehicle_sender(1), a)
    forged_then_own(forklift_1, keys.vehicle_state(2), keys.vehicle_state(1), states_on_b)
    changes = Inbox()
    forklift_2.declare_subscriber(keys.reservation_change, changes)
    service = linked.login(RESERVATION, a)
    m = 0

    def change() -> bool:
        nonlocal m
        m += 1
        service.put(keys.reservation_change, f"change {m}")
        return changes.wait_for(f"change {m}")

    until(change, "the reservation service on a reaches forklift 2 on b")


def test_the_first_hosts_router_takes_a_link_only_with_a_certificate_of_the_run(
        linked: Linked, tmp_path: Path):
    a, b = linked.hosts.hosts
    keys = linked.keys
    dispatcher = linked.login(DISPATCHER, a)
    dispatcher.declare_queryable(keys.dispatch_mission,
                                 lambda q: q.reply(keys.dispatch_mission, "the mission"))
    name = linked.hosts.router_name(b)

    def link(endpoint: str, tls: TlsFiles | None) -> zenoh.Session:
        """A session of router b's login on `endpoint`, with these TLS files."""
        session = open_session(BusConfig(
            "client", (endpoint,), connect_timeout_ms=3000, user=name,
            password=linked.secrets.logins[name].password, tls=tls))
        linked.sessions.append(session)
        return session

    # Router b's login and certificate: the router takes it as router b.
    proper = link(a.link_endpoint, linked.secrets.tls[b.name])
    until(lambda: ask(proper, keys.dispatch_mission) == ["the mission"],
          "router b's login and certificate ask the dispatcher")
    # Refused as a router, each asks once: router b's own login and certificate were just
    # answered so, within the same router.
    # The login alone, on the clients' port: in, but not as a router, so it may do nothing.
    assert ask(link(a.endpoint, None), keys.dispatch_mission) == []
    # The login with a certificate of the run under another router's name: the same.
    assert ask(link(a.link_endpoint, linked.secrets.tls[a.name]), keys.dispatch_mission) == []
    # A certificate of the same name from another CA: the TLS handshake is refused.
    (tmp_path / "other").mkdir()
    forged = RunAuthority("other").issue(name, a.address, tmp_path / "other")
    with pytest.raises(zenoh.ZError):
        link(a.link_endpoint, TlsFiles(linked.secrets.tls[b.name].ca, forged.certificate,
                                       forged.private_key))


def test_each_host_has_a_bundle_of_its_own_and_its_router_takes_its_own_processes_logins(
        linked: Linked):
    """Host b's bundle holds its router's key and the logins of what runs on b, nothing of
    host a's: b's router knows no login of a's processes, nor a's router one of b's (but
    router b's own, which links to it)."""
    a, b = linked.hosts.hosts
    assert {p.name for p in linked.secrets.bundle(b).iterdir()} == {
        "users.txt", "acl.json", "ca.pem", "router-b.pem", "router-b.key",
        "router-b.password", "recorder.password", "vehicle-2.password"}
    for principal, host in ((vehicle_sender(1), b), (RECORDER, a), (vehicle_sender(2), a)):
        with pytest.raises(zenoh.ZError):  # refused in the handshake
            open_session(BusConfig("client", (host.endpoint,), connect_timeout_ms=3000,
                                   user=principal,
                                   password=linked.secrets.logins[principal].password))
    linked.login(vehicle_sender(1), a)
    linked.login(RECORDER, b)
