"""The Foxglove views (fleet/views/scene.py) and the live view server (recorder/live.py).

Foxglove messages are opaque objects, so the tests decode what they encode with the protobuf
schema each one carries, the way Foxglove itself reads a recording."""

from __future__ import annotations

import functools
import json
import math
import struct

import pytest
from foxglove.messages import FrameTransforms, SceneEntity, SceneUpdate
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from matplotlib.colors import to_rgb
from matplotlib.patches import Rectangle
from mcap.reader import make_reader
from test_recording_plots import recorded, two_forklift_record
from websockets.sync.client import connect

from fleet.planning.geometry import body_corners
from fleet.recording.reader import read_recording
from fleet.recording.writer import RecordingWriter
from fleet.views.palette import GOODS_COLOR, forklift_color
from fleet.views.plots import gantt, snapshot
from fleet.views.scene import FRAME, HORIZON_S, SceneViews
from fleet.wire.protocol import GOODS, Progress, StackDone, VehicleState, WireChange
from fleet.world.layout_file import load_layout
from recorder.live import LiveView

BASE = 1_700_000_000 * 10**9
STATE_KEY = "fleet/default/vehicle/{}/state"


@functools.cache
def _message_class(name: str, data: bytes):
    files = descriptor_pb2.FileDescriptorSet.FromString(data)
    pool = descriptor_pool.DescriptorPool()
    for file in files.file:
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name))


def decode(message, data: bytes | None = None):
    """The protobuf message a Foxglove message encodes to (or `data`, if given)."""
    schema = message.get_schema()
    cls = _message_class(schema.name, bytes(schema.data))
    return cls.FromString(message.encode() if data is None else data)


@pytest.fixture(scope="module")
def paper():
    return load_layout("paper")


def views_by_topic(views):
    out: dict[str, list] = {}
    for topic, message, ns in views:
        out.setdefault(topic, []).append((decode(message), ns))
    return out


def state(vehicle=1, x=0.0, y=0.0, theta=0.0, loaded=False):
    return VehicleState(vehicle, "8,10,S", 1, "forward", loaded, x, y, theta)


def entity(views, topic, entity_id=None):
    """The one entity (or the one with this id) of the one update on a topic."""
    ((update, _ns),) = views_by_topic(views)[topic]
    if entity_id is None:
        (one,) = update.entities
        return one
    (one,) = [e for e in update.entities if e.id == entity_id]
    return one


def cells_of(layout, ent):
    """The cells whose centres the entity's cubes stand on."""
    size, (ox, oy) = layout.cell_size, layout.origin
    return {(round((c.pose.position.x - ox) / size), round((c.pose.position.y - oy) / size))
            for c in ent.cubes}


def yaw(q) -> float:
    return 2 * math.atan2(q.z, q.w)


def same_angle(a: float, b: float) -> bool:
    return abs(math.remainder(a - b, 2 * math.pi)) < 1e-9


# ------------------------------------------------------------------------ static scene


def test_static_scene_has_an_entity_per_group(paper):
    views = views_by_topic(SceneViews(paper, BASE).start())
    ((warehouse, ns),) = views["/view/warehouse"]
    assert ns == BASE
    by_id = {e.id: e for e in warehouse.entities}
    for cluster in paper.clusters:
        stacks = {s.cell for s in paper.cluster_stacks(cluster.name)}
        assert cells_of(paper, by_id[f"cluster/{cluster.name}"]) == stacks
        assert by_id[f"cluster/{cluster.name}"].texts[0].text == cluster.name
    for obstacle in paper.obstacles:
        assert cells_of(paper, by_id[f"obstacle/{obstacle.name}"]) == obstacle.cells
    for station in paper.stations:
        assert cells_of(paper, by_id[f"station/{station.name}"]) == {station.cell}
    for passage in paper.passages:
        assert cells_of(paper, by_id[f"passage/{passage.name}"]) == passage.cells
    grid = by_id["floor"].lines[0]
    assert len(grid.points) == 2 * (paper.cols + 1 + paper.rows + 1)
    for e in warehouse.entities:
        assert e.frame_id == FRAME
        assert e.timestamp.seconds * 10**9 + e.timestamp.nanos == BASE
    ((tf, _),) = views["/view/tf"]
    assert [(t.parent_frame_id, t.child_frame_id) for t in tf.transforms] == [("world", FRAME)]
    ((goods, _),) = views["/view/goods"]
    assert list(goods.entities[0].cubes) == []  # a fill mission starts with empty stacks


