"""Layout files: a warehouse layout's TOML text (docs/layouts.md), by built-in name or path,
read and checked into a `fleet.world.layout.Layout`.

Loading checks the structure (known keys, a known vehicle kind, cells on the map, no element
overlapping another, docks working their station, distinct start poses, and an ASCII drawing
that agrees with the data), raising LayoutError at the first problem, naming the element;
poses and docks are checked with the vehicle kind the layout names.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Iterable
from importlib import resources
from pathlib import Path

from fleet.errors import UserError
from fleet.params import VehicleDims
from fleet.planning.geometry import Cell
from fleet.planning.trajectory import Pose
from fleet.vehicles import registry
from fleet.vehicles.kind import VehicleKind
from fleet.world.floor004_file import FLOOR_TABLE, FloorParts
from fleet.world.lane_file import LANE_TABLES, LaneParts
from fleet.world.layout import (
    FREE,
    NOTCH,
    PASSAGE,
    STATION,
    Cluster,
    Layout,
    LayoutError,
    Obstacle,
    Passage,
    Stack,
    Station,
    VehicleSpec,
)

RESERVED_SYMBOLS = {FREE, PASSAGE, NOTCH, STATION, "#", " "}
MAX_MAP_CELLS = 1_000_000  # far beyond any warehouse here; bounds what a hostile file costs


def builtin_names() -> list[str]:
    files = resources.files("fleet.world.layouts")
    return sorted(p.name[:-5] for p in files.iterdir() if p.name.endswith(".toml"))


def load_layout(name_or_path: str | Path) -> Layout:
    """A built-in layout by name (`paper`, `small`, ...) or a TOML file by path."""
    text = str(name_or_path)
    where = f"layout {text}" if text in builtin_names() else text
    return parse_layout(layout_source(name_or_path), where)


def layout_source(name_or_path: str | Path) -> str:
    """The TOML text of a built-in layout or a layout file."""
    text = str(name_or_path)
    if text in builtin_names():
        return resources.files("fleet.world.layouts").joinpath(f"{text}.toml").read_text()
    path = Path(text)
    if not path.is_file():
        raise UserError(f"layout {text!r} is neither a built-in layout "
                        f"({', '.join(builtin_names())}) nor a file")
    return path.read_text()


def parse_layout(source: str, where: str) -> Layout:
    try:
        data = tomllib.loads(source)
    except ValueError as exc:  # TOMLDecodeError, or an integer literal too long to convert
        raise LayoutError(f"{where}: not valid TOML: {exc}") from None
    except RecursionError:
        raise LayoutError(f"{where}: not valid TOML: arrays or tables nested too deep") from None
    return _Builder(data, where).build()


def parse_cells(text: str, where: str, within: tuple[int, int] | None = None) -> list[Cell]:
    """'c,r' is one cell; 'c0,r0..c1,r1' every cell of the rectangle, listed from the first
    corner towards the second (row by row). With `within` (cols, rows), a cell or corner off
    that map is refused before the rectangle is listed."""
    try:
        if ".." not in text:
            c, r = (int(v) for v in text.split(","))
            _on_map((c, r), within, where)
            return [(c, r)]
        first, last = text.split("..")
        c0, r0 = (int(v) for v in first.split(","))
        c1, r1 = (int(v) for v in last.split(","))
    except ValueError:
        raise LayoutError(f"{where}: {text!r} is not a cell 'col,row' or a range "
                          f"'col,row..col,row'") from None
    _on_map((c0, r0), within, where)
    _on_map((c1, r1), within, where)
    count = (abs(c1 - c0) + 1) * (abs(r1 - r0) + 1)
    if count > MAX_MAP_CELLS:
        raise LayoutError(f"{where}: range {text!r} covers {count} cells, more than a map "
                          f"may have ({MAX_MAP_CELLS})")
    dc = 1 if c1 >= c0 else -1
    dr = 1 if r1 >= r0 else -1
    return [(c, r) for r in range(r0, r1 + dr, dr) for c in range(c0, c1 + dc, dc)]


def _on_map(cell: Cell, within: tuple[int, int] | None, where: str) -> None:
    if within is not None and not (0 <= cell[0] < within[0] and 0 <= cell[1] < within[1]):
        raise LayoutError(f"{where}: cell {cell} is off the {within[0]} x {within[1]} map")


def _finite(value: object) -> bool:
    """A real number (not a bool) that fits a float and is neither infinite nor NaN."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:  # an integer too large for a float
        return False


_TOP_KEYS = {"name", "description", "cell_size", "bounds", "vehicle", "cluster", "station",
             "obstacle", "passage", "starts", "drawing", FLOOR_TABLE, *LANE_TABLES}


