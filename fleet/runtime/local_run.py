"""One mission as processes (what `fleet run` does): a zenoh router on a loopback port, the
recorder, the reservation service, one agent per forklift and the dispatcher, all clients of
the router; or the same spread over several hosts, a router on each (fleet/runtime/hosts.py).
This process follows the dispatcher's progress and result, and stops every child when the
mission ends, on Ctrl-C (the dispatcher first, so the recording ends with how far the mission
got), or as soon as any child dies."""

from __future__ import annotations

import dataclasses
import json
import logging
import queue
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import zenoh

from fleet.mission.faults import FaultKind, Scenario, scenario_toml
from fleet.mission.spec import ClockMode, Mission
from fleet.recording.rundir import fresh
from fleet.recording.segments import next_segment
from fleet.runtime.access import (
    OPERATOR,
    LinkedRouter,
    TlsFiles,
    generate_credentials,
    router_acl,
    write_dictionary,
    write_private,
)
from fleet.runtime.args import BusFlags
from fleet.runtime.argtypes import mqtt_host_port
from fleet.runtime.bus import (
    SLOW_CONNECT_S,
    BusConfig,
    BusError,
    follow_recorded,
    free_port,
    open_session,
)
from fleet.runtime.certificates import RunAuthority
from fleet.runtime.hosts import Host, Hosts, cut_links, one_host
from fleet.runtime.injector import Applied, Injector
from fleet.runtime.launcher import Child, Launcher
from fleet.runtime.linkproxy import LinkProxy
from fleet.runtime.mqtt_broker import start_mosquitto
from fleet.runtime.mqtt_broker import stop as stop_broker
from fleet.runtime.process_configs import (
    AgentConfig,
    DispatcherConfig,
    GatewayConfig,
    ProcessConfig,
    RecorderConfig,
    ReservationConfig,
    RouterConfig,
)
from fleet.wire.protocol import MissionDone, Progress, ProtocolError, decode
from fleet.wire.topics import (
    DISPATCHER,
    RECORDER,
    RESERVATION,
    Keys,
    genuine,
    published_by,
    vehicle_of,
    vehicle_sender,
)
from fleet.world.layout_file import load_layout

DISPATCHER_JOURNAL = "dispatcher.journal"  # for a restarted one: who is down, an order book
FAULTS_AS_LIVED = "faults.toml"  # a scenario's host cuts as its forklifts' link cuts
ROUTER_TIMEOUT_MS = 30_000
ROUTER_ATTEMPT_MS = 500  # one connect attempt: a router that died is noticed within this
RECORDED_TIMEOUT_S = 10.0
log = logging.getLogger("fleet.run")


@dataclass
class RunSpec:
    mission: Mission
    vehicles: int
    run_dir: Path  # the recording, logs/ and the reservation journal: a new directory, or
    # one claimed for this run a moment ago (fleet.recording.rundir.claim); anything else is refused
    clock: ClockMode = ClockMode.FAST
    speed: float = 1.0
    weights: Path | None = None
    port: int | None = None  # router port on 127.0.0.1 (default: a free one)
    run: str = "default"
    extra: dict[str, list[str]] = field(default_factory=dict)  # more flags per process kind
    command: str = ""  # the user's command line, for the recording
    foxglove: int | None = None  # serve the live Foxglove view on this port
    record: bool = True  # start the recorder (benchmarks measure the run without it)
    faults: Scenario | None = None  # applied by an injector in this process
    # The scenario's name or file, for the dispatcher (a seed-004 run's dispatcher applies
    # most of its faults itself; `faults` holds only what the injector does)
    faults_source: str = ""
    # Whether the agents follow the clock (seed 004's do not: the injector waits for no ack
    # of theirs before it strikes them)
    clocked_agents: bool = True
    secure: bool = False  # access control and a login per process (fleet/runtime/access.py)
    # DISPATCH_MODES: "vda5050" and "external" run the VDA 5050 gateway on `mqtt`
    dispatch: str = "internal"
    mqtt: str = ""
    own_broker: bool = False  # start a mosquitto on `mqtt`'s port of 127.0.0.1 for the run
    hosts: Hosts | None = None  # several hosts (None: this one, the router on `port`)

    @property
    def recording(self) -> Path:
        return self.run_dir / "run.mcap"


@dataclass
class RunOutcome:
    done: MissionDone | None
    error: str
    endpoint: str
    log_dir: Path
    injected: list[Applied] = field(default_factory=list)  # the faults' actions, when


class RunFailed(RuntimeError):
    pass