def test_stack_done_puts_goods_on_the_stack_or_takes_them(paper):
    stack = paper.stacks[5]
    done = StackDone(stack.cluster, stack.index, 2, 42.5)
    fill = SceneViews(paper, BASE, kind="fill")
    views = fill.on_message("fleet/default/dispatch/stack", done, 42.5)
    assert [ns for _, _, ns in views] == [BASE + 42_500_000_000]
    goods = entity(views, "/view/goods")
    assert cells_of(paper, goods) == {stack.cell}
    assert goods.cubes[0].color.r == pytest.approx(GOODS_COLOR[0])

    empty = SceneViews(paper, BASE, kind="empty")
    start = entity(empty.start(), "/view/goods")
    assert cells_of(paper, start) == {s.cell for s in paper.stacks}
    goods = entity(empty.on_message("k", done, 42.5), "/view/goods")
    assert cells_of(paper, goods) == {s.cell for s in paper.stacks} - {stack.cell}

    assert fill.on_message("k", StackDone("nowhere", 1, 2, 1.0), 1.0) == []
    with pytest.raises(ValueError, match="kind"):
        SceneViews(paper, BASE, kind="refill")


def test_an_outside_masters_goods_are_those_the_store_holds(paper):
    """A session of an outside master's (kind external) has no StackDone: its goods are the
    store's GOODS, put down by a drop's commit and taken by a pick's release; a mission's
    goods reservations (made ahead, when a delivery is decided) draw nothing."""
    a, b = paper.stacks[3].cell, paper.stacks[8].cell
    session = SceneViews(paper, BASE, kind="external")
    assert cells_of(paper, entity(session.start(), "/view/goods")) == set()
    put = WireChange(1, "commit", GOODS, [(*a, 20.0, math.inf)])
    views = session.on_message("k", put, 20.0)
    assert [ns for _, _, ns in views] == [BASE + 20_000_000_000]
    assert cells_of(paper, entity(views, "/view/goods")) == {a}
    session.on_message("k", WireChange(2, "commit", GOODS, [(*b, 30.0, math.inf)]), 30.0)
    taken = WireChange(3, "release", GOODS, release_from=40.0, release_cells=[a])
    assert cells_of(paper, entity(session.on_message("k", taken, 40.0), "/view/goods")) == {b}
    assert SceneViews(paper, BASE, kind="fill").on_message("k", put, 20.0) == []


def test_other_messages_give_nothing(paper):
    views = SceneViews(paper, BASE)
    assert views.on_message("fleet/default/dispatch/progress", Progress(1, 136, 3.0, 0), 3.0) == []


# ------------------------------------------------------------------------ forklifts


@pytest.mark.parametrize("theta", [0.0, 0.7, math.pi / 2, -2.5])
def test_forklift_is_its_body_rectangle_at_the_pose(paper, theta):
    x, y, t = 3.25, -1.5, 12.25
    views = SceneViews(paper, BASE).on_message(STATE_KEY.format(3), state(3, x, y, theta), t)
    assert {ns for _, _, ns in views} == {BASE + 12_250_000_000}
    forklift = entity(views, "/view/forklifts")
    assert forklift.id == "forklift/3"
    assert forklift.frame_id == FRAME
    body = forklift.cubes[0]
    dims = paper.vehicle.dims
    assert body.size.x == pytest.approx(dims.front + dims.rear)
    assert body.size.y == pytest.approx(dims.width)
    phi = yaw(body.pose.orientation)
    assert same_angle(phi, theta)
    c, s = math.cos(phi), math.sin(phi)
    cx, cy = body.pose.position.x, body.pose.position.y
    corners = sorted((round(cx + u * c - v * s, 9), round(cy + u * s + v * c, 9))
                     for u in (-body.size.x / 2, body.size.x / 2)
                     for v in (-body.size.y / 2, body.size.y / 2))
    expected = sorted((round(px, 9), round(py, 9))
                      for px, py in body_corners(x, y, theta, dims))
    assert [v for corner in corners for v in corner] == pytest.approx(
        [v for corner in expected for v in corner])
    (arrow,) = forklift.arrows
    assert (arrow.pose.position.x, arrow.pose.position.y) == pytest.approx((x, y))
    assert same_angle(yaw(arrow.pose.orientation), theta)
    assert forklift.texts[0].text == "3"
    assert body.color.r == pytest.approx(forklift_color(3)[0])


