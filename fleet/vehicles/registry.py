"""The vehicle kinds a layout may name in `[vehicle] kind`, and the kind for a name."""

from __future__ import annotations

from collections.abc import Callable

from fleet.errors import UserError
from fleet.params import VehicleDims
from fleet.vehicles.forklift import Forklift
from fleet.vehicles.kind import VehicleKind

KINDS: dict[str, Callable[[VehicleDims, float], VehicleKind]] = {Forklift.name: Forklift}


class UnknownVehicleKind(UserError):
    """A kind no module of fleet.vehicles implements."""


def vehicle_kind(name: str, dims: VehicleDims, cell_size: float) -> VehicleKind:
    """The kind called `name`, for a body of `dims` on cells of `cell_size` metres."""
    kind = KINDS.get(name)
    if kind is None:
        raise UnknownVehicleKind(f"kind {name!r} is not one of the known vehicle kinds: "
                                 f"{', '.join(KINDS)}")
    return kind(dims, cell_size)