def dispatcher_config(spec: RunSpec, bus: BusFlags, recover: bool) -> DispatcherConfig:
    """The dispatcher of the run (`recover`: a restarted one picks the mission up)."""
    return DispatcherConfig(bus, dataclasses.replace(spec.mission, vehicles=spec.vehicles),
                            spec.weights, spec.clock, spec.speed, command=spec.command,
                            faults=spec.faults_source or None,
                            recorded=spec.record, recover=recover,
                            journal=spec.run_dir / DISPATCHER_JOURNAL,
                            dispatch=spec.dispatch,
                            **({"mqtt": spec.mqtt} if spec.mqtt else {}))


class Secrets:
    """A secure run's logins (fleet/runtime/access.py) and, on several hosts, the certificates
    its routers link with (fleet/runtime/certificates.py), kept in the run directory as a
    bundle per host (`secrets/NAME/`, readable by its owner only) that holds what that host
    needs and no more: its router's dictionary of the logins it checks (its own processes',
    and on the first host the other routers'), its access control (`lifting`: the rules of
    seed 004's lifting AGVs), the run's CA certificate with its router's key and
    certificate, and the password of each process it runs (another host's router logs in to
    the first host's under its process name, router-NAME). A host given its bundle alone
    can pose as none of the other hosts' routers or processes."""

    def __init__(self, folder: Path, run: str, root: str, vehicles: int, hosts: Hosts,
                 lifting: bool = False) -> None:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        self.folder = folder
        self.hosts = hosts
        first, others = hosts.first, hosts.hosts[1:]
        routers = [hosts.router_name(h) for h in others]
        self.logins = generate_credentials(run, vehicles, routers).logins
        authority = RunAuthority(run) if others else None
        self.tls: dict[str, TlsFiles] = {}
        for host in hosts.hosts:
            bundle = self.bundle(host)
            bundle.mkdir(mode=0o700, exist_ok=True)
            here = [p for p in self.logins if self.host_of(p) == host]
            checked = [p for p in here if p not in routers] + (routers if host == first else [])
            write_dictionary((self.logins[p] for p in checked), self.users(host))
            if host == first:  # the others log in, with their certificates
                linked = tuple(LinkedRouter(name, name) for name in routers)
            else:  # the first's certificate: it accepts the link, so it logs in nowhere
                linked = (LinkedRouter(hosts.router_name(first)),)
            write_private(self.acl(host), json.dumps(router_acl(root, vehicles, lifting,
                                                                linked), indent=1))
            for principal in here:
                write_private(self.password_file(principal), self.logins[principal].password)
            if authority is not None:
                self.tls[host.name] = authority.issue(hosts.router_name(host), host.address,
                                                      bundle)

    def bundle(self, host: Host) -> Path:
        """What the host needs, alone: give it this directory and nothing else of `secrets/`."""
        return self.folder / host.name

    def host_of(self, principal: str) -> Host:
        """Where the process that logs in as `principal` runs (the operator: with fleet run,
        on the first host; a router on its own)."""
        for host in self.hosts.hosts[1:]:
            if principal == self.hosts.router_name(host):
                return host
        vehicle = vehicle_of(principal)
        return self.hosts.of_process(f"agent-{vehicle}" if vehicle is not None else principal)

    def password_file(self, principal: str) -> Path:
        return self.bundle(self.host_of(principal)) / f"{principal}.password"

    def users(self, host: Host) -> Path:
        """The dictionary of the host's router."""
        return self.bundle(host) / "users.txt"

    def acl(self, host: Host) -> Path:
        """The access control of the host's router."""
        return self.bundle(host) / "acl.json"

    def router(self, host: Host, config: RouterConfig) -> RouterConfig:
        """The host's router `config`, secured: its access control and the dictionary, and
        on several hosts its certificate; the first host's also takes the others' links on
        its TLS endpoint, another logs in to the first's under its name."""
        config = dataclasses.replace(config, acl=self.acl(host), users=self.users(host),
                                     tls=self.tls.get(host.name))
        if not self.tls:
            return config
        if host == self.hosts.first:
            return dataclasses.replace(config, listen=(*config.listen, host.link_endpoint))
        name = self.hosts.router_name(host)
        return dataclasses.replace(config, user=name, password_file=self.password_file(name))


