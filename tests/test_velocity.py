"""Velocity planner: the 16 links of Figure 11 and FixMovingTime against Table 2 as printed."""

import hypothesis.strategies as st
from hypothesis import given, settings

from fleet.params import ManeuverTimes
from fleet.planning.maneuvers import Kind
from fleet.planning.velocity import (
    INF,
    EndTimes,
    Speed,
    VelocityPlanner,
    fix_ending_levels,
    start_times,
)

T = ManeuverTimes()
VP = VelocityPlanner(T)


def test_sixteen_legal_links_and_no_zero_high_straight():
    assert len(VP.links) == 16
    assert (Kind.STRAIGHT, Speed.ZERO, Speed.HIGH) not in VP.links
    assert (Kind.STRAIGHT, Speed.HIGH, Speed.ZERO) not in VP.links
    assert not any(k is not Kind.STRAIGHT and Speed.HIGH in (a, b) for k, a, b in VP.links)


def table2(kind, tz, tm, th, mu):
    """Table 2 literally, with the paper's convention t_high = t_mid when v_high is not
    reachable. Returns (t_zero, t_mid, t_high) of the child."""
    if kind is Kind.STOP:
        return (tz + T.T12,) * 3
    if kind is Kind.STRAIGHT:
        if mu:
            return tz + T.T1, tz + T.T2, tz + T.T2
        if th == tm:
            return tm + T.T2, tm + T.T3, tm + T.T4
        return tm + T.T2, th + T.T4, th + T.T5
    if kind is Kind.TURN:
        if mu:
            return tz + T.T6, tz + T.T7, tz + T.T7
        return tm + T.T7, tm + T.T8, tm + T.T8
    if mu:
        return tz + T.T9, tz + T.T10, tz + T.T10
    return tm + T.T10, tm + T.T11, tm + T.T11


def as_paper(times: EndTimes):
    z, m, h = times.at
    m = z if m == INF else m
    h = m if h == INF else h
    return z, m, h


def test_hand_worked_straight_run_from_rest():
    t = start_times(100.0)
    one = VP.child_times(t, Kind.STRAIGHT, from_rest=True)
    assert one.at == (104.0, 102.0, INF)  # T1, T2; v_high not reachable from rest
    two = VP.child_times(one, Kind.STRAIGHT, from_rest=False)
    assert two.at == (104.0, 103.25, 102.75)  # 102+T2, 102+T3, 102+T4
    three = VP.child_times(two, Kind.STRAIGHT, from_rest=False)
    # zero: t_mid,p + T2; mid: t_high,p + T4; high: t_high,p + T5
    assert three.at == (103.25 + 2.0, 102.75 + 0.75, 102.75 + 0.5)


def test_turn_after_straight_starts_at_mid():
    t = VP.child_times(start_times(0.0), Kind.STRAIGHT, from_rest=True)
    turn = VP.child_times(t, Kind.TURN, from_rest=False)
    assert turn.at == (2.0 + T.T7, 2.0 + T.T8, INF)
    assert turn.start_level == (Speed.MID, Speed.MID, None)


level = st.integers(0, 400).map(lambda q: q * 0.25)
gap = st.integers(1, 40).map(lambda q: q * 0.25)


@settings(max_examples=400, derandomize=True)
@given(kind=st.sampled_from(list(Kind)), th=level, dm=gap, dz=gap,
       reachable=st.sampled_from(["zero", "mid", "high"]), mu=st.booleans())
def test_fix_moving_time_equals_table_2(kind, th, dm, dz, reachable, mu):
    # A parent ends earliest at high, then mid, then zero (a faster end is an earlier end);
    # after a stop only zero is reachable, after a turn zero and mid.
    tz = th + dm + dz
    tm = th + dm if reachable != "zero" else INF
    th = th if reachable == "high" else INF
    parent = EndTimes((tz, tm, th), (None, None, None))
    child = VP.child_times(parent, kind, from_rest=mu or kind is Kind.STOP)
    expected = table2(kind, *as_paper(parent), mu=mu or reachable == "zero")
    assert as_paper(child) == expected


def test_ending_levels_walk_back_from_zero():
    t0 = start_times(0.0)
    a = VP.child_times(t0, Kind.STRAIGHT, True)
    b = VP.child_times(a, Kind.STRAIGHT, False)
    c = VP.child_times(b, Kind.TURN, False)
    levels = fix_ending_levels([a, b, c])
    assert levels == [Speed.MID, Speed.MID, Speed.ZERO]
    # a ends at mid (2.0), b mid->mid (T3) ends 3.25, the turn mid->zero (T7) ends 8.25.
    assert (a.at[levels[0]], b.at[levels[1]], c.at[levels[2]]) == (2.0, 3.25, 8.25)