def test_loaded_forklift_carries_goods_on_its_forks(paper):
    views = SceneViews(paper, BASE)
    theta = 0.4
    empty = entity(views.on_message("k", state(2, 1.0, 1.0, theta), 1.0), "/view/forklifts")
    loaded = entity(views.on_message("k", state(2, 1.0, 1.0, theta, loaded=True), 1.5),
                    "/view/forklifts")
    assert len(empty.cubes) == 1
    assert len(loaded.cubes) == 2
    cargo = loaded.cubes[1]
    assert (cargo.color.r, cargo.color.g, cargo.color.b) == pytest.approx(GOODS_COLOR)
    # the forks are at the rear: behind the rear-axle point along the heading
    ahead = ((cargo.pose.position.x - 1.0) * math.cos(theta)
             + (cargo.pose.position.y - 1.0) * math.sin(theta))
    assert ahead < 0
    assert {kv.key: kv.value for kv in loaded.metadata}["loaded"] == "true"
    assert {kv.key: kv.value for kv in empty.metadata}["loaded"] == "false"


def test_non_finite_state_is_skipped(paper):
    assert SceneViews(paper, BASE).on_message("k", state(1, math.inf), 1.0) == []


def test_one_message_shows_the_whole_fleet_at_each_instant(paper):
    """After a seek Foxglove shows each topic's last message: it must hold every forklift."""
    views = SceneViews(paper, BASE, vehicles=2)
    assert views.on_message(STATE_KEY.format(1), state(1, 1.0), 0.5) == []  # 2 not yet
    out = views_by_topic(views.on_message(STATE_KEY.format(2), state(2, 5.0), 0.5))
    (update, ns), = out["/view/forklifts"]
    assert [e.id for e in update.entities] == ["forklift/1", "forklift/2"]
    assert ns == BASE + 500_000_000
    (reserved, _), = out["/view/reserved"]
    assert [e.id for e in reserved.entities] == ["reserved/1", "reserved/2"]
    # forklift 2 goes quiet at 1.0: that instant is shown with what it has once 1.5 is whole
    assert views.on_message(STATE_KEY.format(1), state(1, 2.0), 1.0) == []
    assert views.on_message(STATE_KEY.format(1), state(1, 3.0), 1.5) == []
    out = views.on_message(STATE_KEY.format(2), state(2, 6.0), 1.5)
    frames = views_by_topic(out)["/view/forklifts"]
    assert [ns for _, ns in frames] == [BASE + 1_000_000_000, BASE + 1_500_000_000]
    assert frames[0][0].entities[1].cubes[0].pose.position.x == pytest.approx(
        5.0 + (paper.vehicle.dims.front - paper.vehicle.dims.rear) / 2)  # 2 where last seen
    assert views.on_message(STATE_KEY.format(2), state(2, 6.0), 1.0) == []  # came too late


def test_the_static_scene_comes_again_every_ten_seconds(paper):
    views = SceneViews(paper, BASE)
    topics = [sorted(views_by_topic(views.on_message(STATE_KEY.format(1), state(1), t)))
              for t in (0.5, 9.5, 10.0, 10.5, 20.0)]
    static = ["/view/goods", "/view/tf", "/view/warehouse"]
    assert [static[0] in t for t in topics] == [False, False, True, False, True]