def run_processes(spec: RunSpec, on_progress: Callable[[Progress], None] | None = None,
                  on_ready: Callable[[zenoh.Session, Keys, Launcher], None] | None = None
                  ) -> RunOutcome:
    """Run the mission; `on_ready` is called with this process's session, the keys and the
    launcher once every child has been started (tests use it to watch or disturb the run)."""
    hosts = spec.hosts or one_host(spec.port or free_port())
    endpoint = hosts.first.endpoint
    keys = Keys(spec.run)
    fresh(spec.run_dir)  # a run directory of its own: no table, recording or log of another
    log_dir = spec.run_dir / "logs"
    journal = spec.run_dir / "reservation.journal"
    # Everything this process waits for comes through one queue: the dispatcher's messages,
    # a started child's liveliness, and each child's exit the moment it happens.
    inbox: queue.Queue[tuple[str, object]] = queue.Queue()
    launcher = Launcher(log_dir, on_exit=lambda child: inbox.put(("exit", child)))
    session = None
    injector = None
    faults = spec.faults.faults if spec.faults else ()
    # A forklift whose link a fault cuts reaches its router through its own forwarder, a host
    # whose link a fault cuts reaches the first host's router through one; both forward on
    # the first host, where the injector is.
    proxies = {f.vehicle: LinkProxy(hosts.of_process(f"agent-{f.vehicle}").address,
                                    hosts.of_process(f"agent-{f.vehicle}").port,
                                    listen_host=hosts.first.address)
               for f in faults if f.kind is FaultKind.CUT_LINK}
    # A secure run's routers link over TLS, on the first host's link port.
    first = hosts.first
    host_links = {f.host: LinkProxy(first.address, first.link_port, first.address, "tls")
                  if spec.secure else LinkProxy(first.address, first.port, first.address)
                  for f in faults if f.kind is FaultKind.CUT_HOST and f.host}
    if host_links and spec.faults is not None:  # the dispatcher detects them link by link
        lived = spec.run_dir / FAULTS_AS_LIVED
        lived.write_text(scenario_toml(cut_links(spec.faults, hosts),
                                       f"{spec.faults.name}, each host cut as a cut of its "
                                       f"forklifts' links"))
        spec = dataclasses.replace(spec, faults_source=str(lived))
    secrets = Secrets(spec.run_dir / "secrets", spec.run, keys.root, spec.vehicles, hosts,
                      lifting=load_layout(spec.mission.layout).floor is not None) \
        if spec.secure else None
    recorded = threading.Event()  # the recorder holds the mission's result

    def bus(principal: str, connect: str) -> BusFlags:
        """How a process reaches its router, logged in as `principal` in a secure run."""
        if secrets is None:
            return BusFlags(spec.run, connect=(connect,))
        return BusFlags(spec.run, connect=(connect,), user=principal,
                        password_file=secrets.password_file(principal))

    def config_of(kind: str, again: bool) -> ProcessConfig:
        own = hosts.of_process(kind).endpoint  # its host's router
        if kind == "recorder":  # run.mcap, then run-2.mcap after a restart
            return RecorderConfig(bus(RECORDER, own), next_segment(spec.run_dir),
                                  foxglove=spec.foxglove)
        if kind == "reservation":
            return ReservationConfig(bus(RESERVATION, own), journal)
        if kind.startswith("agent-"):
            v = int(kind.split("-")[1])
            return AgentConfig(bus(vehicle_sender(v), proxies[v].endpoint if v in proxies
                                   else own), v)
        if kind == "dispatcher":  # a restart picks the mission up where it was
            return dispatcher_config(spec, bus(DISPATCHER, own), recover=again)
        if kind == "vda5050":
            return GatewayConfig(bus("vda5050", own), spec.mqtt)
        raise RunFailed(f"cannot restart a {kind} process")

    def args_of(kind: str, again: bool = False) -> list[str]:
        """How to start each kind of process (`again`: after a fault killed it)."""
        config = config_of(kind, again)
        return [*config.argv(), *spec.extra.get(config.COMMAND, [])]

    def start(kind: str) -> Child:
        """Start a process on its host."""
        return launcher.start(kind, args_of(kind), hosts.of_process(kind).exec)

    broker = None
    try:
        if spec.own_broker:
            broker = start_mosquitto(log_dir / "mosquitto", mqtt_host_port(spec.mqtt)[1])
        for proxy in (*proxies.values(), *host_links.values()):
            proxy.start()
        def router_config(host: Host, connect: tuple[str, ...]) -> RouterConfig:
            config = RouterConfig((host.endpoint,), connect)
            return secrets.router(host, config) if secrets else config

        router = launcher.start("router", router_config(hosts.first, ()).argv())
        linking = []  # each other host's router, and where it links to the first host's
        for host in hosts.hosts[1:]:  # linked to the first host's, through a fault's forwarder
            if host.name in host_links:
                link = host_links[host.name].endpoint
            else:
                link = hosts.first.link_endpoint if spec.secure else endpoint
            config = dataclasses.replace(router_config(host, (link,)),
                                         announce=keys.router_linked(host.name))
            linking.append((launcher.start(hosts.router_name(host), config.argv(), host.exec),
                            config.announce, link))

        def start_workers() -> Child | None:
            """Start the recorder (returned; None: the run records nothing), the reservation
            service and the agents. The recorder misses nothing the others say: the agents
            wait for the dispatcher to say what the mission is, and it starts once the
            recorder is up."""
            started = start("recorder") if spec.record else None
            start("reservation")
            for v in range(1, spec.vehicles + 1):
                start(f"agent-{v}")
            return started

        # On one host they start with the router and connect as soon as it listens; on
        # several, once every router is linked (nothing runs on a host that is not).
        recorder = None if linking else start_workers()
        operator = secrets.logins[OPERATOR] if secrets else None
        session = _open_when_up(BusConfig("client", (endpoint,),
                                          user=operator.user if operator else "",
                                          password=operator.password if operator else ""),
                                router)
        for child, token, link in linking:  # nothing of its host's reaches this one before
            _wait_started(session, token, inbox, child, f"{child.name} did not link to the "
                          f"first host's router (at {link}) within {ROUTER_TIMEOUT_MS / 1000:g} "
                          f"s: are the hosts file's addresses and ports right, and open "
                          f"between the hosts?")
        if linking:
            recorder = start_workers()
        subscribers = [session.declare_subscriber(key, lambda s: inbox.put(("sample", s)))
                       for key in (keys.dispatch_progress, keys.dispatch_done)]
        clock_started = threading.Event()  # every forklift was up: the mission runs
        subscribers.append(session.declare_subscriber(keys.clock,
                                                      lambda _: clock_started.set()))
        if recorder is not None:
            subscribers.append(follow_recorded(session, keys, recorded, log))
            _wait_started(session, keys.recorder_alive, inbox, recorder)
        if spec.faults is not None:
            injector = Injector(spec.faults, session, keys, launcher,
                                lambda kind: args_of(kind, again=True), proxies,
                                host_links=host_links, hosts=hosts,
                                clocked_agents=spec.clocked_agents)
        start("dispatcher")
        if spec.dispatch != "internal":
            start("vda5050")
        if on_ready is not None:
            on_ready(session, keys, launcher)
        done = _follow(inbox, on_progress, clock_started)
        if spec.record and not recorded.wait(RECORDED_TIMEOUT_S):
            log.warning("the recorder had not recorded the mission's result within %g s",
                        RECORDED_TIMEOUT_S)
        for subscriber in subscribers:
            subscriber.undeclare()
        return RunOutcome(done, "" if done.ok else done.error, endpoint, log_dir,
                          injector.applied if injector else [])
    except RunFailed as exc:
        return RunOutcome(None, str(exc), endpoint, log_dir)
    except KeyboardInterrupt:  # Ctrl-C, or SIGTERM as fleet run has it: what ran is recorded
        if spec.record and session is not None:
            _stop_dispatcher_first(launcher, recorded)
        raise
    finally:
        if injector is not None:
            injector.close()
        if session is not None:
            session.close()  # before the router is told to stop: it waits for its clients
        launcher.stop_all()
        for proxy in (*proxies.values(), *host_links.values()):
            proxy.close()
        if broker is not None:  # after the gateway: its clean goodbye reaches the broker
            stop_broker(broker)


