"""Foxglove views of a run: the warehouse, the forklifts, their reservations ahead and the goods
on the stacks as Foxglove scene messages (foxglove.messages, protobuf), for the view channels
of a recording (RecordingWriter.write_view) and for the live view (recorder.live). On a lane
layout (seed 002): the lanes with their directions, slots, packing stations and piles; the
shelves where they stand; the AGVs, each with the shelf it carries.

Pure: messages in, messages out, no I/O. Everything lies in one frame, "warehouse", whose
x, y are the layout's world metres (z up, the floor at z = 0); /view/tf hangs it under a
root frame "world" so the 3D panel has a display frame from the first message on.

Foxglove's 3D panel shows, after a seek, the last message of each topic before that instant,
so each topic's last message must be enough on its own: the static scene and the goods are
whole snapshots, and the forklifts (one entity each, replaced by every state) come back
within one state period (0.5 s of simulated time).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from foxglove.messages import (
    ArrowPrimitive,
    Color,
    CubePrimitive,
    FrameTransform,
    FrameTransforms,
    KeyValuePair,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    TextPrimitive,
    Timestamp,
    TriangleListPrimitive,
    Vector3,
)

from fleet.mission.spec import EXTERNAL
from fleet.planning.geometry import Cell
from fleet.views.palette import (
    GOODS_COLOR,
    PILE_COLOR,
    RACK_COLOR,
    SHELF_COLOR,
    STATION_COLOR,
    forklift_color,
)
from fleet.views.shelf_tracker import ShelfTracker
from fleet.wire.protocol import (
    GOODS,
    LegAmended,
    Message,
    StackDone,
    SubtaskEvent,
    VehicleState,
    WireChange,
)
from fleet.world.layout import Layout

FRAME = "warehouse"
ROOT_FRAME = "world"
TF = "/view/tf"
WAREHOUSE = "/view/warehouse"
GOODS_TOPIC = "/view/goods"
FORKLIFTS = "/view/forklifts"
RESERVED = "/view/reserved"
HORIZON_S = 20.0  # how far ahead /view/reserved shows a forklift's reservations
STATIC_PERIOD_S = 10.0  # the static scene is sent again every this many sim seconds
NS = 1_000_000_000
MAX_SIM_TIME_S = 1e7  # no mission lasts 115 days

View = tuple[str, Any, int]  # (topic, foxglove message, log time in ns)

# Heights (metres): low racks under the goods, walls taller than anything that moves.
RACK_H, GOODS_H, BODY_H, CARGO_H, WALL_H, STATION_H = 0.1, 1.2, 0.5, 1.0, 3.0, 1.0
RESERVED_H = 0.04
# Lane layouts: an AGV is low (it drives under shelves), a shelf stands on legs.
AGV_H, SHELF_H, PILE_H, MARK_Z = 0.3, 1.2, 0.05, 0.012

# Forklifts, goods, racks and stations have the plots' colours (fleet/views/palette.py).
FLOOR_COLOR = (0.20, 0.20, 0.22)
OBSTACLE_COLORS = {"firewall": (0.60, 0.15, 0.10)}  # other kinds (walls, pillars): grey
WALL_COLOR = (0.50, 0.50, 0.50)
PASSAGE_COLOR = (0.80, 0.75, 0.30)
WHITE = (1.0, 1.0, 1.0)
LANE_ARROW_COLOR = (0.85, 0.85, 0.85)  # on the dark floor
JUNCTION_COLOR = (0.38, 0.38, 0.42)
# An arrowhead on a lane cell, pointing east, in cells about the cell's centre.
ARROW = ((0.3, 0.0), (-0.2, 0.25), (-0.2, -0.25))
TURN = {"E": (1, 0), "N": (0, 1), "W": (-1, 0), "S": (0, -1)}  # (cos, sin) of a direction


def _color(rgb: tuple[float, float, float], a: float = 1.0) -> Color:
    return Color(r=rgb[0], g=rgb[1], b=rgb[2], a=a)


def _plausible(sim_time: float) -> bool:
    """A sim time a run can have (a forged one would not fit Foxglove's timestamps)."""
    return 0.0 <= sim_time <= MAX_SIM_TIME_S


def _stamp(ns: int) -> Timestamp:
    return Timestamp(ns // NS, ns % NS)


def _yaw(theta: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(theta / 2), w=math.cos(theta / 2))


_LEVEL = _yaw(0.0)


def _box(x: float, y: float, z: float, sx: float, sy: float, sz: float, color: Color,
         orientation: Quaternion = _LEVEL) -> CubePrimitive:
    """A box centred at (x, y, z) with sides sx, sy, sz along its own axes."""
    return CubePrimitive(pose=Pose(position=Vector3(x=x, y=y, z=z), orientation=orientation),
                         size=Vector3(x=sx, y=sy, z=sz), color=color)


def _label(text: str, x: float, y: float, z: float) -> TextPrimitive:
    """A text that faces the camera at a constant size on screen."""
    return TextPrimitive(pose=Pose(position=Vector3(x=x, y=y, z=z), orientation=_LEVEL),
                         billboard=True, font_size=14.0, scale_invariant=True,
                         color=_color(WHITE), text=text)


@dataclass(frozen=True, slots=True)
class _Reserved:
    """One reserved cell of one forklift over [t0, t1) (t1 may be infinity)."""

    cell: Cell
    t0: float
    t1: float


class SceneViews:
    """Foxglove scene messages from a run's stream (pure: no I/O).

    `on_message` is called for every message of the run in arrival order with its simulation
    time; it keeps each forklift's reservations from the table's changes and answers with
    the view messages that change. Log times are `base_ns` plus the simulation time.
    """

    def __init__(self, layout: Layout, base_ns: int, kind: str = "fill",
                 vehicles: int = 1) -> None:
        if kind not in ("fill", "empty", "orders", EXTERNAL):
            raise ValueError(f"mission kind {kind!r} is not 'fill', 'empty', 'orders' or "
                             f"'{EXTERNAL}'")
        self.layout = layout
        self.vehicles = vehicles
        self.latest: dict[int, VehicleState] = {}  # each forklift's last state shown
        self.pending: dict[float, dict[int, VehicleState]] = {}  # instant -> states so far
        self.static_at = 0.0  # sim time the static scene was last sent
        self.shown_until = -math.inf  # the last instant shown
        self.base_ns = base_ns
        self.kind = kind
        self._stacks = {(s.cluster, s.index): s.cell for s in layout.stacks}
        # An empty mission starts with goods on every stack; StackDone removes them. (An
        # order mission's shelves are in the layout's slots: it has no stacks.) A session of
        # an outside master's starts empty: its goods are those the store holds (GOODS).
        self.goods: set[Cell] = {s.cell for s in layout.stacks} if kind == "empty" else set()
        self.reserved: dict[int, list[_Reserved]] = {}  # forklift -> its reservations
        # A lane layout's shelves: where each stands, which AGV carries which.
        self.shelves = ShelfTracker(layout) if layout.has_lanes else None
        # Reserved cells are drawn tens of thousands of times: their poses are built once.
        self._cell_pose: dict[Cell, Pose] = {}

    # ------------------------------------------------------------------ entry points

    def start(self) -> list[View]:
        """The root transform, the static warehouse and the goods at the start, at base_ns."""
        return self._static(self.base_ns)

    def _static(self, ns: int) -> list[View]:
        tf = FrameTransforms(transforms=[FrameTransform(
            timestamp=_stamp(ns), parent_frame_id=ROOT_FRAME, child_frame_id=FRAME,
            translation=Vector3(x=0.0, y=0.0, z=0.0), rotation=_LEVEL)])
        return [(TF, tf, ns),
                (WAREHOUSE, SceneUpdate(entities=self._warehouse(ns)), ns),
                (GOODS_TOPIC, self._goods_update(ns), ns)]

    def on_message(self, key: str, message: Message, sim_time: float) -> list[View]:
        """The view messages `message` (received on zenoh key `key`) changes; [] for kinds
        that change nothing. The kind is told by the message's type, so `key` is unused."""
        if isinstance(message, VehicleState):
            return self._on_state(message, sim_time)
        if isinstance(message, WireChange):
            if message.vehicle == GOODS:
                return self._on_goods(message, sim_time)
            self._on_change(message)
            return []  # shown with the forklift's next state, at most 0.5 s later
        if isinstance(message, StackDone):
            return self._on_stack(message, sim_time)
        if self.shelves is not None and isinstance(message, SubtaskEvent | LegAmended):
            self.shelves.on_trip(message)  # when a stow puts its shelf down
        return []

    def log_ns(self, sim_time: float) -> int:
        return max(0, self.base_ns + round(sim_time * NS))

    # ------------------------------------------------------------------ dynamic views

    def _on_state(self, state: VehicleState, sim_time: float) -> list[View]:
        """Forklifts publish on one grid of instants: once every forklift has reported an
        instant, one message per topic shows them all there (after a seek Foxglove shows the
        last message of each topic, which must hold the whole fleet). Earlier instants still
        incomplete (a forklift gone quiet) are shown with what they have."""
        if not (all(math.isfinite(v) for v in (state.x, state.y, state.theta))
                and _plausible(sim_time)):
            return []
        if state.vehicle == GOODS or sim_time <= self.shown_until:
            return []  # an instant already shown (this forklift came late to it)
        self.pending.setdefault(sim_time, {})[state.vehicle] = state
        if len(self.pending[sim_time]) < self.vehicles:
            return []
        views: list[View] = []
        for t in sorted(k for k in self.pending if k <= sim_time):
            views += self._frame(t, self.pending.pop(t))
        return views

    def _frame(self, t: float, states: dict[int, VehicleState]) -> list[View]:
        self.latest.update(states)
        self.shown_until = t
        ns = self.log_ns(t)
        views: list[View] = []
        moved = self.shelves is not None and any(  # a list: every state is heard
            [self.shelves.on_state(states[v], t) for v in sorted(states)])
        if t - self.static_at >= STATIC_PERIOD_S:  # so a viewer that lost it gets it back
            self.static_at = t
            views += [(topic, message, ns) for topic, message, _ in self._static(ns)]
        elif moved:
            views.append((GOODS_TOPIC, self._goods_update(ns), ns))
        vehicles = sorted(self.latest)
        draw = self._forklift if self.shelves is None else self._agv
        views.append((FORKLIFTS, SceneUpdate(
            entities=[draw(self.latest[v], ns) for v in vehicles]), ns))
        views.append((RESERVED, SceneUpdate(
            entities=[self._reserved_ahead(v, t, ns) for v in vehicles]), ns))
        return views

    def _on_goods(self, change: WireChange, sim_time: float) -> list[View]:
        """A mission's goods are drawn from StackDone (the engine reserves a stack's goods
        ahead, when it decides the delivery); an outside master's session's from the store:
        the gateway reserves goods from the instant a drop puts them down, and lets them go
        when a pick takes them."""
        if self.kind != EXTERNAL or not _plausible(sim_time):
            return []
        if change.op == "commit":
            self.goods |= {(c, r) for c, r, _, _ in change.intervals}
        elif change.release_cells is None:
            self.goods.clear()
        else:
            self.goods -= {tuple(cell) for cell in change.release_cells}
        ns = self.log_ns(sim_time)
        return [(GOODS_TOPIC, self._goods_update(ns), ns)]

    def _on_change(self, change: WireChange) -> None:
        if change.op == "release":
            self._release(change.vehicle, -math.inf if change.release_from is None
                          else change.release_from)
        elif change.op == "commit":
            if change.release_from is not None:
                self._release(change.vehicle, change.release_from)
            self.reserved.setdefault(change.vehicle, []).extend(
                _Reserved((c, r), t0, t1) for c, r, t0, t1 in change.intervals)

    def _release(self, vehicle: int, from_t: float) -> None:
        """As the reservation table releases: intervals from `from_t` on go, those spanning it
        are cut there."""
        held = self.reserved.get(vehicle)
        if held:
            self.reserved[vehicle] = [iv if iv.t1 <= from_t else _Reserved(iv.cell, iv.t0, from_t)
                                      for iv in held if iv.t0 < from_t]

    def _on_stack(self, done: StackDone, sim_time: float) -> list[View]:
        cell = self._stacks.get((done.cluster, done.index))
        if cell is None or not _plausible(sim_time):
            return []
        if self.kind == "fill":
            self.goods.add(cell)
        else:
            self.goods.discard(cell)
        ns = self.log_ns(sim_time)
        return [(GOODS_TOPIC, self._goods_update(ns), ns)]

    def _forklift(self, state: VehicleState, ns: int) -> SceneEntity:
        """The body rectangle of geometry.body_corners (from `rear` behind the rear-axle point
        to `front` ahead of it), an arrow along the heading, the goods on the forks (the rear)
        when loaded, and the forklift's number."""
        dims = self.layout.vehicle_kind.outline  # front, rear and width of the body
        x, y, theta = state.x, state.y, state.theta
        c, s = math.cos(theta), math.sin(theta)
        yaw = _yaw(theta)
        mid = (dims.front - dims.rear) / 2  # body centre ahead of the rear-axle point
        color = _color(forklift_color(state.vehicle))
        cubes = [_box(x + mid * c, y + mid * s, BODY_H / 2, dims.front + dims.rear,
                      dims.width, BODY_H, color, yaw)]
        if state.loaded:
            back = -dims.rear / 2
            cubes.append(_box(x + back * c, y + back * s, BODY_H + CARGO_H / 2, dims.rear,
                              dims.width, CARGO_H, _color(GOODS_COLOR), yaw))
        arrow = ArrowPrimitive(
            pose=Pose(position=Vector3(x=x, y=y, z=BODY_H + 0.05), orientation=yaw),
            shaft_length=dims.front * 0.7, shaft_diameter=0.15, head_length=0.4,
            head_diameter=0.35, color=_color(WHITE))
        return SceneEntity(
            timestamp=_stamp(ns), frame_id=FRAME, id=f"forklift/{state.vehicle}",
            cubes=cubes, arrows=[arrow], texts=[_label(str(state.vehicle), x, y, 2.5)],
            metadata=[KeyValuePair(key="pose", value=state.pose),
                      KeyValuePair(key="maneuver", value=state.maneuver),
                      KeyValuePair(key="loaded", value=str(state.loaded).lower())])

    def _agv(self, state: VehicleState, ns: int) -> SceneEntity:
        """A lane layout's AGV: a low square box of its body in its colour (it has no heading),
        the shelf it carries standing on it, and its number."""
        assert self.shelves is not None
        side = self.layout.vehicle_kind.outline.width
        x, y = state.x, state.y
        cubes = [_box(x, y, AGV_H / 2, side, side, AGV_H, _color(forklift_color(state.vehicle)))]
        shelf = self.shelves.carried.get(state.vehicle)
        if shelf is not None:
            top = self.layout.cell_size * 0.8
            cubes.append(_box(x, y, AGV_H + SHELF_H / 2, top, top, SHELF_H,
                              _color(SHELF_COLOR)))
        return SceneEntity(
            timestamp=_stamp(ns), frame_id=FRAME, id=f"agv/{state.vehicle}", cubes=cubes,
            texts=[_label(str(state.vehicle), x, y, AGV_H + SHELF_H + 0.6)],
            metadata=[KeyValuePair(key="pose", value=state.pose),
                      KeyValuePair(key="maneuver", value=state.maneuver),
                      KeyValuePair(key="shelf", value=shelf or "")])

    def _reserved_ahead(self, vehicle: int, t: float, ns: int) -> SceneEntity:
        """The forklift's cells reserved over [t, t + HORIZON_S), the sooner the more opaque.
        Reservations that ended are dropped here: states of a forklift come in time order."""
        ahead: dict[Cell, float] = {}  # cell -> how soon it is reserved (s)
        held = self.reserved.get(vehicle)
        if held:
            held[:] = [iv for iv in held if iv.t1 > t]
            horizon = t + HORIZON_S
            for iv in held:
                if iv.t0 < horizon:
                    soon = max(iv.t0 - t, 0.0)
                    if soon < ahead.get(iv.cell, math.inf):
                        ahead[iv.cell] = soon
        rgb = forklift_color(vehicle)
        side = self.layout.cell_size * 0.9
        cubes = [CubePrimitive(pose=self._pose_of(cell), size=Vector3(x=side, y=side,
                               z=RESERVED_H), color=_color(rgb, 0.6 - 0.45 * soon / HORIZON_S))
                 for cell, soon in ahead.items()]
        # An entity with no cubes replaces (clears) the previous one.
        return SceneEntity(timestamp=_stamp(ns), frame_id=FRAME, id=f"reserved/{vehicle}",
                           cubes=cubes)

    def _pose_of(self, cell: Cell) -> Pose:
        pose = self._cell_pose.get(cell)
        if pose is None:
            x, y = self.layout.cell_center(cell)
            pose = Pose(position=Vector3(x=x, y=y, z=RACK_H + RESERVED_H / 2 + 0.01),
                        orientation=_LEVEL)  # above the racks, or they hide it
            self._cell_pose[cell] = pose
        return pose

    def _goods_update(self, ns: int) -> SceneUpdate:
        """Every stack's goods in one entity: the last message alone says where they all are.
        On a lane layout, the shelves standing in slots (those on AGVs ride with them)."""
        side = self.layout.cell_size * 0.8
        if self.shelves is not None:
            cubes = [self._cell_box(cell, side, 0.0, SHELF_H, _color(SHELF_COLOR))
                     for cell in sorted(self.shelves.in_slot)]
            return SceneUpdate(entities=[SceneEntity(timestamp=_stamp(ns), frame_id=FRAME,
                                                     id="shelves", cubes=cubes)])
        cubes = [self._cell_box(cell, side, RACK_H, GOODS_H, _color(GOODS_COLOR))
                 for cell in sorted(self.goods)]
        return SceneUpdate(entities=[SceneEntity(timestamp=_stamp(ns), frame_id=FRAME,
                                                 id="goods", cubes=cubes)])

    # ------------------------------------------------------------------ static scene

    def _cell_box(self, cell: Cell, side: float, z0: float, height: float,
                  color: Color) -> CubePrimitive:
        x, y = self.layout.cell_center(cell)
        return _box(x, y, z0 + height / 2, side, side, height, color)

    def _group(self, entity_id: str, cells: Iterable[Cell], side: float, z0: float,
               height: float, color: Color, ns: int, label: str = "") -> SceneEntity:
        """One static entity: a box on each cell, and a label over their middle."""
        cells = sorted(cells)
        texts = []
        if label:
            xs, ys = zip(*(self.layout.cell_center(c) for c in cells), strict=True)
            texts.append(_label(label, sum(xs) / len(xs), sum(ys) / len(ys), z0 + height + 0.5))
        return SceneEntity(timestamp=_stamp(ns), frame_id=FRAME, id=entity_id,
                           cubes=[self._cell_box(c, side, z0, height, color) for c in cells],
                           texts=texts)

    def _warehouse(self, ns: int) -> list[SceneEntity]:
        """The floor with its grid, and an entity per cluster of stacks, passage, obstacle and
        station."""
        layout, size = self.layout, self.layout.cell_size
        entities = [self._floor(ns)]
        if layout.has_lanes:
            entities += self._lane_places(ns)
        for p in layout.passages:
            entities.append(self._group(f"passage/{p.name}", p.cells, size, 0.0, 0.01,
                                        _color(PASSAGE_COLOR, 0.35), ns))
        for cluster in layout.clusters:
            cells = [s.cell for s in layout.cluster_stacks(cluster.name)]
            entities.append(self._group(f"cluster/{cluster.name}", cells, size * 0.9, 0.0,
                                        RACK_H, _color(RACK_COLOR), ns, cluster.name))
        for o in layout.obstacles:
            entities.append(self._group(f"obstacle/{o.name}", o.cells, size, 0.0, WALL_H,
                                        _color(OBSTACLE_COLORS.get(o.kind, WALL_COLOR)), ns))
        for st in layout.stations:
            entities.append(self._group(f"station/{st.name}", [st.cell], size * 0.8, 0.0,
                                        STATION_H, _color(STATION_COLOR), ns, st.name))
        return entities

    def _lane_places(self, ns: int) -> list[SceneEntity]:
        """A lane layout: the lanes (an arrowhead on each cell outside junctions, pointing
        its way, and the junctions' cells), the slots (low racks), each packing station and
        each pile, named."""
        layout, size = self.layout, self.layout.cell_size
        junctions = {c for j in layout.junctions for c in j.cells}
        arrows = []
        for cell, directions in sorted(layout.lane_directions.items()):
            if cell in junctions:
                continue
            x, y = layout.cell_center(cell)
            for d in sorted(directions):
                c, s = TURN[d]
                arrows += [Point3(x=x + size * (u * c - v * s), y=y + size * (u * s + v * c),
                                  z=MARK_Z) for u, v in ARROW]
        tiles = []
        for cell in sorted(junctions):
            x, y = layout.cell_center(cell)
            h = size * 0.48
            a, b, c, d = ((x - h, y - h), (x + h, y - h), (x + h, y + h), (x - h, y + h))
            tiles += [Point3(x=px, y=py, z=MARK_Z / 2) for px, py in (a, b, c, a, c, d)]
        lanes = SceneEntity(timestamp=_stamp(ns), frame_id=FRAME, id="lanes", triangles=[
            TriangleListPrimitive(pose=Pose(position=Vector3(x=0.0, y=0.0, z=0.0),
                                            orientation=_LEVEL), points=points,
                                  color=_color(rgb, alpha))
            for points, rgb, alpha in ((tiles, JUNCTION_COLOR, 1.0),
                                       (arrows, LANE_ARROW_COLOR, 0.8)) if points])
        entities = [lanes, self._group("slots", [s.cell for s in layout.slots], size * 0.9, 0.0,
                                       RACK_H, _color(RACK_COLOR), ns)]
        for p in layout.packing:
            entities.append(self._group(f"packing/{p.name}", [p.cell], size * 0.8, 0.0,
                                        STATION_H, _color(STATION_COLOR), ns, p.name))
        for p in layout.piles:
            entities.append(self._group(f"pile/{p.name}", [p.cell], size * 0.8, 0.0, PILE_H,
                                        _color(PILE_COLOR), ns, p.name))
        return entities

    def _floor(self, ns: int) -> SceneEntity:
        """A slab under the map and the cell borders drawn on it."""
        layout, size = self.layout, self.layout.cell_size
        x0, y0 = layout.origin[0] - size / 2, layout.origin[1] - size / 2
        x1, y1 = x0 + layout.cols * size, y0 + layout.rows * size
        z = 0.005
        points = []
        for i in range(layout.cols + 1):
            points += [Point3(x=x0 + i * size, y=y0, z=z), Point3(x=x0 + i * size, y=y1, z=z)]
        for j in range(layout.rows + 1):
            points += [Point3(x=x0, y=y0 + j * size, z=z), Point3(x=x1, y=y0 + j * size, z=z)]
        grid = LinePrimitive(type=LinePrimitiveLineType.LineList, thickness=1.0,
                             scale_invariant=True, points=points, color=_color(WHITE, 0.25))
        slab = _box((x0 + x1) / 2, (y0 + y1) / 2, -0.01, x1 - x0, y1 - y0, 0.02,
                    _color(FLOOR_COLOR))
        return SceneEntity(timestamp=_stamp(ns), frame_id=FRAME, id="floor", cubes=[slab],
                           lines=[grid])
