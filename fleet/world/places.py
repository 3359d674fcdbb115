"""Where a plan starts or ends, as the user writes it: a pose ('3,5,N'), a station ('p1', its
docking pose) or a stack ('s1#5', the poses with forks pointing at stack 5 of s1)."""

from __future__ import annotations

from collections.abc import Iterable

from fleet.errors import UserError
from fleet.planning.geometry import Cell
from fleet.planning.trajectory import Pose
from fleet.world.layout import Layout


def filled_counts(layout: Layout, counts: dict[str, int]) -> set[Cell]:
    """Cells of the first `n` stacks of each named cluster."""
    cells = set()
    for name, n in counts.items():
        cluster = layout.cluster(name)
        stacks = [s for s in layout.stacks if s.cluster == cluster.name]
        if not 0 <= n <= len(stacks):
            raise UserError(f"filled: cluster {name} has {len(stacks)} stacks, not {n}")
        cells |= {s.cell for s in stacks if s.index <= n}
    return cells


def resolve(layout: Layout, text: str, filled: Iterable[Cell] = ()) -> list[Pose]:
    """Poses meant by a place; stacks use the given fill state (the stack itself is empty)."""
    text = text.strip()
    if "," in text:
        try:
            return [Pose.parse(text)]
        except ValueError as exc:
            raise UserError(str(exc)) from None
    for station in layout.stations:
        if station.name == text:
            return [station.dock]
    if "#" in text:
        name, _, number = text.partition("#")
        cluster = layout.cluster(name)
        stack = next((s for s in layout.stacks
                      if s.cluster == cluster.name and str(s.index) == number), None)
        if stack is None:
            raise UserError(f"place {text!r}: cluster {name} has no stack {number!r}")
        filled = set(filled) - {stack.cell}
        poses = layout.unload_poses(stack.cell, filled)
        if not poses:
            raise UserError(f"place {text!r}: no free pose points its forks at stack "
                            f"{stack.cell} with this fill state")
        return poses
    names = ", ".join(s.name for s in layout.stations)
    raise UserError(f"place {text!r} is not a pose 'col,row,H', a station ({names}) or a "
                    f"stack like 's1#5'")


def col_row(text: str) -> Cell:
    """A cell as the user writes it, 'col,row' (a UserError naming the text otherwise)."""
    try:
        col, row = (int(part) for part in text.split(","))
    except ValueError:
        raise UserError(f"place {text!r} must be 'col,row' with two whole numbers") from None
    return col, row
