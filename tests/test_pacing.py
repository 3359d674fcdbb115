"""The real-time clock's arithmetic (dispatcher/pacing.py): decisions a lead ahead of their
instant, so that a run that keeps up decides what the fast clock would, and the one clock
every process computes from the ticks."""

import pytest

from dispatcher.pacing import RealtimePacing
from fleet.wire.protocol import ClockTick
from vehicle_agent import clock as agent_clock
from vehicle_agent.clock import SimClock

START = 1_800_000_000.0  # the Unix time the clock is made
SPEED = 20.0


def pacing() -> RealtimePacing:
    return RealtimePacing.starting(SPEED, START, lead_wall_s=2.0, reach_wall_s=0.3)


def test_sim_time_starts_a_lead_after_the_clock_and_stands_at_0_until_then():
    p = pacing()
    assert (p.lead, p.reach) == (40.0, 6.0)
    assert p.wall_at(0.0) == START + 2.0
    assert p.now(START) == p.now(START + 1.9) == 0.0
    assert p.now(START + 3.0) == pytest.approx(20.0)
    # A tick before the start says so: sim time 0, at the start to come.
    assert p.anchor(START + 0.5) == (0.0, START + 2.0)
    t, wall = p.anchor(START + 7.25)
    assert t == pytest.approx(105.0) and p.wall_at(t) == pytest.approx(wall)


def test_the_first_instants_are_decided_a_whole_lead_ahead_like_every_later_one():
    p = pacing()
    assert p.decision_wall(5.0) == pytest.approx(START + 0.25)  # the mission's first instant
    assert p.decision_wall(1005.0) == pytest.approx(p.wall_at(1005.0) - 2.0)


def test_a_decision_on_time_keeps_every_free_time():
    p = pacing()
    free = {1: 400.0, 2: 400.0, 3: 431.25}
    # Taken at its wall instant, or later as long as the plan still has its reach.
    for wall in (p.decision_wall(400.0), p.wall_at(400.0) - 0.35):
        paced, late = p.paced(free, wall)
        assert paced == free and late is None
    # The first instants, decided before sim time 0 has come.
    assert p.paced({1: 5.0, 2: 5.0}, START + 1.0) == ({1: 5.0, 2: 5.0}, None)


def test_a_late_decision_moves_the_free_times_already_too_near_and_says_which():
    p = pacing()
    paced, late = p.paced({1: 400.0, 2: 401.0, 3: 431.25}, p.wall_at(400.0) - 0.1)
    assert late is not None and late.until == pytest.approx(404.0)  # 0.3 s after now
    assert late.moved == {1: 400.0, 2: 401.0}
    assert paced == {1: late.until, 2: late.until, 3: 431.25}


def test_a_restarted_dispatchers_clock_goes_on_from_the_tick_heard():
    p = pacing()
    t, wall = p.anchor(START + 50.0)
    again = RealtimePacing.going_on(SPEED, t, wall, lead_wall_s=2.0, reach_wall_s=0.3)
    assert again.wall0 == pytest.approx(p.wall0)
    assert again.now(START + 60.0) == pytest.approx(p.now(START + 60.0))


@pytest.mark.parametrize("wall", [START + 0.5, START + 2.0, START + 9.5])
def test_an_agent_computes_the_dispatchers_now_from_its_ticks(monkeypatch, wall):
    """Before the start too: an agent told of a start to come does not run its clock
    backwards (it stands at 0, as the dispatcher's)."""
    p = pacing()
    t, anchor = p.anchor(START + 0.1)  # the first tick, heard before the start
    agent = SimClock()
    agent.tick = ClockTick(1, "realtime", t, SPEED, anchor)
    monkeypatch.setattr(agent_clock.time, "time", lambda: wall)
    assert agent.now() == pytest.approx(p.now(wall))
    assert agent.wall_at(105.0) == pytest.approx(p.wall_at(105.0))
