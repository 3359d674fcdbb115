"""The Foxglove views of a seed-004 run, from its tracking events alone."""

from test_scene import decode

from fleet.mission.orders004 import Mission004, generate_orders
from fleet.mission.record004 import event_to_wire
from fleet.views.scene import FORKLIFTS, GOODS_TOPIC, NS, WAREHOUSE
from fleet.views.scene004 import FRAME_S, HEAT, Scene004Views, scene_views
from fleet.wire.protocol import AgvEvent, MissionDone
from fleet.world.layout_file import load_layout

LAYOUT = load_layout("paper004")
FLOOR = LAYOUT.floor


def drawn(views, topic):
    """The (log time, decoded message) of each view on `topic`."""
    return [(ns, decode(m)) for t, m, ns in views if t == topic]


def agv_at(update, vehicle):
    (entity,) = [e for e in update.entities if e.id == f"agv/{vehicle}"]
    return entity


def test_an_agv_is_drawn_between_two_cells_while_it_moves_and_carries_the_shelf_it_lifted():
    views = scene_views(LAYOUT, 0, "orders", 1)
    assert isinstance(views, Scene004Views)
    start = views.start()
    assert drawn(start, WAREHOUSE) and drawn(start, GOODS_TOPIC)
    shelves_at_start = len(drawn(start, GOODS_TOPIC)[0][1].entities[0].cubes)
    assert shelves_at_start == len(FLOOR.slots)
    a, b = FLOOR.parking[0], FLOOR.slots[0].xy  # (a move of one cell, as far as drawing goes)
    out = views.on_message("k", AgvEvent("moved", 1, 1.0, 2.0, a, b, task="M1"), 1.0)
    out += views.on_message("k", AgvEvent("paused", 1, 2.0, 4.0, b, label="lift"), 2.0)
    out += views.on_message("k", AgvEvent("moved", 1, 5.0, 6.0, b, a, task="M2",
                                          loaded=True), 5.0)
    frames = {ns / NS: m for ns, m in drawn(out, FORKLIFTS)}
    assert sorted(frames) == [k * FRAME_S for k in range(10)]  # every instant before 5 s
    xa, ya = LAYOUT.cell_center(FLOOR.cell(a))
    xb, yb = LAYOUT.cell_center(FLOOR.cell(b))
    halfway = agv_at(frames[1.5], 1).cubes[0].pose.position
    assert (halfway.x, halfway.y) == ((xa + xb) / 2, (ya + yb) / 2)
    assert len(agv_at(frames[3.5], 1).cubes) == 1  # lifting
    carried = agv_at(frames[4.0], 1)
    assert len(carried.cubes) == 2 and carried.cubes[0].pose.position.x == xb  # on it
    goods = drawn(out, GOODS_TOPIC)
    assert len(goods[-1][1].entities[0].cubes) == shelves_at_start - 1  # away from home
    # The end of the mission draws the last move to its end.
    end = views.on_message("k", MissionDone(True), 6.0)
    last = drawn(end, FORKLIFTS)[-1][1]
    assert agv_at(last, 1).cubes[0].pose.position.x == xa


def test_a_recorded_mission_draws_its_fleet_every_instant_and_its_heat():
    orders = generate_orders(FLOOR, 6, 1)
    events = Mission004(FLOOR, 3, orders).run().events
    views = scene_views(LAYOUT, 0, "orders", 3)
    out = views.start()
    for e in events:
        wire = event_to_wire(e)
        out += views.on_message("k", wire, wire.t0)
    frames = drawn(out, FORKLIFTS)
    assert all(len(m.entities) == 3 for _, m in frames)
    times = [ns / NS for ns, _ in frames]
    assert times == sorted(times) and times[1] - times[0] == FRAME_S
    heat = drawn(out, HEAT)
    assert heat and heat[-1][1].entities[0].cubes  # cells entered so far
