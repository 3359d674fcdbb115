"""Parametric warehouses for scale tests, in the pattern of the paper's layout.

A wide vertical main passage (2 cells) runs through the middle with two stations at each end.
`aisles` wide horizontal aisles (2 cells) cross it; on each side of the main passage an aisle
has `depth` lanes above it and `depth` lanes below, each `lane_depth` stacks deep and filled
from its far end. Every aisle ends in a station at both map edges. Forklifts start parked in
the aisles' lower rows facing the main passage, spread over the aisles.
"""

from __future__ import annotations

from dataclasses import dataclass

import tomli_w

from fleet.errors import UserError
from fleet.world.layout import Layout
from fleet.world.layout_file import parse_layout

MIN_DEPTH = 4  # lanes per side: fewer leave an aisle no parking slot (slots_per_aisle)


@dataclass(frozen=True)
class Shape:
    aisles: int = 2
    depth: int = 8  # lanes per side of the main passage, above and below each aisle
    lane_depth: int = 5
    vehicles: int = 4
    cell_size: float = 2.0

    @property
    def cols(self) -> int:
        return 2 * self.depth + 4  # station column, lanes, main passage, lanes, station column

    @property
    def rows(self) -> int:
        return self.aisles * (2 * self.lane_depth + 2)

    @property
    def main(self) -> tuple[int, int]:
        return self.depth + 1, self.depth + 2

    @property
    def slots_per_aisle(self) -> int:
        return 2 * ((self.depth - 2) // 2)


def generate(shape: Shape, name: str | None = None) -> dict:
    """The layout as TOML-ready data (see docs/layouts.md)."""
    _validate(shape)
    name = name or f"generated-{shape.aisles}x{shape.depth}"
    cols, rows, (m0, m1) = shape.cols, shape.rows, shape.main
    L = shape.lane_depth
    clusters, stations, walls, passages = [], [], [], []
    passages.append({"name": "main", "kind": "wide", "cells": [f"{m0},1..{m1},{rows - 2}"]})
    for c in (m0, m1):
        stations.append({"name": f"main-{c}-bottom", "cell": f"{c},0", "dock": f"{c},1,N"})
        stations.append({"name": f"main-{c}-top", "cell": f"{c},{rows - 1}",
                         "dock": f"{c},{rows - 2},S"})
    letters = iter("abcdefghijklmopqrstuvwxyz" * (4 * shape.aisles))
    for a in range(shape.aisles):
        base = a * (2 * L + 2)
        low, high = base + L, base + L + 1  # the aisle's two rows
        passages.append({"name": f"aisle-{a + 1}", "kind": "wide",
                         "cells": [f"1,{low}..{m0 - 1},{high}",
                                   f"{m1 + 1},{low}..{cols - 2},{high}"]})
        for r in (low, high):
            stations.append({"name": f"aisle-{a + 1}-{r - low + 1}-west", "cell": f"0,{r}",
                             "dock": f"1,{r},E"})
            stations.append({"name": f"aisle-{a + 1}-{r - low + 1}-east",
                             "cell": f"{cols - 1},{r}", "dock": f"{cols - 2},{r},W"})
        walls.append(f"0,{base}..0,{low - 1}")
        walls.append(f"0,{high + 1}..0,{high + L}")
        walls.append(f"{cols - 1},{base}..{cols - 1},{low - 1}")
        walls.append(f"{cols - 1},{high + 1}..{cols - 1},{high + L}")
        for side, lane_cols in (("w", range(1, m0)), ("e", range(cols - 2, m1, -1))):
            for part, (deep, mouth) in (("below", (base, low - 1)),
                                        ("above", (high + L, high + 1))):
                clusters.append({"name": f"a{a + 1}{side}-{part}", "symbol": next(letters),
                                 "fill": [f"{c},{deep}..{c},{mouth}" for c in lane_cols]})
    return {
        "name": name,
        "description": (f"generated: {shape.aisles} aisles, {shape.depth} lanes of "
                        f"{shape.lane_depth} per side, {shape.vehicles} forklifts"),
        "cell_size": shape.cell_size,
        "starts": _starts(shape),
        "bounds": {"x": [0.0, cols * shape.cell_size], "y": [0.0, rows * shape.cell_size]},
        "cluster": clusters,
        "obstacle": [{"name": "walls", "kind": "wall", "cells": walls}],
        "station": stations,
        "passage": passages,
    }


def _starts(shape: Shape) -> list[str]:
    """Parking slots in the aisles' lower rows, nearest the main passage first, aisle by
    aisle in turn, so the first vehicles out are the first dispatched."""
    m0, m1 = shape.main
    per_side = shape.slots_per_aisle // 2
    slots = []
    for k in range(per_side):
        for a in range(shape.aisles):
            low = a * (2 * shape.lane_depth + 2) + shape.lane_depth
            slots.append(f"{m0 - 2 - 2 * k},{low},E")
            slots.append(f"{m1 + 2 + 2 * k},{low},W")
    return slots[:shape.vehicles]


def _validate(shape: Shape) -> None:
    if shape.aisles < 1:
        raise UserError(f"--aisles must be at least 1, not {shape.aisles}")
    if shape.depth < MIN_DEPTH:
        raise UserError(f"--depth must be at least {MIN_DEPTH}, not {shape.depth}: with fewer "
                        f"lanes per side an aisle has no parking slot for a forklift")
    if shape.lane_depth < 1:
        raise UserError(f"--lane-depth must be at least 1, not {shape.lane_depth}")
    room = shape.slots_per_aisle * shape.aisles
    if not 1 <= shape.vehicles <= room:
        raise UserError(f"--vehicles must be between 1 and {room} for {shape.aisles} aisles of "
                        f"depth {shape.depth} (their parking slots), not {shape.vehicles}: "
                        f"give fewer --vehicles, or more --aisles or --depth")


def generate_toml(shape: Shape, name: str | None = None) -> str:
    """The layout file text, drawing included (the loader checks it on the way back in)."""
    data = generate(shape, name)
    drawing = parse_layout(tomli_w.dumps(data), "generated layout").render_drawing()
    header = {k: data[k] for k in ("name", "description", "cell_size", "starts")}
    rest = {k: v for k, v in data.items() if k not in header}
    return (tomli_w.dumps(header) + 'drawing = """\n' + drawing + '\n"""\n\n'
            + tomli_w.dumps(rest))


def generate_layout(shape: Shape, name: str | None = None) -> Layout:
    return parse_layout(generate_toml(shape, name), "generated layout")
