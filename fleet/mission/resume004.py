"""Where a killed seed-004 dispatcher died, so that its successor picks the mission up there
(docs/faults.md, "A restarted dispatcher picks the mission up").

The tracker is a function of the mission and its faults, so the new dispatcher runs it again
in its own process, telling nobody, up to the instant the dead one died, and goes on from
there through the agents. That is exact only where the dead one died with every request
answered: the fault injector kills a dispatcher at a service fault's instant of the tracker,
after it has settled every request and journaled the instant (`FaultInstant`, one record
per service fault in the dispatcher's journal, and one where a successor went live). A
dispatcher that died anywhere else left the store part way through an instant, and is not
picked up: the new one says so.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from fleet.errors import UserError
from fleet.mission.faults import Fault
from fleet.mission.faults004 import dispatcher_killed

REACHED, PICKED_UP = "service_fault", "picked_up"  # the journal records' first field


@dataclass(frozen=True)
class FaultInstant:
    """A service fault the tracker reached (or, `picked_up`, where a successor went live):
    its `number` among them (from 1), its sim time, and the fault clock's tick then."""

    number: int
    t: float
    tick: int
    picked_up: bool = False

    def to_record(self) -> list[object]:
        return [PICKED_UP if self.picked_up else REACHED, self.number, self.t, self.tick]

    @classmethod
    def from_record(cls, record: object) -> FaultInstant:
        """The record as journaled; ValueError naming what is wrong."""
        if not (isinstance(record, list) and len(record) == 4
                and record[0] in (REACHED, PICKED_UP)):
            raise ValueError(f"not a record [{REACHED!r} or {PICKED_UP!r}, number, t, tick]: "
                             f"{record!r}")
        kind, number, t, tick = record
        if not (isinstance(number, int) and not isinstance(number, bool) and number >= 1):
            raise ValueError(f"{kind} number {number!r} is not a whole number from 1")
        if not (isinstance(t, int | float) and not isinstance(t, bool) and math.isfinite(t)
                and t >= 0):
            raise ValueError(f"{kind} time {t!r} is not a sim time")
        # each service fault ticks the fault clock once, and an agent's fault may too
        if not (isinstance(tick, int) and not isinstance(tick, bool) and tick >= number):
            raise ValueError(f"{kind} tick {tick!r} is not a whole number from its number, "
                             f"{number}")
        return cls(number, float(t), tick, kind == PICKED_UP)


def where_it_died(records: Sequence[object], faults: Sequence[Fault], journal: str
                  ) -> FaultInstant:
    """The instant the dead dispatcher reached last, which must be a kill of the dispatcher
    its scenario schedules there (else it died elsewhere: a UserError says so)."""
    try:
        reached = [FaultInstant.from_record(r) for r in records]
    except ValueError as exc:
        raise UserError(f"{journal}: not a seed-004 dispatcher's journal: {exc}") from None
    if not reached:
        raise UserError(f"{journal} names no instant the dead dispatcher reached: a seed-004 "
                        f"dispatcher is picked up only where the fault injector killed it "
                        f"(kill_service of the dispatcher in --faults)")
    last = reached[-1]
    if last.picked_up:
        raise UserError(f"{journal}: the dead dispatcher had picked the mission up at "
                        f"t={last.t:g} and died before the next service fault: elsewhere "
                        f"than where the fault injector kills it, part way through an "
                        f"instant, and a seed-004 mission is picked up only there")
    if not any(dispatcher_killed(f) and f.at == last.t for f in faults):
        raise UserError(f"{journal}: the dead dispatcher's last instant, t={last.t:g}, is no "
                        f"kill of the dispatcher in its scenario: it died elsewhere, part way "
                        f"through an instant, and a seed-004 mission is picked up only where "
                        f"the fault injector killed it")
    return last
