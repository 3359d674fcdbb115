"""The one source of "now" for every process of a run: all planning is in sim time, and the
dispatcher publishes it on fleet/<run>/clock (docs/runtime.md). Both clocks are `Pacer`s of the
engine (fleet/mission/seam.py).

Fast: discrete events. Before each decision the clock moves to the decision's instant and
waits until every agent has acknowledged the tick (having published its states up to it), so
a run is deterministic and every state stream is complete up to "now". With a fault scenario
it also stops at every fault instant, waits for the injector's ack (the fault is applied) and
then for the fault to be detected the way it would be anyway (a liveliness token gone or
back, a forklift's own report): sim time stands still meanwhile, so a fault run is as
reproducible as any other and detection costs no sim time (docs/faults.md).
Real time: sim time = speed x wall time since the start; ticks carry the wall anchor so every
process computes the same "now". The dispatcher decides each subtask a lead ahead of its
instant (dispatcher/pacing.py), so a run that keeps up decides what the fast clock would; a
forklift whose free time has already passed waits until the next instant a plan can still
be ready for, and the dispatcher's log says so. Faults are noticed as they come, and frozen
a margin ahead of now, so that every forklift that can move hears of the freeze before it.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Mapping
from contextlib import ExitStack

import zenoh

from dispatcher.liveness import Liveness, ParticipantLost
from dispatcher.pacing import LEAD_WALL_S, Late, RealtimePacing
from fleet.mission.faults import DETECT_TIMEOUT_S, FaultKind, Scenario
from fleet.mission.freeze import (
    BREAKDOWN,
    CAUSES,
    Disruption,
    VehicleDown,
    VehicleUp,
    ZoneClosure,
    scheduled_at,
)
from fleet.mission.spec import ClockMode
from fleet.runtime.bus import RELIABLE, received
from fleet.wire.protocol import ClockAck, ClockTick, VehicleFault, encode
from fleet.wire.topics import CLOCK, Keys

log = logging.getLogger("fleet.dispatcher")
SENDER = CLOCK
ACK_TIMEOUT_S = 60.0
INJECTOR = 0  # the fault injector acknowledges ticks as "vehicle" 0
RECORDER_WAIT_S = 60.0


class _Clock:
    """What both clocks share: the publisher of the ticks, the forklifts' fault reports
    (heard with liveliness, under `liveness.changed`, which the clocks wait on) and what was
    detected."""

    def __init__(self, session: zenoh.Session, keys: Keys, vehicles: list[int],
                 liveness: Liveness, down: frozenset[int] = frozenset()) -> None:
        """`down`: forklifts down when a restarted dispatcher's clock starts."""
        self.vehicles = vehicles
        self.liveness = liveness
        # Each token's appearances when its forklift was last known up (every one not `down`
        # is, now): one that came again since went, however short its absence. One down is
        # back once its token is here (a restarted agent may be here already).
        self.generation: dict[int, int] = dict(liveness.appeared) | {v: -1 for v in down}
        # Each fault seen: what, its sim instant, and the wall clock when it was detected and
        # when the engine had recovered (asked the clock again): `fleet bench faults` reads it.
        self.detected: list[dict] = []
        self.declared = ExitStack()
        self.publisher = self.declared.enter_context(
            session.declare_publisher(keys.clock, congestion_control=RELIABLE))

    def _send(self, tick: ClockTick) -> None:
        self.publisher.put(encode(tick, SENDER, tick.tick, tick.t))

    def _listen(self, session: zenoh.Session, keys: Keys) -> None:
        """Hear the forklifts' fault reports; called once the clock is ready for them."""
        self.declared.enter_context(
            session.declare_subscriber(keys.vehicle_fault("*"), self._on_fault))

    def _on_fault(self, sample: zenoh.Sample) -> None:
        message = received(sample, VehicleFault, log)
        if message is not None and message.vehicle in self.vehicles:
            with self.liveness.changed:  # what the clock waits on, with liveliness
                self._reported(message.vehicle, message.state)
                self.liveness.changed.notify_all()

    def _reported(self, vehicle: int, state: str) -> None:
        """A forklift's report ("broken", "repaired"), taken holding liveness.changed."""
        raise NotImplementedError

    def close(self) -> None:
        self.declared.close()


