"""Where the shelves of a lane layout are, followed message by message as a run goes (the
live and recorded Foxglove scene, fleet/views/scene.py): the plots read it from the whole
record instead (fleet/views/order_timeline.py), and both follow the same rule.

A shelf leaves its slot on the AGV under it when that AGV's state turns `loaded` (it sets off
for a packing station) and is put down in the slot its stow trip ends at once the AGV's state
reaches the trip's arrival (dispatch/subtask, later if dispatch/amended postponed the leg).
An AGV keeps saying `loaded` until its next trip, so only a change to loaded lifts a shelf.
Pure: messages in, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from fleet.planning.geometry import Cell
from fleet.planning.trajectory import Pose
from fleet.wire.protocol import LegAmended, SubtaskEvent, VehicleState
from fleet.world.layout import Layout

STOW = "stow"


@dataclass(frozen=True)
class _Stow:
    t_i: float  # the trip's decision time, which names it to an amendment
    slot: Cell
    t_end: float  # the arrival: the shelf is down from here


class ShelfTracker:
    def __init__(self, layout: Layout) -> None:
        self.layout = layout
        self.slots = {s.name: s.cell for s in layout.slots}
        self.slot_cells = frozenset(self.slots.values())
        self.in_slot: dict[Cell, str] = {cell: name for name, cell in self.slots.items()}
        self.carried: dict[int, str] = {}  # AGV -> the shelf on it
        self.stows: dict[int, _Stow] = {}  # AGV -> its stow trip under way
        self.loaded: dict[int, bool] = {}  # AGV -> its last state's flag

    def on_trip(self, message: SubtaskEvent | LegAmended) -> None:
        """A stow trip decided, or a leg postponed: when the AGV will put its shelf down."""
        v = message.vehicle
        if isinstance(message, SubtaskEvent):
            if message.kind == STOW and message.target in self.slots:
                self.stows[v] = _Stow(message.t_i, self.slots[message.target], message.t_end)
            else:
                self.stows.pop(v, None)
        elif v in self.stows and self.stows[v].t_i == message.t_i:
            stow = self.stows[v]
            self.stows[v] = _Stow(stow.t_i, stow.slot, message.t_end)

    def on_state(self, state: VehicleState, t: float) -> bool:
        """An AGV's state at sim time t; whether a shelf moved between slot and AGV."""
        v = state.vehicle
        was_loaded, self.loaded[v] = self.loaded.get(v, False), state.loaded
        if v in self.carried:
            stow = self.stows.get(v)
            if stow is not None and t >= stow.t_end:
                del self.stows[v]
                return self._put(v, stow.slot)
            if not state.loaded:  # its stow was not heard: down where it stands, if a slot
                return self._put(v, self._cell(state))
            return False
        if state.loaded and not was_loaded:
            shelf = self.in_slot.pop(self._cell(state), None)
            if shelf is not None:
                self.carried[v] = shelf
                return True
        return False

    def _put(self, vehicle: int, cell: Cell) -> bool:
        """The AGV's shelf down in `cell`, if that is a vacant slot (else it stays on)."""
        if cell not in self.slot_cells or cell in self.in_slot:
            return False
        self.in_slot[cell] = self.carried.pop(vehicle)
        return True

    def _cell(self, state: VehicleState) -> Cell:
        """The cell the AGV stands on, or set off from (a state under way names the step's
        start pose); from its position if the pose is not one."""
        try:
            return Pose.parse(state.pose).cell
        except ValueError:
            ox, oy = self.layout.origin
            size = self.layout.cell_size
            if not (math.isfinite(state.x) and math.isfinite(state.y)):
                return (-1, -1)
            return (round((state.x - ox) / size), round((state.y - oy) / size))
