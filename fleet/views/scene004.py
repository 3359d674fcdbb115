"""Foxglove views of a seed-004 run: the floor with its slots, station routes, worker places and
piles; the shelves standing home (a lifted one rides on its AGV); the lifting AGVs with their
heading; and the heat of the run so far (cells entered, the brighter the more). Built from
the tracking events (`AgvEvent`), as `SceneViews` is from forklift states, with the same
entry points, so the recorder and the in-process recording use either alike.

The AGVs are drawn on a grid of instants (every FRAME_S of sim time): events come in time
order, so once one is later than an instant, everything before it is known; an AGV between
two cells is drawn where it is at that instant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from foxglove.messages import ArrowPrimitive, KeyValuePair, Pose, SceneEntity, SceneUpdate, Vector3

from fleet.planning.rules004 import XY, Direction, Kind
from fleet.views.palette import PILE_COLOR, RACK_COLOR, SHELF_COLOR, STATION_COLOR, forklift_color
from fleet.views.scene import (
    AGV_H,
    FORKLIFTS,
    FRAME,
    GOODS_TOPIC,
    PILE_H,
    RACK_H,
    SHELF_H,
    STATIC_PERIOD_S,
    WALL_COLOR,
    WALL_H,
    WHITE,
    SceneViews,
    View,
    _box,
    _color,
    _label,
    _plausible,
    _stamp,
    _yaw,
)
from fleet.wire.protocol import AgvEvent, Message, MissionDone
from fleet.world.floor004 import Floor004
from fleet.world.layout import Layout

FRAME_S = 0.5  # the AGVs are drawn every this many sim seconds (as forklift states come)
HEAT = "/view/heat"
LANE_COLOR = (0.55, 0.70, 0.90)  # a station's route
HEAT_COLOR = (1.0, 0.45, 0.10)
ZONES = "/view/zones"
ZONE_COLOR = (0.85, 0.10, 0.10)  # a closed zone (a fault)
# The seed's direction code as a yaw in the project's frame (its y points up; the seed's down).
YAW = {Direction.UP: math.pi / 2, Direction.LEFT: math.pi, Direction.DOWN: -math.pi / 2,
       Direction.RIGHT: 0.0}


@dataclass
class _Agv:
    cell: XY
    heading: Direction = Direction.DOWN
    to: XY | None = None  # moving from `cell` to `to` over [t0, t1)
    t0: float = 0.0
    t1: float = 0.0
    shelf: XY | None = None  # the home of the shelf it carries (from the lift's end)
    lift_at: tuple[float, XY] | None = None  # a lift under way: it carries from then
    drop_at: float | None = None  # a drop under way: it carries until then
    down: tuple[float, float] = (0.0, 0.0)  # broken down over [t0, t1)


class Scene004Views(SceneViews):
    def __init__(self, layout: Layout, base_ns: int, kind: str = "orders",
                 vehicles: int = 1) -> None:
        super().__init__(layout, base_ns, kind, vehicles)
        assert layout.floor is not None
        self.floor: Floor004 = layout.floor
        self.agvs = {v: _Agv(xy) for v, xy in enumerate(self.floor.parking[:vehicles], 1)}
        self.entered: dict[XY, int] = {}
        self.next_frame = 0.0
        self.zones: list[tuple[float, float, tuple[XY, ...]]] = []  # closed: t0, t1, cells
        self.zones_shown: frozenset[XY] = frozenset()

    # -- entry points (SceneViews') ----------------------------------------------------------
    def on_message(self, key: str, message: Message, sim_time: float) -> list[View]:
        if isinstance(message, MissionDone):  # the last moves, to where they end
            end = max((a.t1 for a in self.agvs.values()), default=0.0)
            return self._frames_before(end + FRAME_S) if _plausible(end) else []
        if isinstance(message, AgvEvent) and message.kind == "zone_closed" and \
                _plausible(message.t0):
            views = self._frames_before(message.t0)
            self.zones.append((message.t0, message.t1, tuple(message.cells)))
            return views
        if not isinstance(message, AgvEvent) or not _plausible(message.t0) or \
                message.vehicle not in self.agvs:
            return []
        views = self._frames_before(message.t0)
        self._apply(message)
        return views

    def _frames_before(self, t: float) -> list[View]:
        """Every instant of the grid before `t` not drawn yet (at most one a static period:
        a long quiet stretch shows no motion)."""
        views: list[View] = []
        if t > self.next_frame + STATIC_PERIOD_S:
            self.next_frame = math.floor((t - STATIC_PERIOD_S) / FRAME_S) * FRAME_S
        while self.next_frame < t:
            views += self._frame004(self.next_frame)
            self.next_frame += FRAME_S
        return views

    def _apply(self, m: AgvEvent) -> None:
        agv = self.agvs[m.vehicle]
        if m.kind == "moved" and m.to is not None:
            self._settle(agv, m.t0)
            agv.cell, agv.to, agv.t0, agv.t1 = m.at, m.to, m.t0, m.t1
            self.entered[m.to] = self.entered.get(m.to, 0) + 1
        elif m.kind == "turned" and m.heading in YAW:
            agv.heading = Direction(m.heading)
        elif m.kind == "paused" and m.label == "lift":
            agv.lift_at = (m.t1, m.at)
        elif m.kind == "paused" and m.label == "drop":
            agv.drop_at = m.t1
        elif m.kind == "broke_down":
            agv.down = (m.t0, m.t1)

    @staticmethod
    def _settle(agv: _Agv, t: float) -> None:
        """What has ended by `t`: a move, a lift, a drop."""
        if agv.to is not None and agv.t1 <= t:
            agv.cell, agv.to = agv.to, None
        if agv.lift_at is not None and agv.lift_at[0] <= t:
            agv.shelf, agv.lift_at = agv.lift_at[1], None
        if agv.drop_at is not None and agv.drop_at <= t:
            agv.shelf, agv.drop_at = None, None

    def _frame004(self, t: float) -> list[View]:
        ns = self.log_ns(t)
        views: list[View] = []
        if t - self.static_at >= STATIC_PERIOD_S:
            self.static_at = t
            views += [(topic, message, ns) for topic, message, _ in self._static(ns)]
            views.append((HEAT, self._heat(ns), ns))
        away = {a.shelf for a in self.agvs.values()}
        for agv in self.agvs.values():
            self._settle(agv, t)
        if away != {a.shelf for a in self.agvs.values()}:
            views.append((GOODS_TOPIC, self._goods_update(ns), ns))
        views.append((FORKLIFTS, SceneUpdate(entities=[
            self._lifting_agv(v, agv, t, ns) for v, agv in sorted(self.agvs.items())]), ns))
        closed = frozenset(xy for t0, t1, cells in self.zones if t0 <= t < t1 for xy in cells)
        if closed != self.zones_shown:
            self.zones_shown = closed
            side = self.layout.cell_size * 0.95
            views.append((ZONES, SceneUpdate(entities=[SceneEntity(
                timestamp=_stamp(ns), frame_id=FRAME, id="closed", cubes=[
                    self._cell_box(self.floor.cell(xy), side, 0.0, 0.05,
                                   _color(ZONE_COLOR, 0.8)) for xy in sorted(closed)])]), ns))
        return views

    # -- drawing -----------------------------------------------------------------------------
    def _xy(self, cell: XY) -> tuple[float, float]:
        return self.layout.cell_center(self.floor.cell(cell))

    def _lifting_agv(self, v: int, agv: _Agv, t: float, ns: int) -> SceneEntity:
        x, y = self._xy(agv.cell)
        if agv.to is not None and agv.t1 > agv.t0:
            share = min(max((t - agv.t0) / (agv.t1 - agv.t0), 0.0), 1.0)
            x2, y2 = self._xy(agv.to)
            x, y = x + (x2 - x) * share, y + (y2 - y) * share
        side = self.layout.cell_size * 0.8
        yaw = _yaw(YAW[agv.heading])
        cubes = [_box(x, y, AGV_H / 2, side, side, AGV_H, _color(forklift_color(v)), yaw)]
        if agv.shelf is not None:
            cubes.append(_box(x, y, AGV_H + SHELF_H / 2, side, side, SHELF_H,
                              _color(SHELF_COLOR)))
        arrow = ArrowPrimitive(pose=Pose(position=Vector3(x=x, y=y, z=AGV_H + 0.02),
                                         orientation=yaw),
                               shaft_length=0.3, shaft_diameter=0.08, head_length=0.15,
                               head_diameter=0.2, color=_color(WHITE))
        return SceneEntity(
            timestamp=_stamp(ns), frame_id=FRAME, id=f"agv/{v}", cubes=cubes,
            arrows=[arrow], texts=[_label(str(v), x, y, AGV_H + SHELF_H + 0.6)],
            metadata=[KeyValuePair(key="cell", value=f"{agv.cell[0]},{agv.cell[1]}"),
                      KeyValuePair(key="down", value=str(agv.down[0] <= t < agv.down[1]).lower()),
                      KeyValuePair(key="heading", value=agv.heading.name.lower()),
                      KeyValuePair(key="shelf", value="" if agv.shelf is None else
                                   f"{agv.shelf[0]},{agv.shelf[1]}")])

    def _goods_update(self, ns: int) -> SceneUpdate:
        """The shelves standing home: every slot whose shelf no AGV carries."""
        away = {a.shelf for a in self.agvs.values()}
        side = self.layout.cell_size * 0.8
        cubes = [self._cell_box(self.floor.cell(s.xy), side, 0.0, SHELF_H, _color(SHELF_COLOR))
                 for s in self.floor.slots if s.xy not in away]
        return SceneUpdate(entities=[SceneEntity(timestamp=_stamp(ns), frame_id=FRAME,
                                                 id="shelves", cubes=cubes)])

    def _warehouse(self, ns: int) -> list[SceneEntity]:
        """The floor, the slots (low racks), the walls and station structure, each station's
        route and each pile."""
        floor, size = self.floor, self.layout.cell_size
        by_kind: dict[Kind, list[tuple[int, int]]] = {}
        for xy, kind in floor.kinds.items():
            by_kind.setdefault(kind, []).append(floor.cell(xy))
        entities = [self._floor(ns),
                    self._group("slots", by_kind.get(Kind.SLOT, []), size * 0.9, 0.0, RACK_H,
                                _color(RACK_COLOR), ns),
                    self._group("walls", by_kind.get(Kind.WALL, []) +
                                by_kind.get(Kind.STRUCTURE, []), size, 0.0, WALL_H / 3,
                                _color(WALL_COLOR), ns)]
        for s in floor.stations:
            entities.append(self._group(f"station/{s.name}", [floor.cell(c) for c in s.route],
                                        size * 0.9, 0.0, 0.01, _color(LANE_COLOR, 0.6), ns,
                                        s.name))
            entities.append(self._group(f"worker/{s.name}", [floor.cell(s.worker)], size * 0.6,
                                        0.0, 1.0, _color(STATION_COLOR), ns))
        entities.append(self._group("piles", [floor.cell(p) for p in floor.piles], size * 0.8,
                                    0.0, PILE_H, _color(PILE_COLOR), ns))
        return entities

    def _heat(self, ns: int) -> SceneUpdate:
        """The cells entered so far, the more often the more opaque (Figures 10-11 live)."""
        top = max(self.entered.values(), default=0)
        side = self.layout.cell_size * 0.9
        cubes = [self._cell_box(self.floor.cell(xy), side, 0.0, 0.02,
                                _color(HEAT_COLOR, 0.15 + 0.85 * n / top))
                 for xy, n in sorted(self.entered.items())]
        return SceneUpdate(entities=[SceneEntity(timestamp=_stamp(ns), frame_id=FRAME,
                                                 id="heat", cubes=cubes)])



def scene_views(layout: Layout, base_ns: int, kind: str = "fill",
                vehicles: int = 1) -> SceneViews:
    """The Foxglove views of a run on `layout`: a seed-004 floor's, or seed 000's and 002's."""
    if layout.floor is not None:
        return Scene004Views(layout, base_ns, kind, vehicles)
    return SceneViews(layout, base_ns, kind, vehicles)