def _stop_dispatcher_first(launcher: Launcher, recorded: threading.Event) -> None:
    """Stop the dispatcher alone, and wait (up to RECORDED_TIMEOUT_S) until the recorder
    holds its last word: how far the mission got and its result (docs/runtime.md)."""
    try:
        launcher.signal("dispatcher", signal.SIGTERM)
    except RuntimeError:  # not started yet, or gone: it has nothing more to say
        return
    if not recorded.wait(RECORDED_TIMEOUT_S):
        log.warning("the recorder had not recorded the dispatcher's last word within %g s",
                    RECORDED_TIMEOUT_S)


def _follow(inbox: queue.Queue, on_progress: Callable[[Progress], None] | None,
            clock_started: threading.Event) -> MissionDone:
    while True:
        kind, item = inbox.get()  # a message, or a child's exit, as it happens
        if kind == "exit":
            # A fault's kill is the injector's, a forklift's death once the mission runs the
            # dispatcher's to recover from (docs/faults.md); any other death ends the run (a
            # forklift that never came up would keep the dispatcher waiting for it).
            if item.killed or (item.name.startswith("agent-") and clock_started.is_set()):
                continue
            done = _last_word(inbox)
            if done is not None:
                return done  # the dispatcher's account of it, when it has one
            raise RunFailed(Launcher.death(item, "before the mission ended"))
        message = _from_dispatcher(item) if kind == "sample" else None
        if isinstance(message, MissionDone):
            return message
        if isinstance(message, Progress) and on_progress is not None:
            on_progress(message)


