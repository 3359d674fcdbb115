"""The fault injector of `fleet run --faults`: it applies a scenario's faults to the run's
processes as the clock passes their instants (docs/faults.md).

It follows the clock like a forklift: on each tick it applies every action due by then, then
acknowledges the tick, so in fast mode the clock stands still until the fault is in place.
Signals and restarts go to the launcher's children; a link is cut at the forklift's own
forwarder (fleet/runtime/linkproxy.py), a host's at the forwarder between its router and the
first host's; a breakdown or a slow planner is told to the agent, which
plays the hardware. Detection and recovery are not its business: the dispatcher notices a
fault as it would notice a real one.
"""

from __future__ import annotations

import logging
import queue
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import zenoh

from fleet.mission.faults import Fault, FaultKind, Scenario
from fleet.mission.spec import ClockMode
from fleet.runtime.bus import Requester, RequestFailed, Stream, received, wait_gone
from fleet.runtime.hosts import Hosts
from fleet.runtime.launcher import Launcher
from fleet.runtime.linkproxy import LinkProxy
from fleet.wire.protocol import ClockAck, ClockTick, InjectFault, Reply
from fleet.wire.topics import INJECTOR, Keys

log = logging.getLogger("fleet.runtime.injector")
SENDER = INJECTOR
INJECTOR_ID = 0  # its ClockAck's vehicle field
ACK_WAIT_S = 10.0
SERVICE_GONE_S = 10.0
DUE = object()  # the worker's wake-up for an action due on a real-time clock


@dataclass(frozen=True)
class Action:
    t: float
    what: str  # for the log and the bench: "kill agent-2", ...
    apply: Callable[[], None]
    vehicles: tuple[int, ...] = ()  # the forklifts it stops: applied once they acked the tick
    ends: bool = False  # it ends a fault (restart, continue, restore, repair)


@dataclass
class Applied:
    """When an action was applied: sim time and wall clock as it began (the bench measures
    from it)."""

    what: str
    t: float
    wall: float
    fault: Fault
    ends: bool


