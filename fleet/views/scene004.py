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

from foxglove.messages import ArrowPrimitive, KeyValuePair, Pose, SceneEntity, SceneUpdate, Vector3

from fleet.mission.record004 import NotAnEvent, event_from_wire
from fleet.mission.tracking004 import ZoneClosed
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
from fleet.views.state004 import AgvTrack, closed_at
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


class Scene004Views(SceneViews):
    def __init__(self, layout: Layout, base_ns: int, kind: str = "orders",
                 vehicles: int = 1) -> None:
        super().__init__(layout, base_ns, kind, vehicles)
        assert layout.floor is not None
        self.floor: Floor004 = layout.floor
        self.agvs = {v: AgvTrack(xy) for v, xy in enumerate(self.floor.parking[:vehicles], 1)}
        self.entered: dict[XY, int] = {}
        self.next_frame = 0.0
        self.zones: list[ZoneClosed] = []
        self.zones_shown: frozenset[XY] = frozenset()
        self.away_shown: frozenset[XY] = frozenset()  # the shelves last shown away

    # -- entry points (SceneViews') ----------------------------------------------------------
    def on_message(self, key: str, message: Message, sim_time: float) -> list[View]:
        if isinstance(message, MissionDone):  # the last moves, to where they end
            end = max((a.t1 for a in self.agvs.values()), default=0.0)
            return self._frames_before(end + FRAME_S) if _plausible(end) else []
        if not isinstance(message, AgvEvent) or not _plausible(message.t0) or \
                (message.kind != "zone_closed" and message.vehicle not in self.agvs):
            return []
        views = self._frames_before(message.t0)
        try:
            event = event_from_wire(message, self.floor)
        except NotAnEvent:
            return views  # (fleet analyze names it)
        if isinstance(event, ZoneClosed):
            self.zones.append(event)
        else:
            self.agvs[message.vehicle].apply(event)
            if message.kind == "moved" and message.to is not None:
                self.entered[message.to] = self.entered.get(message.to, 0) + 1
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

    def _frame004(self, t: float) -> list[View]:
        ns = self.log_ns(t)
        views: list[View] = []
        if t - self.static_at >= STATIC_PERIOD_S:
            self.static_at = t
            views += [(topic, message, ns) for topic, message, _ in self._static(ns)]
            views.append((HEAT, self._heat(ns), ns))
        for agv in self.agvs.values():
            agv.settle(t)
        if self._away() != self.away_shown:
            views.append((GOODS_TOPIC, self._goods_update(ns), ns))
        views.append((FORKLIFTS, SceneUpdate(entities=[
            self._lifting_agv(v, agv, t, ns) for v, agv in sorted(self.agvs.items())]), ns))
        closed = closed_at(self.zones, t)
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

    def _lifting_agv(self, v: int, agv: AgvTrack, t: float, ns: int) -> SceneEntity:
        x, y = self._xy(agv.cell)
        if agv.to is not None and agv.t1 > agv.t0:
            share = agv.share(t)
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
                      KeyValuePair(key="down", value=str(agv.broken(t)).lower()),
                      KeyValuePair(key="heading", value=agv.heading.name.lower()),
                      KeyValuePair(key="shelf", value="" if agv.shelf is None else
                                   f"{agv.shelf[0]},{agv.shelf[1]}")])

    def _goods_update(self, ns: int) -> SceneUpdate:
        """The shelves standing home: every slot whose shelf no AGV carries."""
        away = self.away_shown = self._away()
        side = self.layout.cell_size * 0.8
        cubes = [self._cell_box(self.floor.cell(s.xy), side, 0.0, SHELF_H, _color(SHELF_COLOR))
                 for s in self.floor.slots if s.xy not in away]
        return SceneUpdate(entities=[SceneEntity(timestamp=_stamp(ns), frame_id=FRAME,
                                                 id="shelves", cubes=cubes)])

    def _away(self) -> frozenset[XY]:
        return frozenset(a.shelf for a in self.agvs.values() if a.shelf is not None)

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
