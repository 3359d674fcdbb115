"""The agent's view of the run's one clock: the last tick it heard from the dispatcher, and
which ticks it takes. On the fast clock a tick's sim time is "now" until the next one; on the
real-time clock every process computes "now" from the tick's wall anchor and speed (an
anchor still to come, before the clock has started: now stands at the tick's sim time)."""

from __future__ import annotations

import math
import time

from fleet.mission.spec import ClockMode
from fleet.wire.protocol import ClockTick

# No mission lasts 115 days of sim time or plays faster than 10 000x: a tick beyond is broken.
SIM_TIME_LIMIT_S = 1e7
MAX_SPEED = 1e4


def tick_problem(tick: ClockTick, last: ClockTick | None) -> str:
    """Why a tick cannot be the clock's next one ("" if it can)."""
    if last is not None and tick.tick <= last.tick:
        return f"not after tick {last.tick}"
    if tick.mode not in tuple(ClockMode):
        return f"unknown mode {tick.mode!r}"
    if last is not None and (tick.mode, tick.speed) != (last.mode, last.speed):
        return f"mode {tick.mode} at speed {tick.speed} is not the clock's {last.mode} at " \
            f"speed {last.speed}"
    if not 0 <= tick.t <= SIM_TIME_LIMIT_S:
        return f"sim time {tick.t} is outside [0, {SIM_TIME_LIMIT_S:g}] s"
    if last is not None and tick.t < last.t:
        return f"sim time {tick.t} is before the last tick's {last.t}"
    if tick.mode == ClockMode.REALTIME and not (0 < tick.speed <= MAX_SPEED and
                                                 math.isfinite(tick.wall)):
        return f"speed {tick.speed} or wall time {tick.wall} is not a real-time clock's"
    return ""


class SimClock:
    """This process's view of the one clock: the last tick heard, and since when the clock
    has been silent."""

    def __init__(self) -> None:
        self.tick: ClockTick | None = None
        self.spoke = -math.inf  # monotonic time the clock sent the newest tick heard

    def take(self, tick: ClockTick) -> None:
        """The clock's next tick (checked with `tick_problem`). A real-time tick says when it
        was sent: one that arrives late (it waited in a buffer while this process was stalled
        or cut off) sets the time, but says nothing of whether the clock speaks now."""
        age = 0.0
        if tick.mode == ClockMode.REALTIME:
            age = max(0.0, time.time() - tick.wall)  # an anchor still to come: sent now
        self.tick = tick
        self.spoke = max(self.spoke, time.monotonic() - age)

    def silent_for(self) -> float:
        """Seconds since the clock sent the newest tick heard (infinite before any)."""
        return time.monotonic() - self.spoke

    @property
    def realtime(self) -> bool:
        return self.tick is not None and self.tick.mode == ClockMode.REALTIME

    def now(self) -> float:
        tick = self.tick
        if tick is None:
            return 0.0
        if tick.mode == ClockMode.REALTIME:
            return tick.t + tick.speed * max(0.0, time.time() - tick.wall)
        return tick.t

    def heeds_down_from(self, t_resume: float, lease_s: float) -> float:
        """The first instant at which a tick listing this forklift as down holds it down
        again, once it is resumed at t_resume. On the real-time clock a tick sent before the
        dispatcher heard the resume answered may still list it at a later instant, and one
        that lists it anew comes only after its token has gone, a lease after it last spoke:
        not before a lease from now."""
        tick = self.tick
        if tick is None or tick.mode != ClockMode.REALTIME:
            return t_resume
        return max(t_resume, self.now() + lease_s * tick.speed)

    def wall_at(self, t: float) -> float | None:
        """Real time: the Unix time at which sim time is t (None on the fast clock)."""
        tick = self.tick
        if tick is None or tick.mode != ClockMode.REALTIME:
            return None
        return tick.wall + (t - tick.t) / tick.speed
