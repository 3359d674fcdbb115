"""The lower bound on a stack mission's end time never exceeds a real schedule: seeded random
small missions (layouts with starts on and off the station docks, fleets of one and two, every
strategy but ANN, handling times from none to long) all end at or after it; and the split of a
record's forklift-seconds adds up to the fleet's time."""

import functools
import random
import zlib

import pytest

from fleet.dispatching.decision import STACK_STRATEGIES, Strategy
from fleet.mission.engine import EngineOptions, run_mission
from fleet.mission.lower_bound import Bound, gap, relaxed_bound, stack_trips
from fleet.mission.spec import STACK_KINDS, Mission, MissionKind
from fleet.params import DispatchParams
from fleet.planning.reservations import ReservationTable
from fleet.planning.trajectory import Pose, Trajectory
from fleet.world.generator import Shape, generate_layout
from fleet.world.layout_file import load_layout
from fleet.world.site import planners_for

LAYOUTS = {
    "small": lambda: load_layout("small"),  # forklifts start on the station docks
    "generated-1x4": lambda: generate_layout(Shape(aisles=1, depth=4, lane_depth=2,
                                                   vehicles=2)),  # they start in the aisle
}


@functools.cache
def layout_and_trips(name: str):
    layout = LAYOUTS[name]()
    return layout, stack_trips(layout, layout.vehicle_starts)


def random_cases(seed: int, count: int):
    rng = random.Random(seed)
    strategies = [s for s in STACK_STRATEGIES if s is not Strategy.ANN]
    for _ in range(count):
        yield (rng.choice(strategies), rng.choice([(0,), (1,), (0, 1)]),
               DispatchParams(t_claim=rng.choice([0.0, 2.0, 5.0, 12.0]),
                              t_unload=rng.choice([0.0, 3.0, 5.0, 9.0])))


@pytest.mark.parametrize("kind", STACK_KINDS)
@pytest.mark.parametrize("name", sorted(LAYOUTS))
def test_bound_never_above_a_real_schedule(name, kind):
    layout, trips = layout_and_trips(name)
    for strategy, which, params in random_cases(zlib.crc32(f"{name} {kind.value}".encode()), 4):
        starts = tuple(layout.vehicle_starts[i] for i in which)
        record = run_mission(Mission(layout=name, kind=kind, strategy=strategy, starts=starts),
                             EngineOptions(params=params), layout)
        bound = Bound.of(trips, kind, starts, params)
        case = f"{strategy.value}, starts {which}, {params.t_claim}/{params.t_unload} s"
        assert len(record.stacks_done) == len(layout.stacks), case
        assert 0 < bound.value <= record.end_time, case
        split = gap(record, bound)
        assert split.total_s == pytest.approx(len(starts) * record.end_time), case
        assert min(split.as_dict().values()) >= 0, case


def test_one_forklift_is_never_idle_before_its_last_stack():
    layout, trips = layout_and_trips("small")
    start = layout.vehicle_starts[:1]
    record = run_mission(Mission(layout="small", strategy=Strategy.GREEDY, starts=start),
                         EngineOptions(), layout)
    split = gap(record, Bound.of(trips, MissionKind.FILL, start, DispatchParams()))
    assert split.after_last_s == 0 and split.between_s == 0 and split.aside_s == 0
    assert split.handling_s == 24 * (DispatchParams().t_claim + DispatchParams().t_unload)


def test_relaxed_arrivals_are_never_later_than_a_planned_trip():
    """The bound's pruning stands on this: 200 seeded random trips on `small`'s empty floor."""
    layout = load_layout("small")
    planner = planners_for(layout).get(frozenset())
    grid = layout.grid_map()
    poses = [Pose((x, y), h) for x in range(grid.cols) for y in range(grid.rows)
             for h in range(4) if planner.component(Pose((x, y), h)) is not None]
    rng = random.Random(7)
    planned = 0
    for _ in range(200):
        start, end = rng.sample(poses, 2)
        trip = planner.plan(1, start, 0.0, [end], ReservationTable())
        relaxed = planner.earliest_arrivals(start)
        if isinstance(trip, Trajectory):
            planned += 1
            assert relaxed[end.cell[0], end.cell[1], end.heading] <= trip.t_end
    assert planned > 150


def test_the_relaxed_bound_proves_less():
    layout, trips = layout_and_trips("generated-1x4")
    for kind in STACK_KINDS:
        relaxed = relaxed_bound(layout, kind, layout.vehicle_starts)
        assert 0 < relaxed < Bound.of(trips, kind, layout.vehicle_starts, DispatchParams()).value


def test_a_start_the_trips_were_not_found_for_is_refused():
    layout, trips = layout_and_trips("small")  # its forklifts start on the docks
    assert trips.first_saving(layout.vehicle_starts[0]) == 0.0
    with pytest.raises(ValueError, match="no trips were found from start"):
        trips.first_saving(Pose((4, 4), 0))
