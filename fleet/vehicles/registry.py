"""The vehicle kinds a layout may name in `[vehicle] kind`, and the kind for a name."""

from __future__ import annotations

from collections.abc import Callable

from fleet.errors import UserError
from fleet.params import VehicleDims
from fleet.vehicles.agv import Agv
from fleet.vehicles.forklift import Forklift
from fleet.vehicles.kind import VehicleKind

KINDS: dict[str, Callable[[VehicleDims, float], VehicleKind]] = {Forklift.name: Forklift,
                                                                Agv.name: Agv}

# Kinds a layout may already name though no module implements them yet: such a layout loads,
# shows and checks, and whatever would drive one refuses in one line (KindNotBuilt).
PLANNED: dict[str, str] = {"lifting-agv": "seed 004's lifting AGV that drives under shelves; "
                                       "it drives on seed-004 floors only, generated from a "
                                       "[floor004] table (docs/agv-004.md), not on a floor "
                                       "of stacks or lanes"}


class UnknownVehicleKind(UserError):
    """A kind no module of fleet.vehicles implements."""


class KindNotBuilt(UserError):
    """A planned kind (PLANNED): known by name, not implemented yet."""


def known(name: str) -> bool:
    return name in KINDS or name in PLANNED


def is_built(name: str) -> bool:
    return name in KINDS


def not_built(name: str) -> str:
    return (f"the {name} vehicle kind is not built yet ({PLANNED[name]}): its layouts load, "
            f"show and check")


def vehicle_kind(name: str, dims: VehicleDims, cell_size: float) -> VehicleKind:
    """The kind called `name`, for a body of `dims` on cells of `cell_size` metres."""
    kind = KINDS.get(name)
    if kind is None:
        if name in PLANNED:
            raise KindNotBuilt(not_built(name))
        raise UnknownVehicleKind(f"kind {name!r} is not one of the known vehicle kinds: "
                                 f"{', '.join([*KINDS, *PLANNED])}")
    return kind(dims, cell_size)


# Kinds that drive a lane layout's directed lanes (seed 002); the forklift plans on open floor.
DRIVES_LANES = frozenset({"agv"})