class _Builder(LaneParts, FloorParts):
    """Turns the parsed TOML into a Layout, raising LayoutError at the first problem."""

    def __init__(self, data: dict, where: str) -> None:
        self.data = data
        self.where = where
        self.owner: dict[Cell, str] = {}  # cell -> the element that claims it
        self.kind: VehicleKind | None  # set by `vehicle`; None for a kind not built yet

    def fail(self, message: str) -> LayoutError:
        return LayoutError(f"{self.where}: {message}")

    def keys(self, table: dict, allowed: set[str], element: str) -> None:
        unknown = sorted(set(table) - allowed)
        if unknown:
            raise self.fail(f"{element}: unknown key {unknown[0]!r} "
                            f"(known: {', '.join(sorted(allowed))})")

    def get(self, table: dict, key: str, kind: type, element: str, default=None):
        if key not in table:
            if default is None:
                raise self.fail(f"{element}: missing {key!r}")
            return default
        value = table[key]
        if kind is float:
            if not _finite(value):
                raise self.fail(f"{element}: {key!r} must be a float (a finite number), "
                                f"not {value!r}")
            return float(value)
        if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
            raise self.fail(f"{element}: {key!r} must be a {kind.__name__}, not {value!r}")
        return value

    def cells(self, texts, element: str) -> list[Cell]:
        if isinstance(texts, str):
            texts = [texts]
        if not isinstance(texts, list):
            raise self.fail(f"{element}: cells must be a string or a list of strings")
        found: list[Cell] = []
        for text in texts:
            if not isinstance(text, str):
                raise self.fail(f"{element}: cell {text!r} must be a string 'col,row'")
            found += parse_cells(text, f"{self.where}: {element}", (self.cols, self.rows))
        return found

    def claim(self, cells: Iterable[Cell], element: str) -> None:
        for cell in cells:
            other = self.owner.get(cell)
            if other is not None:
                raise self.fail(f"{element} overlaps {other} at cell {cell}")
            self.owner[cell] = element

    def pose(self, text, element: str) -> Pose:
        if not isinstance(text, str):
            raise self.fail(f"{element}: pose {text!r} must be a string 'col,row,H'")
        if self.kind is None:
            raise self.fail(f"{element}: a pose is checked with the vehicle kind's body, and "
                            f"the {self.data['vehicle']['kind']} vehicle kind is not built yet")
        try:
            pose = Pose.parse(text)
        except ValueError as exc:
            raise self.fail(f"{element}: {exc}") from None
        for cell in self.kind.body_cells_at_rest(pose):
            if not (0 <= cell[0] < self.cols and 0 <= cell[1] < self.rows):
                raise self.fail(f"{element}: pose {pose} puts the body on cell {cell}, off the "
                                f"{self.cols} x {self.rows} map")
        return pose

    def build(self) -> Layout:
        data = self.data
        self.keys(data, _TOP_KEYS, "layout")
        name = self.get(data, "name", str, "layout")
        description = self.get(data, "description", str, "layout", "")
        cell_size = self.get(data, "cell_size", float, "layout", 2.0)
        if cell_size <= 0:
            raise self.fail(f"layout: cell_size must be positive, not {cell_size}")
        bounds = self.get(data, "bounds", dict, "layout")
        self.keys(bounds, {"x", "y"}, "bounds")
        spans = []
        for axis in ("x", "y"):
            span = bounds.get(axis)
            if (not isinstance(span, list) or len(span) != 2
                    or not all(_finite(v) for v in span) or span[1] <= span[0]):
                raise self.fail(f"bounds: {axis} must be [min, max] in metres with min < max")
            cells = (float(span[1]) - float(span[0])) / cell_size
            if not cells <= MAX_MAP_CELLS:
                raise self.fail(f"bounds: {axis} spans {cells:g} cells of {cell_size:g} m, "
                                f"more than a map may have ({MAX_MAP_CELLS})")
            if abs(cells - round(cells)) > 1e-9 or round(cells) < 1:
                raise self.fail(f"bounds: {axis} span {span[1] - span[0]:g} m is not a whole "
                                f"number of {cell_size:g} m cells")
            spans.append((float(span[0]), round(cells)))
        (x0, self.cols), (y0, self.rows) = spans
        if self.cols * self.rows > MAX_MAP_CELLS:
            raise self.fail(f"bounds: the map of {self.cols} x {self.rows} cells has more than "
                            f"{MAX_MAP_CELLS} cells")
        origin = (x0 + cell_size / 2, y0 + cell_size / 2)

        vehicle = self.vehicle(data.get("vehicle", {}), cell_size)
        if self.is_floor004():
            return self.floor_layout(Layout(name, description, self.cols, self.rows, cell_size,
                                            origin, (), (), (), (), (), vehicle, (), ""))
        obstacles = [self.obstacle(t, i) for i, t in enumerate(self.tables("obstacle"))]
        if self.is_lane_layout():
            layout = self.lane_layout(Layout(name, description, self.cols, self.rows,
                                             cell_size, origin, (), (), (), tuple(obstacles),
                                             (), vehicle, (), ""))
            drawing = self.drawing(data.get("drawing"), layout)
            return dataclasses.replace(layout, drawing=drawing)
        stations = [self.station(t, i) for i, t in enumerate(self.tables("station"))]
        clusters, stacks = [], []
        for i, table in enumerate(self.tables("cluster")):
            cluster, cluster_stacks = self.cluster(table, i)
            clusters.append(cluster)
            stacks.extend(cluster_stacks)
        passages = [self.passage(t, i) for i, t in enumerate(self.tables("passage"))]
        self.unique_names(clusters, stations, obstacles, passages)
        for station in stations:
            for cell in self.kind.body_cells_at_rest(station.dock):
                self.free_for(cell, f"station {station.name}: dock {station.dock}")
        starts = self.starts(data.get("starts", []))
        layout = Layout(name, description, self.cols, self.rows, cell_size, origin,
                        tuple(clusters), tuple(stacks), tuple(stations), tuple(obstacles),
                        tuple(passages), vehicle, tuple(starts), "")
        drawing = self.drawing(data.get("drawing"), layout)
        return dataclasses.replace(layout, drawing=drawing)

    def tables(self, key: str) -> list[dict]:
        value = self.data.get(key, [])
        if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
            raise self.fail(f"{key}: must be an array of tables [[{key}]]")
        return value

    def vehicle(self, table: dict, cell_size: float) -> VehicleSpec:
        if not isinstance(table, dict):
            raise self.fail("vehicle: must be a table [vehicle]")
        fields = {"front_overhang", "rear_overhang", "wheelbase", "width"}
        self.keys(table, {"kind", "passes_under_shelves"} | fields, "vehicle")
        kind = self.get(table, "kind", str, "vehicle", "forklift")
        defaults = VehicleDims()
        dims = VehicleDims(**{f: self.get(table, f, float, "vehicle", getattr(defaults, f))
                              for f in sorted(fields)})
        if min(dims.__dict__.values()) <= 0:
            raise self.fail("vehicle: every dimension must be positive")
        try:
            self.kind = registry.vehicle_kind(kind, dims, cell_size)
        except registry.KindNotBuilt:
            self.kind = None  # the layout may still load, show and check (registry.PLANNED)
        except registry.UnknownVehicleKind as exc:
            raise self.fail(f"vehicle: {exc}") from None
        under = table.get("passes_under_shelves", False)
        if not isinstance(under, bool):
            raise self.fail("vehicle: passes_under_shelves must be true or false")
        return VehicleSpec(kind, dims, under)

    def obstacle(self, table: dict, i: int) -> Obstacle:
        element = self.element(table, "obstacle", i)
        self.keys(table, {"name", "kind", "cells", "symbol"}, element)
        name = self.get(table, "name", str, element)
        element = f"obstacle {name}"
        kind = self.get(table, "kind", str, element, "wall")
        symbol = self.symbol(table, element, "#")
        cells = self.cells(table.get("cells", []), element)
        if not cells:
            raise self.fail(f"{element}: has no cells")
        self.claim(cells, element)
        return Obstacle(name, kind, frozenset(cells), symbol)

    def station(self, table: dict, i: int) -> Station:
        element = self.element(table, "station", i)
        self.keys(table, {"name", "cell", "dock"}, element)
        name = self.get(table, "name", str, element)
        element = f"station {name}"
        cells = self.cells(self.get(table, "cell", str, element), element)
        if len(cells) != 1:
            raise self.fail(f"{element}: cell must be one cell")
        cell = cells[0]
        self.claim([cell], element)
        dock = self.pose(self.get(table, "dock", str, element), element)
        worked = self.kind.handled_cell(dock)
        if worked != cell:
            raise self.fail(f"{element}: dock {dock} works cell {worked}, not the station "
                            f"{cell}")
        return Station(name, cell, dock)

    def cluster(self, table: dict, i: int) -> tuple[Cluster, list[Stack]]:
        element = self.element(table, "cluster", i)
        self.keys(table, {"name", "symbol", "fill", "notches"}, element)
        name = self.get(table, "name", str, element)
        if not name:
            raise self.fail(f"{element}: 'name' must not be empty")
        element = f"cluster {name}"
        symbol = self.symbol(table, element, name[-1])
        runs = table.get("fill")
        if not isinstance(runs, list) or not runs:
            raise self.fail(f"{element}: 'fill' must list its stacks in fill order")
        order: list[Cell] = []
        for run in runs:
            cells = self.cells(run, element)
            if len({c[0] for c in cells}) > 1 and len({c[1] for c in cells}) > 1:
                raise self.fail(f"{element}: fill run {run!r} is not a straight line, so its "
                                f"order is ambiguous")
            order.extend(cells)
        stacks = []
        for index, cell in enumerate(order, start=1):
            self.claim([cell], f"{element} stack {index}")
            stacks.append(Stack(name, index, cell))
        notches = self.cells(table.get("notches", []), f"{element} notches")
        self.claim(notches, f"{element} notch")
        return Cluster(name, symbol, frozenset(notches)), stacks

    def passage(self, table: dict, i: int) -> Passage:
        element = self.element(table, "passage", i)
        self.keys(table, {"name", "kind", "cells"}, element)
        name = self.get(table, "name", str, element)
        element = f"passage {name}"
        kind = self.get(table, "kind", str, element, "wide")
        if kind not in ("wide", "channel"):
            raise self.fail(f"{element}: kind {kind!r} is not 'wide' or 'channel'")
        cells = self.cells(table.get("cells", []), element)
        for cell in cells:
            other = self.owner.get(cell)
            if other is not None and not other.startswith("passage"):
                raise self.fail(f"{element} overlaps {other} at cell {cell}")
        return Passage(name, kind, frozenset(cells))

    @staticmethod
    def element(table: dict, kind: str, i: int) -> str:
        """How errors name a table: by its name when it has one, else by its position."""
        name = table.get("name")
        return f"{kind} {name}" if isinstance(name, str) and name else f"{kind}[{i}]"

    def symbol(self, table: dict, element: str, default: str) -> str:
        symbol = self.get(table, "symbol", str, element, default)
        if len(symbol) != 1 or symbol in RESERVED_SYMBOLS - {"#"}:
            raise self.fail(f"{element}: symbol {symbol!r} must be one character other than "
                            f"{' '.join(sorted(RESERVED_SYMBOLS - {'#', ' '}))}")
        return symbol

    def unique_names(self, *groups) -> None:
        seen: set[str] = set()
        for group in groups:
            for element in group:
                if element.name in seen:
                    raise self.fail(f"name {element.name!r} is used twice")
                seen.add(element.name)

    def free_for(self, cell: Cell, element: str) -> None:
        other = self.owner.get(cell)
        if other is not None and not other.startswith("passage"):
            raise self.fail(f"{element} puts the body on cell {cell}, which is {other}")

    def starts(self, texts) -> list[Pose]:
        if not isinstance(texts, list):
            raise self.fail("starts: must be a list of poses 'col,row,H'")
        poses: list[Pose] = []
        taken: dict[Cell, int] = {}
        for i, text in enumerate(texts, start=1):
            element = f"start {i}"
            pose = self.pose(text, element)
            for cell in self.kind.body_cells_at_rest(pose):
                if cell in self.owner and "stack" in self.owner[cell]:
                    raise self.fail(f"{element}: pose {pose} stands on {self.owner[cell]}, "
                                    f"which would block it from being filled")
                self.free_for(cell, f"{element}: pose {pose}")
                if cell in taken:
                    raise self.fail(f"{element}: pose {pose} overlaps start {taken[cell]} at "
                                    f"cell {cell}")
                taken[cell] = i
            poses.append(pose)
        return poses

    def drawing(self, text, layout: Layout) -> str:
        expected = layout.render_drawing()
        if text is None:
            return expected
        if not isinstance(text, str):
            raise self.fail("drawing: must be a multi-line string")
        lines = [line.rstrip() for line in text.strip("\n").split("\n")]
        if len(lines) != layout.rows:
            raise self.fail(f"drawing: has {len(lines)} rows, the map has {layout.rows}")
        owners = {cell: self.owner.get(cell, "free floor") for cell in self.owner}
        passage_of = {c: f"passage {p.name}" for p in layout.passages for c in p.cells}
        want_lines = expected.split("\n")
        for k, (got, want) in enumerate(zip(lines, want_lines, strict=True)):
            row = layout.rows - 1 - k
            if len(got) != layout.cols:
                raise self.fail(f"drawing: row {row} has {len(got)} columns, the map has "
                                f"{layout.cols}")
            for col, (g, w) in enumerate(zip(got, want, strict=True)):
                if g != w:
                    what = owners.get((col, row)) or passage_of.get((col, row), "free floor")
                    raise self.fail(f"drawing: cell ({col}, {row}) shows {g!r} but the data "
                                    f"makes it {what} ({w!r})")
        return expected