def test_a_forklift_has_one_colour_in_the_gantt_chart_a_snapshot_and_foxglove(tmp_path):
    layout, record, states = recorded(tmp_path, two_forklift_record())
    chart = gantt(record).axes[0]
    picture = snapshot(layout, record, 20.0).axes[0]
    views = SceneViews(layout, BASE, vehicles=2)
    shown = []
    for t, s in states:
        if t == 20.0:
            shown += views.on_message(STATE_KEY.format(s.vehicle), s, t)
    scene = {e.id: e for e in views_by_topic(shown)["/view/forklifts"][0][0].entities}
    rows = {label.get_text(): (y, label) for y, label in zip(
        chart.get_yticks(), chart.get_yticklabels(), strict=True)}
    bodies = {p.get_gid(): p for p in picture.patches if p.get_gid()}
    seen = []
    for v in (1, 2):
        (subtask,) = [s for s in record.subtasks if s.vehicle == v]
        y, label = rows[f"forklift {v}"]
        # The bar of its subtask's drive (a "deliver": the forklift's own colour), its row's
        # name, its body in the snapshot and its body in Foxglove.
        (bar,) = [p for p in chart.patches if isinstance(p, Rectangle)
                  and p.get_x() == pytest.approx(subtask.t_i)
                  and p.get_width() == pytest.approx(subtask.t_end - subtask.t_i)
                  and abs(p.get_y() + p.get_height() / 2 - y) < 1e-9]
        body = scene[f"forklift/{v}"].cubes[0].color
        colours = [to_rgb(bar.get_facecolor()), to_rgb(label.get_color()),
                   to_rgb(bodies[f"forklift/{v}"].get_facecolor()), (body.r, body.g, body.b)]
        for colour in colours[1:]:
            assert colour == pytest.approx(colours[0], abs=1e-6), v
        seen.append(colours[0])
    assert seen[0] != pytest.approx(seen[1], abs=0.05)  # and two forklifts are told apart


# ------------------------------------------------------------------------ reservations


def reserved_cells(views, paper, vehicle, t):
    out = views.on_message(STATE_KEY.format(vehicle), state(vehicle), t)
    ent = entity(out, "/view/reserved", f"reserved/{vehicle}")
    assert ent.id == f"reserved/{vehicle}"
    return cells_of(paper, ent), ent


def test_reserved_cells_ahead_follow_the_table(paper):
    views = SceneViews(paper, BASE)
    inf = math.inf
    views.on_message("k", WireChange(1, "commit", 2, [(8, 10, 0.0, inf), (9, 10, 0.0, inf)]), 0.0)
    assert reserved_cells(views, paper, 2, 0.0)[0] == {(8, 10), (9, 10)}

    # a trajectory from 5 s: the parking is cut at 5 s, the cells beyond the horizon wait
    views.on_message("k", WireChange(2, "commit", 2, [(8, 10, 5.0, 8.0), (8, 9, 6.0, 10.0),
                                                  (8, 8, 9.0, 14.0), (8, 7, 30.0, inf)],
                                 release_from=5.0), 5.0)
    cells, ent = reserved_cells(views, paper, 2, 4.0)
    assert cells == {(8, 10), (9, 10), (8, 9), (8, 8)}
    assert all(c.color.r == pytest.approx(forklift_color(2)[0]) and 0 < c.color.a < 1
               for c in ent.cubes)
    assert reserved_cells(views, paper, 2, 10.0)[0] == {(8, 8)}  # (8, 7) is 20 s ahead
    assert reserved_cells(views, paper, 2, 30.0 - HORIZON_S + 1.0)[0] == {(8, 8), (8, 7)}

    # replanned at 12 s: everything from 12 s on goes, (8, 8) is cut to [9, 12)
    views.on_message("k", WireChange(3, "commit", 2, [(7, 8, 12.0, inf)], release_from=12.0), 12.0)
    assert reserved_cells(views, paper, 2, 11.5)[0] == {(8, 8), (7, 8)}
    assert reserved_cells(views, paper, 2, 12.0)[0] == {(7, 8)}

    # a release drops the rest; the entity is sent empty so it clears the previous one
    views.on_message("k", WireChange(4, "release", 2, [], release_from=13.0), 13.0)
    assert reserved_cells(views, paper, 2, 13.0)[0] == set()
    # other forklifts and the goods (owner 0) do not show on forklift 2's view
    views.on_message("k", WireChange(5, "commit", 0, [(0, 11, 13.0, inf)]), 13.0)
    views.on_message("k", WireChange(6, "commit", 3, [(5, 5, 13.0, inf)]), 13.0)
    assert reserved_cells(views, paper, 2, 14.0)[0] == set()
    assert reserved_cells(views, paper, 3, 14.5)[0] == {(5, 5)}
    assert 0 not in views.reserved


