"""Velocity planner of seed 000 (Section 4.2, Tables 1 and 2, Figure 11).

A maneuver starts and ends at one of three speed levels. The duration of a maneuver depends on
its kind and on its start and end levels (Table 1); v_high exists only when going straight and
zero <-> high within one straight move is illegal, which leaves the 16 legal links of Figure 11.

FixMovingTime (Table 2) keeps, for every search node, the earliest instant at which the maneuver
can end at each level. `child_times` computes it as a minimum over the legal links; this equals
Table 2 row by row (tests check it) and also remembers which start level achieved each end
level, so a found trajectory can be timed exactly by walking back from v_zero at the goal.
"""

from __future__ import annotations

import math
from enum import IntEnum
from typing import NamedTuple

from fleet.params import ManeuverTimes
from fleet.planning.maneuvers import Kind

INF = math.inf


class Speed(IntEnum):
    ZERO = 0
    MID = 1
    HIGH = 2


def link_durations(times: ManeuverTimes) -> dict[tuple[Kind, Speed, Speed], float]:
    """The 16 legal (kind, start level, end level) links and their durations (Table 1)."""
    z, m, h = Speed.ZERO, Speed.MID, Speed.HIGH
    s, t, lane = Kind.STRAIGHT, Kind.TURN, Kind.LANE
    return {
        (s, z, z): times.T1, (s, z, m): times.T2, (s, m, z): times.T2, (s, m, m): times.T3,
        (s, m, h): times.T4, (s, h, m): times.T4, (s, h, h): times.T5,
        (t, z, z): times.T6, (t, z, m): times.T7, (t, m, z): times.T7, (t, m, m): times.T8,
        (lane, z, z): times.T9, (lane, z, m): times.T10, (lane, m, z): times.T10,
        (lane, m, m): times.T11,
        (Kind.STOP, z, z): times.T12,
    }


class EndTimes(NamedTuple):
    """Earliest end instant per end level (INF: level not reachable), and the start level
    that achieves it (None for unreachable or the trajectory start). A named tuple: the
    search makes millions."""

    at: tuple[float, float, float]
    start_level: tuple[Speed | None, Speed | None, Speed | None]

    @property
    def t_zero(self) -> float:
        return self.at[Speed.ZERO]


def start_times(t_i: float) -> EndTimes:
    """The trajectory starts at rest at t_i."""
    return EndTimes((t_i, INF, INF), (None, None, None))


class VelocityPlanner:
    """FixMovingTime over the 16 legal links."""

    def __init__(self, times: ManeuverTimes = ManeuverTimes()) -> None:
        self.links = link_durations(times)
        # Per (kind, from rest): (start level, end level, duration, start level as a Speed);
        # plain ints index faster than IntEnum members in the search's innermost loop.
        self._links: dict[tuple[Kind, bool], tuple[tuple[int, int, float, Speed], ...]] = {}
        for kind in Kind:
            for from_rest in (False, True):
                self._links[kind, from_rest] = tuple(
                    (int(v0), int(v1), dt, v0) for (k, v0, v1), dt in self.links.items()
                    if k is kind and not (from_rest and v0))

    def child_times(self, parent: EndTimes, kind: Kind, from_rest: bool) -> EndTimes:
        """End times of a maneuver of this kind after a parent that ends as `parent` says.
        from_rest (the stopping flag mu = 1): the maneuver must start at v_zero, as after a
        stop or when the direction of travel reverses."""
        return self.child_window(parent, kind, from_rest)[0]

    def child_window(self, parent: EndTimes, kind: Kind, from_rest: bool
                     ) -> tuple[EndTimes, float, float, float]:
        """`child_times`, with the window the maneuver may occupy: its end at v_zero, the
        earliest instant it may start (the soonest parent level a best end starts from) and
        the latest finite end."""
        best = [INF, INF, INF]
        via: list[Speed | None] = [None, None, None]
        at = parent.at
        for v0, v1, dt, level in self._links[kind, from_rest]:
            t = at[v0] + dt
            if t < best[v1]:
                best[v1] = t
                via[v1] = level
        b0, b1, b2 = best
        t_from = min([at[v] for v in via if v is not None])
        t_to = max([t for t in best if t < INF])
        return EndTimes((b0, b1, b2), (via[0], via[1], via[2])), b0, t_from, t_to


def fix_ending_levels(chain: list[EndTimes]) -> list[Speed]:
    """Pick each maneuver's end level along a found path: the last ends at v_zero, and each
    earlier one ends at the level its successor started from."""
    levels: list[Speed] = []
    level: Speed | None = Speed.ZERO
    for times in reversed(chain):
        assert level is not None
        levels.append(level)
        level = times.start_level[level]
    levels.reverse()
    return levels