class FastClock(_Clock):
    def __init__(self, session: zenoh.Session, keys: Keys, vehicles: list[int],
                 liveness: Liveness, scenario: Scenario | None = None,
                 recorded: bool = False, tick: int = 0, t: float = 0.0,
                 down: frozenset[int] = frozenset(), heard: Mapping[int, str] | None = None
                 ) -> None:
        """`tick` and `t`: where a restarted dispatcher's clock goes on from (the forklifts
        refuse a tick that is not after the last one they heard); `down`: the forklifts
        down then; `heard`: each breakdown as its agent said it was ("broken", "repaired")."""
        super().__init__(session, keys, vehicles, liveness, down)
        self.recorded = recorded
        self.scenario = scenario
        self.pending = [i for i in scenario.instants() if i > t] if scenario else []
        self.down = down
        # Down by the scenario, back by it too.
        self.scheduled_down: set[int] = {f.vehicle for f in scenario.faults
                                         if f.vehicle in down and f.kind in CAUSES
                                         and f.at <= t < f.until} if scenario else set()
        self.tick = tick
        self.t = t
        self.acked: dict[int, int] = {}
        # (forklift, "broken" / "repaired") heard; guarded by liveness.changed
        self.reports: set[tuple[int, str]] = set((heard or {}).items())
        self.changed = threading.Condition()
        self.declared.enter_context(session.declare_subscriber(keys.clock_ack("*"),
                                                               self._on_ack))
        self._listen(session, keys)

    def _on_ack(self, sample: zenoh.Sample) -> None:
        message = received(sample, ClockAck, log)
        if message is None:
            return
        with self.changed:
            self.acked[message.vehicle] = max(self.acked.get(message.vehicle, 0), message.tick)
            self.changed.notify_all()

    def _reported(self, vehicle: int, state: str) -> None:
        self.reports.add((vehicle, state))  # what _detect waits for

    @property
    def awaited(self) -> list[int]:
        """Who must acknowledge a tick: every forklift not down, and the injector."""
        return [v for v in self.vehicles if v not in self.down] + \
            ([INJECTOR] if self.scenario else [])

    def advance(self, t: float) -> None:
        """Move to t and wait for the acks. A forklift whose token goes meanwhile is not
        waited for: `disruptions` reports it."""
        self.tick += 1
        self.t = max(self.t, t)
        self._send(ClockTick(self.tick, ClockMode.FAST.value, self.t, down=sorted(self.down)))
        deadline = time.monotonic() + ACK_TIMEOUT_S
        with self.changed:
            while late := [v for v in self.awaited if self.acked.get(v, 0) < self.tick and
                           (v == INJECTOR or v in self.liveness.alive)]:
                if time.monotonic() > deadline:
                    raise ParticipantLost(f"{_who(late)} did not acknowledge tick "
                                          f"{self.tick} (t={self.t}) within {ACK_TIMEOUT_S} s")
                self.changed.wait(0.5)  # wakes on every ack; the timeout re-checks liveness
        if self.recorded:  # sim time stands still while no recorder runs (a killed one)
            self.liveness.wait_for_recorder(RECORDER_WAIT_S)

    def resumed(self, vehicle: int) -> None:
        pass  # ticks go out only as the clock advances, with the engine's down set then

    def disruptions(self, t_next: float, down: frozenset[int]) -> list[Disruption]:
        self.down = down
        _recovered(self.detected)
        while self.pending and self.pending[0] <= t_next:
            t = self.pending.pop(0)
            self.advance(t)
            found = [self._detect(d) for d in scheduled_at(self.scenario, t)]
            if found:
                return found
        return self._unscheduled(down)

    def _unscheduled(self, down: frozenset[int]) -> list[Disruption]:
        """Forklifts lost or back without a scenario saying so (a killed, paused or cut-off
        container): gone when their token goes, or went and came again since they were last
        known up; back once it has come again since. A forklift the engine lost itself (its
        agent did not answer) may be back before the clock was asked: its token's
        appearances say so."""
        with self.liveness.changed:
            alive, appeared = set(self.liveness.alive), dict(self.liveness.appeared)
        came_again = {v for v in self.vehicles
                      if appeared.get(v, 0) > self.generation.get(v, 0)}
        back = sorted(v for v in down - self.scheduled_down if v in alive & came_again)
        lost = sorted(v for v in self.vehicles
                      if v not in down and (v not in alive or v in came_again))
        for v in back:
            self.generation[v] = appeared[v]
        return [VehicleUp(v, self.t) for v in back] + \
            [VehicleDown(v, self.t, "agent lost (its liveliness token is gone)") for v in lost]

    def _detect(self, expected: Disruption) -> Disruption:
        """Wait until the fault is seen the way it would be without a schedule."""
        started = time.monotonic()
        if isinstance(expected, VehicleDown):
            v = expected.vehicle
            seen = (lambda: (v, "broken") in self.reports) if expected.cause == BREAKDOWN \
                else (lambda: v not in self.liveness.alive)
        elif isinstance(expected, VehicleUp):
            v = expected.vehicle
            seen = (lambda: (v, "repaired") in self.reports) if \
                (v, "broken") in self.reports else (lambda: v in self.liveness.alive)
        else:
            return expected  # a zone closes by the schedule itself
        with self.liveness.changed:  # liveliness and fault reports notify it
            if not self.liveness.changed.wait_for(seen, DETECT_TIMEOUT_S):
                raise ParticipantLost(f"{expected} was not detected within "
                                      f"{DETECT_TIMEOUT_S:g} s")
        if isinstance(expected, VehicleUp):
            self.reports -= {(expected.vehicle, "broken"), (expected.vehicle, "repaired")}
            self.scheduled_down.discard(expected.vehicle)
            self.generation[expected.vehicle] = self.liveness.appearances(expected.vehicle)
        else:
            self.scheduled_down.add(expected.vehicle)
        self.detected.append(_sighting(expected))
        log.info("detected %s after %.3f s", expected, time.monotonic() - started)
        return expected

    def instant(self, t: float) -> float:
        return t  # sim time stands still while the engine recovers

    def before_decision(self, t_next: float, t_free: dict[int, float]) -> dict[int, float]:
        self.advance(t_next)
        return t_free

    def finish(self, t_end: float) -> None:
        self.advance(t_end)


