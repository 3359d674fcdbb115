"""The arithmetic of the real-time clock (dispatcher/clock.py's `RealtimeClock`), apart from
its threads and its publisher: where sim time stands at a wall instant, what a tick says,
when a decision is taken and what a late one does to the free times.

A decision is taken `lead` of sim time before its instant: the engine's discrete-event
order then decides every subtask for the very instant the fast clock would, as long as the
machine keeps up, and a real-time run that keeps up gives the fast run's record. Only a
decision that is late (a search that ran long, a machine busy with other work) moves free
times already past to `reach` after now, the soonest a plan decided now can be committed
for; from there on the run is its own.

Sim time 0 is itself `lead` after the clock starts, so the mission's first instants are
decided as far ahead as every later one (the processes' first plans are also their
slowest: nothing is cached yet). Until then sim time stands at 0.
"""

from __future__ import annotations

from dataclasses import dataclass

# Wall seconds a decision is taken ahead of its instant. It bounds how long the decisions of
# one instant may take in all (the plans that fail, then the one that is committed): about
# 0.4 s at most on `paper` in one quiet process, several times that on a loaded machine.
LEAD_WALL_S = 2.0
# Wall seconds from deciding late to the instant decided for: a plan and its commit.
REACH_WALL_S = 0.3


@dataclass(frozen=True)
class Late:
    """A decision taken after its instant had come too near: each forklift free before
    `until` was moved to it (vehicle -> the free time it had)."""

    until: float
    moved: dict[int, float]


@dataclass(frozen=True)
class RealtimePacing:
    speed: float  # sim seconds per wall second
    wall0: float  # the Unix time at which sim time is 0
    lead: float  # sim seconds a decision is taken ahead of its instant
    reach: float  # sim seconds: the soonest instant after now a decision can be for

    @classmethod
    def starting(cls, speed: float, wall: float, lead_wall_s: float = LEAD_WALL_S,
                 reach_wall_s: float = REACH_WALL_S) -> RealtimePacing:
        """A clock started at Unix time `wall`: sim time 0 comes a lead later."""
        return cls(speed, wall + lead_wall_s, lead_wall_s * speed, reach_wall_s * speed)

    @classmethod
    def going_on(cls, speed: float, t: float, wall: float, lead_wall_s: float = LEAD_WALL_S,
                 reach_wall_s: float = REACH_WALL_S) -> RealtimePacing:
        """The clock of a tick heard (sim time t at Unix time `wall`): a restarted
        dispatcher's."""
        return cls(speed, wall - t / speed, lead_wall_s * speed, reach_wall_s * speed)

    def now(self, wall: float) -> float:
        return max(0.0, (wall - self.wall0) * self.speed)

    def wall_at(self, t: float) -> float:
        return self.wall0 + t / self.speed

    def anchor(self, wall: float) -> tuple[float, float]:
        """What a tick published at `wall` says: a sim time and the Unix time it is (before
        sim time 0, 0 and the start to come)."""
        t = self.now(wall)
        return t, self.wall_at(t)

    def decision_wall(self, t_next: float) -> float:
        """When the decision for instant t_next is taken."""
        return self.wall_at(t_next - self.lead)

    def paced(self, t_free: dict[int, float], wall: float) -> tuple[dict[int, float],
                                                                    Late | None]:
        """The free times to decide with at `wall`, and what lateness moved (None: none)."""
        until = (wall - self.wall0) * self.speed + self.reach  # before sim 0 too
        moved = {v: t for v, t in t_free.items() if t < until}
        return {v: max(t, until) for v, t in t_free.items()}, \
            Late(until, moved) if moved else None
