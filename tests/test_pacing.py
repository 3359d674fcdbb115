"""The real-time clock's arithmetic (dispatcher/pacing.py): decisions a lead ahead of their
instant, so that a run that keeps up decides what the fast clock would, and the one clock
every process computes from the ticks."""

import itertools
import os

import pytest

from dispatcher.clock import FastClock
from dispatcher.liveness import Liveness
from dispatcher.pacing import RealtimePacing
from fleet.dispatching.decision import TaskKind
from fleet.mission.engine import Engine, engine_options
from fleet.mission.freeze import (
    BREAKDOWN,
    Disruption,
    Freeze,
    ScheduledPacer,
    VehicleDown,
    VehicleUp,
)
from fleet.mission.seam import LocalExecutor, Task
from fleet.mission.spec import Mission
from fleet.runtime.bus import BusConfig, open_session
from fleet.wire.protocol import ClockTick
from fleet.wire.topics import Keys
from fleet.world.layout_file import load_layout
from fleet.world.site import planners_for
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



def test_a_resumed_agent_heeds_a_down_list_only_where_it_can_be_news(monkeypatch):
    """Resumed at t=215 (its answer sent at t=230, the engine already late): a tick the
    dispatcher sent before it heard the answer may list the forklift at t=230.x, and must
    not hold it down for good. A forklift newly down is listed only once its token has
    gone, a lease (1 s, 20 sim s here) after it last spoke: from t=250 a list is news."""
    p = pacing()
    agent = SimClock()
    t, wall = p.anchor(START + 10.0)
    agent.tick = ClockTick(9, "realtime", t, SPEED, wall)
    monkeypatch.setattr(agent_clock.time, "time", lambda: p.wall_at(230.0))
    assert agent.heeds_down_from(215.0, lease_s=1.0) == pytest.approx(250.0)
    assert agent.heeds_down_from(260.0, lease_s=1.0) == 260.0  # resumed further ahead
    agent.tick = ClockTick(9, "fast", 230.0)  # its ticks come in the engine's order
    assert agent.heeds_down_from(215.0, lease_s=1.0) == 215.0


class NewsComesLate(ScheduledPacer):
    """The engine's pacer in process, with each disruption heard only once the engine
    decides `lag` after its instant: as on the real-time clock, which decides a lead ahead
    of now and freezes a margin after now, before subtasks it has already decided."""

    def __init__(self, disruptions: list[Disruption], lag: float) -> None:
        self.pending, self.lag = list(disruptions), lag

    def disruptions(self, t_next: float, down: frozenset[int]) -> list[Disruption]:
        due = [d for d in self.pending if d.t + self.lag <= t_next]
        self.pending = [d for d in self.pending if d not in due]
        return due


def test_a_freeze_before_subtasks_decided_undoes_them_but_not_the_handling_before():
    """Forklift 1 of `small` unloads at b from 29.75 s to 34.75 s, and its return from
    34.75 s is decided before its breakdown at 31 s is heard: the return is undone, and
    after the repair the forklift moves no sooner than its unloading is over."""
    mission = Mission("small")
    layout = load_layout("small")
    news = NewsComesLate([VehicleDown(1, 31.0, BREAKDOWN), VehicleUp(1, 32.0)], lag=10.0)
    record = Engine(mission, engine_options(mission, layout, None), layout, pacer=news).run()
    assert news.pending == [] and record.halts[0][:2] == (1, 31.0)
    undone = [record.subtasks[i] for i in record.cut_subtasks]
    assert [(s.vehicle, s.kind, s.t_i) for s in undone] == [(1, TaskKind.RETURN, 34.75)]
    for vehicle in (1, 2):
        kept = [s for i, s in enumerate(record.subtasks)
                if s.vehicle == vehicle and i not in record.cut_subtasks]
        assert all(b.t_i >= a.t_done for a, b in itertools.pairwise(kept)), vehicle
    assert len(record.stacks_done) == 24


def test_the_clock_hears_that_a_forklift_is_up_as_soon_as_it_is_resumed():
    """A real-time clock lists the forklifts held down in every tick, and a forklift that
    hears itself listed at an instant after its resumption stands for good: a new dispatcher
    found forklift 1 of paper002's real-time mixed run down, where the engine was slow after
    resuming it (a sleep there makes it happen every time). The engine tells the pacer which
    forklift it resumed as soon as it is told to move, before it asks or commits anything
    else; forklift 2 goes down as forklift 1 comes back, in the same news."""
    mission = Mission("small")
    layout = load_layout("small")
    told: list[tuple] = []

    class Listening(NewsComesLate):
        def resumed(self, vehicle: int) -> None:
            told.append(("resumed", vehicle))

        def disruptions(self, t_next: float, down: frozenset[int]) -> list[Disruption]:
            found = super().disruptions(t_next, down)
            told.append(("disruptions", *found))
            return found

    class Resuming(LocalExecutor):
        def execute(self, task: Task):
            told.append(("execute",))
            return super().execute(task)

        def resume(self, vehicle: int, freeze: Freeze, t: float, loaded: bool,
                   battery: float | None = None) -> None:
            told.append(("resume", vehicle))

    news = Listening([VehicleDown(1, 31.0, BREAKDOWN), VehicleUp(1, 40.0),
                      VehicleDown(2, 40.0, BREAKDOWN), VehicleUp(2, 50.0)], lag=10.0)
    executor = Resuming(layout.vehicle_kind, planners_for(layout))
    record = Engine(mission, engine_options(mission, layout, None), layout, executor,
                    news).run()
    news_of_1_back = next(call for call in told if VehicleUp(1, 40.0) in call)
    assert VehicleDown(2, 40.0, BREAKDOWN) in news_of_1_back
    resumed = [i for i, call in enumerate(told) if call[0] == "resume"]
    assert [told[i][1] for i in resumed] == [1, 2]
    assert [told[i + 1] for i in resumed] == [("resumed", 1), ("resumed", 2)]
    assert len(record.stacks_done) == 24


def test_the_fast_clock_brings_back_a_forklift_whose_token_came_again_before_it_looked():
    """A forklift the engine lost itself (its agent did not answer: a container cut off its
    network) is down, and its token went and came again before the clock was next asked (a
    quick reconnect): the clock brings it back. One whose token went and came again while
    it was up (an agent restarted at once) is lost, then back."""
    keys = Keys(f"clock{os.getpid()}")
    with open_session(BusConfig("peer", (), ())) as session:
        tokens = {v: session.liveliness().declare_token(keys.vehicle_alive(v)) for v in (1, 2)}
        liveness = Liveness(session, keys)
        liveness.wait_for([1, 2], 10.0)
        clock = FastClock(session, keys, [1, 2], liveness)

        def gone_and_back(v: int) -> None:
            tokens[v].undeclare()
            with liveness.changed:
                assert liveness.changed.wait_for(lambda: v not in liveness.alive, 10.0)
            tokens[v] = session.liveliness().declare_token(keys.vehicle_alive(v))
            liveness.wait_for([v], 10.0)

        try:
            assert clock.disruptions(5.0, frozenset()) == []
            gone_and_back(2)
            assert clock.disruptions(5.0, frozenset({2})) == [VehicleUp(2, 0.0)]
            assert clock.disruptions(5.0, frozenset()) == []
            gone_and_back(1)
            assert clock.disruptions(5.0, frozenset()) == [
                VehicleDown(1, 0.0, "agent lost (its liveliness token is gone)")]
            assert clock.disruptions(5.0, frozenset({1})) == [VehicleUp(1, 0.0)]
        finally:
            clock.close()
            liveness.close()
