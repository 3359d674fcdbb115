"""Each dispatcher's decision failures as it counted them against those it announced.

The dispatcher announces every decision failure it counts (dispatch/failure), and says its
count as it goes (dispatch/progress) and at its end (its result, dispatch/done, or how far it
got, dispatch/stopped): in a recording the two agree, and one where they differ fails the
messages verdict (docs/metrics.md). Each dispatcher that ran (a restarted one counts from 0
and numbers its messages from 1) is judged on its own.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

from fleet.recording.mission_record import Final, Restart
from fleet.recording.reader import Recording
from fleet.wire.protocol import DecisionFailure, MissionStopped, Progress


@dataclass(frozen=True)
class FailureCount:
    dispatcher: int  # 1, 2, ...: in the order they ran
    counted: int  # its count: at its end if `final`, else the highest it reported on the way
    announced: int  # the dispatch.failure messages it numbered (recorded or not), or its record's
    final: bool  # it said its count at its end (else the count may have grown since)
    known: bool  # what it sent is recorded, or in its record: the two can be compared

    @property
    def agrees(self) -> bool:
        """Every failure counted was announced, and no more (to its last report, when its
        count at its end is not recorded)."""
        if not self.known:
            return True
        return self.announced == self.counted if self.final else self.announced >= self.counted

    def line(self) -> str:
        return (f"dispatcher {self.dispatcher} counted {self.counted} decision failures"
                + ("" if self.final else " by its last report")
                + f", announced {self.announced}")


def failure_counts(recording: Recording, restarts: list[Restart],
                   final: Final | None) -> list[FailureCount]:
    """Each dispatcher's count and announcements, from its messages (those between two
    restarts) and, for the last, its record (`final`, fleet.recording.mission_record)."""
    starts = [x.at_ns for x in restarts]
    lives = len(starts) + 1

    def life(log_ns: int) -> int:
        return bisect.bisect_right(starts, log_ns)

    counted, announced = [0] * lives, [0] * lives
    final_count: list[int | None] = [None] * lives
    for r, m in recording.of(Progress):
        counted[life(r.log_ns)] = max(counted[life(r.log_ns)], m.failures)
    for r, m in recording.of(MissionStopped):
        final_count[life(r.log_ns)] = m.decision_failures
    for r, _ in recording.of(DecisionFailure):
        announced[life(r.log_ns)] = max(announced[life(r.log_ns)], r.envelope.seq)
    if final is not None:
        announced[-1] = max(announced[-1], len(final.failures))
        if final.account is not None:
            final_count[-1] = final.account.decision_failures
    bounds = [-math.inf, *starts, math.inf]
    out = []
    for k in range(lives):
        recorded = not any(g.start_ns < bounds[k + 1] and g.end_ns > bounds[k]
                           for g in recording.gaps)
        end = final_count[k]
        out.append(FailureCount(k + 1, counted[k] if end is None else end,
                                announced[k], end is not None,
                                recorded or (final is not None and k == lives - 1)))
    return out