def _sighting(disruption: Disruption) -> dict:
    """A fault seen, for `fleet bench faults`: what, its sim instant, and the wall clock."""
    return {"what": repr(disruption), "vehicle": getattr(disruption, "vehicle", None),
            "up": isinstance(disruption, VehicleUp), "t": disruption.t,
            "detected_wall": time.time()}


def _recovered(detected: list[dict]) -> None:
    """The engine asks the clock again: what was seen so far has been recovered from."""
    for seen in detected:
        seen.setdefault("recovered_wall", time.time())


def _who(late: list[int]) -> str:
    names = ["the fault injector" if v == INJECTOR else f"forklift {v}" for v in late]
    return ", ".join(names)


class RealtimeClock(_Clock):
    """Sim time = speed x wall time since the start (a lead after the clock is made:
    dispatcher/pacing.py). Faults are not waited for: the clock notices them as they come
    (a liveliness token gone or back, a forklift's report, a zone whose time has come) and
    the engine freezes at the first instant every forklift that can move can still be told
    of: now + `margin` (docs/faults.md)."""

    TICK_PERIOD_S = 0.5

    def __init__(self, session: zenoh.Session, keys: Keys, speed: float, vehicles: list[int],
                 liveness: Liveness, scenario: Scenario | None = None, tick: int = 0,
                 t: float = 0.0, wall: float = 0.0, closed: frozenset = frozenset(),
                 lead_wall_s: float = LEAD_WALL_S, margin_wall_s: float = 0.5,
                 down: frozenset[int] = frozenset(), heard: Mapping[int, str] | None = None
                 ) -> None:
        """`tick`, `t` and `wall`: the last tick a restarted dispatcher's forklifts heard
        (the clock goes on from its anchor; they refuse a tick numbered before it);
        `closed`: the cells the store holds as a closed zone (zones closed before it);
        `down`: the forklifts down then; `heard`: each breakdown as its agent said it was
        ("broken", "repaired"): one down and still broken is back when repaired, one up
        and broken broke while no dispatcher listened."""
        if speed <= 0:
            raise ValueError(f"--speed must be positive, not {speed}")
        super().__init__(session, keys, vehicles, liveness, down)
        self.speed = speed
        self.pacing = RealtimePacing.going_on(speed, t, wall, lead_wall_s) if wall else \
            RealtimePacing.starting(speed, time.time(), lead_wall_s)
        self.lead = self.pacing.lead
        self.margin = margin_wall_s * speed  # a freeze this much ahead reaches everyone
        self.late: list[Late] = []  # the decisions taken too late for their instant
        self.zones = sorted((f for f in scenario.faults if f.kind is FaultKind.CLOSE_ZONE
                             and f.until > t and not set(f.cells) & closed),
                            key=lambda f: f.at) if scenario else []
        self.last_instant = max(scenario.instants(), default=0.0) if scenario else 0.0
        self.down = down
        # "broken" / "repaired", in order, not acted on
        self.reports: dict[int, list[str]] = {v: [state] for v, state in (heard or {}).items()
                                              if v not in down}
        # down because broken: back when repaired
        self.broken: set[int] = {v for v, state in (heard or {}).items()
                                 if v in down and state == "broken"}
        self.tick = tick
        self.publishing = threading.Lock()  # ticks go out numbered in order, from two threads
        self.stopping = threading.Event()
        self._listen(session, keys)
        self._publish()
        self.ticker = threading.Thread(target=self._tick, daemon=True)
        self.ticker.start()

    def now(self) -> float:
        return self.pacing.now(time.time())

    def instant(self, t: float) -> float:
        return self.now() + self.margin  # not t: the engine decides a lead ahead of now

    def _publish(self) -> None:
        with self.publishing:
            self.tick += 1
            t, wall = self.pacing.anchor(time.time())
            self._send(ClockTick(self.tick, ClockMode.REALTIME.value, t, self.speed, wall,
                                 down=sorted(self.down)))

    def resumed(self, vehicle: int) -> None:
        """Not listed from now on, though the engine is still handling what it noticed with
        the forklift's return: meanwhile the ticker would list it at instants after its
        resumption (others that went down stay listed)."""
        self._held_down(self.down - {vehicle})

    def _held_down(self, down: frozenset[int]) -> None:
        """Say at once who is down: a forklift must hear it before its freeze instant (it
        then stays silent), and one resumed must not hear it again afterwards."""
        if down != self.down:
            self.down = down
            self._publish()

    def _tick(self) -> None:
        while not self.stopping.wait(self.TICK_PERIOD_S):
            self._publish()

    def _reported(self, vehicle: int, state: str) -> None:
        self.reports.setdefault(vehicle, []).append(state)  # in order: _noticed acts on them

    def _wall_until(self, t: float) -> float:
        """Wall seconds until sim time t (0 once it has come)."""
        return max(0.0, self.pacing.wall_at(t) - time.time())

    def wait_until(self, t: float) -> None:
        while (ahead := self._wall_until(t)) > 0:
            self.stopping.wait(min(ahead, 0.5))

    def before_decision(self, t_next: float, t_free: dict[int, float]) -> dict[int, float]:
        self.wait_until(t_next - self.lead)
        paced, late = self.pacing.paced(t_free, time.time())
        if late is not None:
            self.late.append(late)
            log.info("decided late for t=%.2f: %s moved to t=%.2f", t_next,
                     ", ".join(f"forklift {v} (free at t={t:.2f})"
                               for v, t in sorted(late.moved.items())), late.until)
        return paced

    def finish(self, t_end: float) -> None:
        self.wait_until(t_end)
        if self.late:
            log.warning("%d decisions were taken too late for their instant (the first for "
                        "t=%.2f): from there on this run is not the fast clock's",
                        len(self.late), min(self.late[0].moved.values()))

    def disruptions(self, t_next: float, down: frozenset[int]) -> list[Disruption]:
        """Wait for the next decision's time, returning early with whatever happens
        meanwhile. With nobody to decide for (every forklift left is down), wait for one to
        come back until the scenario's last instant, plus DETECT_TIMEOUT_S."""
        self._held_down(down)
        _recovered(self.detected)
        target = t_next - self.lead if math.isfinite(t_next) else \
            max(self.last_instant, self.now()) + DETECT_TIMEOUT_S * self.speed
        with self.liveness.changed:  # liveliness and fault reports notify it
            while not (found := self._noticed(down)):
                if self._wall_until(target) <= 0:
                    return []
                ahead = self._wall_until(min([target, *(z.at for z in self.zones)]))
                self.liveness.changed.wait(min(ahead, 0.5))
        # The new ones are down from now on; one back stays listed until it is resumed.
        self._held_down(down | {d.vehicle for d in found if isinstance(d, VehicleDown)})
        for d in found:
            self.detected.append(_sighting(d))
            log.info("noticed %s at t=%.2f", d, self.now())
        return found

    def _noticed(self, down: frozenset[int]) -> list[Disruption]:
        """What changed since the engine last heard (called holding liveness.changed)."""
        t = self.instant(self.now())
        alive, appeared = self.liveness.alive, self.liveness.appeared
        found: list[Disruption] = []
        for v in sorted(down):
            events = self.reports.setdefault(v, [])
            if v in self.broken:  # back when repaired
                if "repaired" in events:
                    del events[:events.index("repaired") + 1]
                    self.broken.discard(v)
                    self.generation[v] = appeared.get(v, 0)
                    found.append(VehicleUp(v, t))
            elif v in alive and appeared.get(v, 0) > self.generation.get(v, 0):
                events.clear()  # back: its token came again since it was last known up
                self.generation[v] = appeared.get(v, 0)
                found.append(VehicleUp(v, t))
        for v in self.vehicles:
            if v in down:
                continue
            events = self.reports.setdefault(v, [])
            if v not in alive or appeared.get(v, 0) > self.generation.get(v, 0):
                # Gone, or gone and back since last asked (a short outage, an agent that
                # restarted at once): down now, back at the next look if its token is there.
                found.append(VehicleDown(v, t, "agent lost (its liveliness token went)"))
            elif "broken" in events:
                del events[:events.index("broken") + 1]
                self.broken.add(v)
                found.append(VehicleDown(v, t, BREAKDOWN))
        while self.zones and self.zones[0].at <= self.now():
            zone = self.zones.pop(0)
            if zone.until > t:
                found.append(ZoneClosure(frozenset(zone.cells), t, zone.until))
        return found

    def close(self) -> None:
        self.stopping.set()
        self.ticker.join()
        super().close()
