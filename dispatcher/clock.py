"""The one source of "now" (DESIGN.md section 3), published by the dispatcher on
fleet/<run>/clock. Both clocks are `Pacer`s of the engine (fleet/execution.py).

Fast: discrete events. Before each decision the clock moves to the decision's instant and
waits until every agent has acknowledged the tick (having published its states up to it), so
a run is deterministic and every state stream is complete up to "now".
Real time: sim time = speed x wall time since the start; ticks carry the wall anchor so every
process computes the same "now". The dispatcher decides a subtask a little ahead of the
forklift's free time; a forklift whose free time has already passed waits until the next
instant a plan can still be ready for.
"""

from __future__ import annotations

import threading
import time

import zenoh

from dispatcher.liveness import Liveness, ParticipantLost
from fleet.bus import RELIABLE, Keys, received
from fleet.protocol import ClockAck, ClockTick, encode

SENDER = "clock"
ACK_TIMEOUT_S = 60.0


class FastClock:
    def __init__(self, session: zenoh.Session, keys: Keys, vehicles: list[int],
                 liveness: Liveness, log) -> None:
        self.vehicles = vehicles
        self.liveness = liveness
        self.log = log
        self.tick = 0
        self.t = 0.0
        self.acked: dict[int, int] = {}
        self.changed = threading.Condition()
        self.publisher = session.declare_publisher(keys.clock, congestion_control=RELIABLE)
        self.subscriber = session.declare_subscriber(keys.clock_ack("*"), self._on_ack)

    def _on_ack(self, sample: zenoh.Sample) -> None:
        message = received(sample, ClockAck, self.log)
        if message is None:
            return
        with self.changed:
            self.acked[message.vehicle] = max(self.acked.get(message.vehicle, 0), message.tick)
            self.changed.notify_all()

    def advance(self, t: float) -> None:
        self.tick += 1
        self.t = max(self.t, t)
        self.publisher.put(encode(ClockTick(self.tick, "fast", self.t), SENDER, self.tick,
                                  self.t))
        deadline = time.monotonic() + ACK_TIMEOUT_S
        with self.changed:
            while not all(self.acked.get(v, 0) >= self.tick for v in self.vehicles):
                self.liveness.check(self.vehicles)
                if time.monotonic() > deadline:
                    late = [v for v in self.vehicles if self.acked.get(v, 0) < self.tick]
                    raise ParticipantLost(f"forklifts {late} did not acknowledge tick "
                                          f"{self.tick} (t={self.t}) within {ACK_TIMEOUT_S} s")
                self.changed.wait(0.5)  # wakes on every ack; the timeout re-checks liveness

    def before_decision(self, t_next: float, t_free: dict[int, float]) -> dict[int, float]:
        self.advance(t_next)
        return t_free

    def finish(self, t_end: float) -> None:
        self.advance(t_end)

    def close(self) -> None:
        self.subscriber.undeclare()
        self.publisher.undeclare()


class RealtimeClock:
    TICK_PERIOD_S = 0.5

    def __init__(self, session: zenoh.Session, keys: Keys, speed: float, vehicles: list[int],
                 liveness: Liveness, lead_wall_s: float = 0.3) -> None:
        if speed <= 0:
            raise ValueError(f"--speed must be positive, not {speed}")
        self.speed = speed
        self.vehicles = vehicles
        self.liveness = liveness
        self.lead = lead_wall_s * speed  # decide this much sim time ahead
        self.wall0 = time.time()
        self.tick = 0
        self.stopping = threading.Event()
        self.publisher = session.declare_publisher(keys.clock, congestion_control=RELIABLE)
        self._publish()
        self.ticker = threading.Thread(target=self._tick, daemon=True)
        self.ticker.start()

    def now(self) -> float:
        return (time.time() - self.wall0) * self.speed

    def _publish(self) -> None:
        self.tick += 1
        wall = time.time()
        t = (wall - self.wall0) * self.speed
        self.publisher.put(encode(ClockTick(self.tick, "realtime", t, self.speed, wall),
                                  SENDER, self.tick, t))

    def _tick(self) -> None:
        while not self.stopping.wait(self.TICK_PERIOD_S):
            self._publish()

    def wait_until(self, t: float) -> None:
        while (ahead := t - self.now()) > 0:
            self.liveness.check(self.vehicles)
            self.stopping.wait(min(ahead / self.speed, 0.5))

    def before_decision(self, t_next: float, t_free: dict[int, float]) -> dict[int, float]:
        self.wait_until(t_next - self.lead)
        floor = self.now() + self.lead / 2
        return {v: max(t, floor) for v, t in t_free.items()}

    def finish(self, t_end: float) -> None:
        self.wait_until(t_end)

    def close(self) -> None:
        self.stopping.set()
        self.ticker.join()
        self.publisher.undeclare()
