"""Where a killed seed-004 dispatcher died, so that its successor picks the mission up there
(docs/faults.md, "A restarted dispatcher picks the mission up").

The tracker is a function of the mission and its faults, so the new dispatcher runs it again
in its own process, telling nobody, up to the instant the dead one died, and goes on from
there through the agents. That is exact only where the dead one died with every request
answered: the fault injector kills a dispatcher at a service fault's instant of the tracker,
after it has settled every request and journaled the instant (`FaultInstant`, one record
per service fault in the dispatcher's journal). A dispatcher that died anywhere else left
the store part way through an instant, and is not picked up: the new one says so.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from fleet.errors import UserError
from fleet.mission.faults import Fault, FaultKind

KIND = "service_fault"  # the journal record's first field


@dataclass(frozen=True)
class FaultInstant:
    """A service fault the tracker reached: its `number` among them (from 1), its sim time,
    and the fault clock's tick that told the injector."""

    number: int
    t: float
    tick: int

    def to_record(self) -> list[object]:
        return [KIND, self.number, self.t, self.tick]

    @classmethod
    def from_record(cls, record: object) -> FaultInstant:
        """The record as journaled; ValueError naming what is wrong."""
        if not (isinstance(record, list) and len(record) == 4 and record[0] == KIND):
            raise ValueError(f"not a {KIND} record [{KIND!r}, number, t, tick]: {record!r}")
        _, number, t, tick = record
        if not (isinstance(number, int) and not isinstance(number, bool) and number >= 1):
            raise ValueError(f"{KIND} number {number!r} is not a whole number from 1")
        if not (isinstance(t, int | float) and not isinstance(t, bool) and math.isfinite(t)
                and t >= 0):
            raise ValueError(f"{KIND} time {t!r} is not a sim time")
        if not (isinstance(tick, int) and not isinstance(tick, bool) and tick >= 1):
            raise ValueError(f"{KIND} tick {tick!r} is not a whole number from 1")
        return cls(number, float(t), tick)


def dispatcher_killed_at(fault: Fault, t: float) -> bool:
    return fault.kind is FaultKind.KILL_SERVICE and fault.service == "dispatcher" and \
        fault.at == t


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
    if not any(dispatcher_killed_at(f, last.t) for f in faults):
        raise UserError(f"{journal}: the dead dispatcher's last instant, t={last.t:g}, is no "
                        f"kill of the dispatcher in its scenario: it died elsewhere, part way "
                        f"through an instant, and a seed-004 mission is picked up only where "
                        f"the fault injector killed it")
    return last