# ------------------------------------------------------------------------ recording


def test_views_write_to_mcap_as_foxglove_protobuf(paper, tmp_path):
    path = tmp_path / "run.mcap"
    writer = RecordingWriter(path)
    views = SceneViews(paper, BASE)
    written = views.start()
    views.on_message("k", WireChange(1, "commit", 1, [(8, 10, 0.0, math.inf)]), 0.0)
    written += views.on_message(STATE_KEY.format(1), state(1, 1.0, 2.0, 0.5, True), 0.5)
    stack = paper.stacks[0]
    written += views.on_message("k", StackDone(stack.cluster, stack.index, 1, 9.0), 9.0)
    for topic, message, ns in written:
        writer.write_view(topic, message, ns)
    writer.close()

    with open(path, "rb") as f:
        reader = make_reader(f)
        found = {}
        for schema, channel, message in reader.iter_messages():
            assert channel.message_encoding == "protobuf"
            assert schema.encoding == "protobuf"
            found.setdefault(channel.topic, []).append((schema, message))
    assert {topic: [s.name for s, _ in rows] for topic, rows in found.items()} == {
        "/view/tf": ["foxglove.FrameTransforms"], "/view/warehouse": ["foxglove.SceneUpdate"],
        "/view/goods": ["foxglove.SceneUpdate"] * 2, "/view/forklifts": ["foxglove.SceneUpdate"],
        "/view/reserved": ["foxglove.SceneUpdate"]}
    # decoded with the schema the file holds, as Foxglove reads it
    schema, message = found["/view/forklifts"][0]
    update = _message_class(schema.name, bytes(schema.data)).FromString(message.data)
    assert update.entities[0].id == "forklift/1"
    assert message.log_time == BASE + 500_000_000
    assert read_recording(path).view_schemas["/view/goods"] == "foxglove.SceneUpdate"


# ------------------------------------------------------------------------ live view


def test_live_view_advertises_and_sends_the_view_channels():
    update = SceneUpdate(entities=[SceneEntity(id="forklift/1", frame_id=FRAME)])
    with LiveView(port=0) as live:
        assert live.port > 0
        live.publish("/view/forklifts", update)  # before any client: replayed on subscribe
        with connect(live.url, subprotocols=["foxglove.sdk.v1"],
                                       open_timeout=5) as ws:
            assert json.loads(ws.recv(timeout=5))["op"] == "serverInfo"
            channel = None
            while channel is None:
                msg = json.loads(ws.recv(timeout=5))
                if msg["op"] == "advertise":
                    channel = next((c for c in msg["channels"]
                                    if c["topic"] == "/view/forklifts"), None)
            assert channel["schemaName"] == "foxglove.SceneUpdate"
            assert channel["encoding"] == "protobuf"
            ws.send(json.dumps({"op": "subscribe",
                                "subscriptions": [{"id": 7, "channelId": channel["id"]}]}))

            def next_data() -> bytes:
                while True:
                    frame = ws.recv(timeout=5)
                    if isinstance(frame, bytes) and frame[0] == 1:  # message data
                        (subscription,) = struct.unpack_from("<I", frame, 1)
                        assert subscription == 7
                        return frame[1 + 4 + 8:]

            assert next_data() == update.encode()
            moved = SceneUpdate(entities=[SceneEntity(id="forklift/2", frame_id=FRAME)])
            live.publish("/view/forklifts", moved)
            assert decode(moved, next_data()).entities[0].id == "forklift/2"
        with pytest.raises(ValueError, match="carries"):
            live.publish("/view/forklifts", FrameTransforms())
    assert live.closed


@pytest.mark.parametrize("t", [-1.0, 1e10, 1e300, math.inf])
def test_a_sim_time_no_run_has_shows_nothing(paper, t):
    views = SceneViews(paper, BASE)
    assert views.on_message(STATE_KEY.format(1), state(1), t) == []
    assert views.on_message("k", StackDone("s1", 1, 1, t), t) == []