@dataclass
class Injector:
    scenario: Scenario
    session: zenoh.Session
    keys: Keys
    launcher: Launcher
    restart_args: Callable[[str], list[str]]  # fleet arguments to start a process kind again
    proxies: dict[int, LinkProxy] = field(default_factory=dict)
    # A run on several hosts: each host's link to the first, and who runs there
    host_links: dict[str, LinkProxy] = field(default_factory=dict)
    hosts: Hosts | None = None
    applied: list[Applied] = field(default_factory=list)
    clocked_agents: bool = True  # they ack each tick: a stop waits until theirs is in

    def __post_init__(self) -> None:
        self.actions = sorted(((a, f) for f in self.scenario.faults for a in self._actions(f)),
                              key=lambda pair: pair[0].t)
        self.requester = Requester(self.session, SENDER, timeout_s=10.0, retry_s=10.0)
        self.inbox: queue.Queue[zenoh.Sample | None] = queue.Queue()
        self.ack = Stream(self.session, self.keys.injector_ack, SENDER, reliable=True)
        self.acked: dict[int, int] = {}  # forklift -> last tick it acknowledged
        self.acks = threading.Condition()
        self.subscribers = [
            self.session.declare_subscriber(self.keys.clock, self.inbox.put),
            self.session.declare_subscriber(self.keys.clock_ack("*"), self._on_ack)]
        self.worker = threading.Thread(target=self._work, name="injector", daemon=True)
        self.worker.start()
        self.restarts: dict[str, int] = {}

    def close(self) -> None:
        for subscriber in self.subscribers:
            subscriber.undeclare()
        self.inbox.put(None)
        self.worker.join()
        self.ack.undeclare()
        for proxy in (*self.proxies.values(), *self.host_links.values()):
            proxy.close()

    def _work(self) -> None:
        """Fast clock: apply what is due by each tick, then acknowledge it. Real time: apply
        each action when the clock's anchor says its instant has come."""
        last: ClockTick | None = None
        while True:
            try:
                sample = self.inbox.get(timeout=self._until_due(last))
            except queue.Empty:  # real time: the next action's instant has come
                sample = DUE
            if sample is None:
                return
            if sample is not DUE:
                tick = received(sample, ClockTick, log)
                if tick is None or (last is not None and tick.tick <= last.tick):
                    continue
                last = tick
            if last is None:
                continue
            fast = last.mode == ClockMode.FAST
            now = last.t if fast else last.t + last.speed * max(0.0, time.time() - last.wall)
            while self.actions and self.actions[0][0].t <= now:
                action, fault = self.actions.pop(0)
                if fast and self.clocked_agents:
                    for vehicle in action.vehicles:  # what it said is on its way first
                        self._wait_ack(vehicle, last.tick)
                started = time.time()  # the fault's moment: applying it may take a while
                try:
                    action.apply()
                except (OSError, RequestFailed, RuntimeError) as exc:  # never stop the clock
                    log.error("fault action %r failed: %s", action.what, exc)
                self.applied.append(Applied(action.what, action.t, started, fault,
                                            action.ends))
                log.warning("t=%.2f: %s", action.t, action.what)
            if fast and sample is not DUE:
                self.ack.put(ClockAck(last.tick, INJECTOR_ID), last.t)

    def _until_due(self, last: ClockTick | None) -> float | None:
        """Wall seconds to the next action on a real-time clock (None: wait for a tick)."""
        if last is None or last.mode == ClockMode.FAST or not self.actions:
            return None
        due = last.wall + (self.actions[0][0].t - last.t) / last.speed
        return max(0.0, due - time.time())

    def _on_ack(self, sample: zenoh.Sample) -> None:
        ack = received(sample, ClockAck, log)
        if ack is not None:
            with self.acks:
                self.acked[ack.vehicle] = max(self.acked.get(ack.vehicle, 0), ack.tick)
                self.acks.notify_all()

    def _wait_ack(self, vehicle: int, tick: int) -> None:
        with self.acks:
            if not self.acks.wait_for(lambda: self.acked.get(vehicle, 0) >= tick, ACK_WAIT_S):
                log.warning("forklift %d did not acknowledge tick %d: faulting it anyway",
                            vehicle, tick)

    # -- what each kind does -------------------------------------------------------------------
    def _actions(self, fault: Fault) -> list[Action]:
        k, v = fault.kind, fault.vehicle
        agent = f"agent-{v}"
        if k is FaultKind.KILL_VEHICLE:
            out = [Action(fault.at, f"kill {agent}", lambda: self.launcher.kill(agent), (v,))]
            if fault.duration is not None:
                out.append(Action(fault.until, f"restart {agent}",
                                  lambda: self._restart(agent), ends=True))
            return out
        if k is FaultKind.STALL_VEHICLE:
            return [Action(fault.at, f"stall {agent}",
                           lambda: self.launcher.signal(agent, signal.SIGSTOP), (v,)),
                    Action(fault.until, f"continue {agent}",
                           lambda: self.launcher.signal(agent, signal.SIGCONT), ends=True)]
        if k is FaultKind.CUT_LINK:
            return [Action(fault.at, f"cut the link of {agent}", lambda: self.proxies[v].cut(),
                           (v,)),
                    Action(fault.until, f"restore the link of {agent}",
                           lambda: self.proxies[v].restore(), ends=True)]
        if k is FaultKind.CUT_HOST:
            name = fault.host or ""
            link = self.host_links[name]
            host = self.hosts.host(name) if self.hosts is not None else None
            return [Action(fault.at, f"cut the link of host {name}", link.cut,
                           host.vehicles if host is not None else ()),
                    Action(fault.until, f"restore the link of host {name}", link.restore,
                           ends=True)]
        if k is FaultKind.SLOW_PLANNER:
            return [Action(fault.at, f"slow the planner of {agent} {fault.factor:g}x",
                           lambda: self._tell(v, "slow_planner", fault.factor)),
                    Action(fault.until, f"restore the planner of {agent}",
                           lambda: self._tell(v, "slow_planner", 1.0), ends=True)]
        if k is FaultKind.VEHICLE_BREAKDOWN:
            out = [Action(fault.at, f"break down forklift {v}",
                          lambda: self._tell(v, "breakdown"), (v,))]
            if fault.duration is not None:
                out.append(Action(fault.until, f"repair forklift {v}",
                                  lambda: self._tell(v, "repair"), ends=True))
            return out
        if k is FaultKind.KILL_SERVICE:
            name = fault.service or ""
            return [Action(fault.at, f"kill the {name} for {fault.downtime:g} s",
                           lambda: self._kill_service(name, fault.downtime))]
        return []  # close_zone: the dispatcher closes it itself

    def _restart(self, kind: str) -> None:
        n = self.restarts[kind] = self.restarts.get(kind, 1) + 1
        self.launcher.restart(kind, f"{kind}-{n}", self.restart_args(kind))

    def _kill_service(self, name: str, downtime: float) -> None:
        """Kill now; start again after `downtime` wall seconds (the mission may not advance
        without the service, so the delay cannot be sim time). The tick is acknowledged only
        once its token is gone, so the fast clock holds from the instant it died."""
        self.launcher.kill(name)
        token = {"recorder": self.keys.recorder_alive, "dispatcher": self.keys.dispatcher_alive,
                 "reservation": self.keys.reservation_alive}[name]
        if not wait_gone(self.session, token, SERVICE_GONE_S):
            log.warning("the %s's liveliness token outlived it by %g s", name, SERVICE_GONE_S)
        timer = threading.Timer(downtime, self._restart, args=(name,))
        timer.daemon = True
        timer.start()

    def _tell(self, vehicle: int | None, kind: str, factor: float = 1.0) -> None:
        assert vehicle is not None
        request = InjectFault(self.requester.next_id(), vehicle, kind, factor)
        reply = self.requester.request(self.keys.vehicle_inject(vehicle), request).message
        if not isinstance(reply, Reply) or not reply.ok:
            raise RuntimeError(f"forklift {vehicle} did not take {kind}: {reply}")