def _open_when_up(config: BusConfig, router: Child) -> zenoh.Session:
    """This process's session, once the router takes connections; at once a RunFailed that
    says why when the router exits first (a busy port, a bad access control file). Zenoh's
    open cannot be interrupted, so it is tried in short attempts with the router's exit
    looked at between them."""
    attempt = dataclasses.replace(config, connect_timeout_ms=ROUTER_ATTEMPT_MS)
    start = time.monotonic()
    said = False
    while True:
        try:  # each attempt quiet: its own note would give its 0.5 s as the whole wait
            return open_session(attempt, say=lambda _: None)
        except BusError as exc:
            if router.proc.poll() is not None:
                raise RunFailed(Launcher.death(router, "before the run started")) from None
            waited = time.monotonic() - start
            if waited > ROUTER_TIMEOUT_MS / 1000:
                raise RunFailed(f"the router took no connection within "
                                f"{ROUTER_TIMEOUT_MS / 1000:g} s: {exc}") from None
            if not said and waited >= SLOW_CONNECT_S:
                log.warning("waiting for the router at %s to take connections (up to %g s)",
                            ", ".join(config.connect), ROUTER_TIMEOUT_MS / 1000)
                said = True


def _wait_started(session: zenoh.Session, token: str, inbox: queue.Queue, child: Child,
                  late: str = "") -> None:
    """Wait for a child's liveliness token; fail at once, saying why, if it or another child
    exits first (only exits and tokens come through the inbox before the dispatcher
    starts). `late` says what it means when the token does not come in time."""
    alive = session.liveliness().declare_subscriber(
        token, lambda sample: inbox.put(("alive", str(sample.key_expr)))
        if sample.kind == zenoh.SampleKind.PUT else None, history=True)
    try:
        deadline = time.monotonic() + ROUTER_TIMEOUT_MS / 1000
        while (left := deadline - time.monotonic()) > 0:
            try:
                kind, item = inbox.get(timeout=left)
            except queue.Empty:
                break
            if kind == "alive" and item == token:  # not a late one of an earlier wait
                return
            if kind == "exit" and not item.killed:
                raise RunFailed(Launcher.death(item, "as it started" if item is child
                                               else "before the mission ended"))
        raise RunFailed((late or f"{child.name} was not up within "
                                 f"{ROUTER_TIMEOUT_MS / 1000:g} s (no {token} token)")
                        + f"; its log: {child.log}")
    finally:
        alive.undeclare()


def _last_word(inbox: queue.Queue, within_s: float = 3.0) -> MissionDone | None:
    """The dispatcher's result if it arrives soon (it notices a dead forklift by liveliness
    and says which one and when)."""
    deadline = time.monotonic() + within_s
    while (left := deadline - time.monotonic()) > 0:
        try:
            kind, item = inbox.get(timeout=left)
        except queue.Empty:
            return None
        message = _from_dispatcher(item) if kind == "sample" else None
        if isinstance(message, MissionDone):
            return message
    return None


def _from_dispatcher(sample: zenoh.Sample) -> MissionDone | Progress | None:
    """The dispatcher's progress or result, believed only on its own key from its own name
    (anyone on the network could put a forged result)."""
    try:
        envelope = decode(sample.payload.to_bytes())
    except ProtocolError as exc:
        log.warning("rejected a message on %s: %s", sample.key_expr, exc)
        return None
    message, key = envelope.message, str(sample.key_expr)
    if not isinstance(message, MissionDone | Progress):
        log.warning("rejected a %s on %s: it does not belong there", message.TYPE, key)
        return None
    if not genuine(key, envelope):
        wanted = published_by(DISPATCHER)[type(message)].pattern
        log.warning("ignored a %s on %s from %r: only the dispatcher's on %s counts",
                    message.TYPE, key, envelope.sender, wanted)
        return None
    return message
