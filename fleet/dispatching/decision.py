"""What the engine and a dispatch policy say to each other, whichever the policy: the strategy
a mission names, the vehicles as a policy sees them, the targets it may send one to, and the
decision it answers with (fleet/dispatching/policy.py has the policy interface)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

from fleet.planning.geometry import Cell
from fleet.planning.trajectory import Pose


class Strategy(Enum):
    """What a mission names to choose its dispatch policy (fleet/dispatching/policy.py maps
    each to one). Today the five dispatching strategies of seed 000, Section 6.2, all
    Algorithm 1."""

    GREEDY = "greedy"  # argmax I_d
    TRAFFIC = "traffic"  # traffic-jam removal: argmax J_d,0
    BALANCE = "balance"  # argmax G_d
    COMPREHENSIVE = "comprehensive"  # argmax S_d,0
    ANN = "ann"  # argmax S_d (Equation 9): comprehensive corrected by the MLP
    NEAREST = "nearest"  # seed 002: the order book's nearest idle AGV, station, slot, pile


# Seed 000's five, all Algorithm 1 (stack missions); NEAREST runs order missions only.
STACK_STRATEGIES = tuple(s for s in Strategy if s is not Strategy.NEAREST)


class TaskKind(Enum):
    DELIVER = "deliver"  # to a shelf cluster (put goods in fill, take goods in empty)
    RETURN = "return"  # to a picking station
    ASIDE = "aside"  # out of another vehicle's way (a deadlock broken; no policy decides it)
    # Seed 002's order missions (fleet/mission/order_work.py)
    FETCH = "fetch"  # to the order's shelf, lifted from under
    PACK = "pack"  # with the shelf to a packing station, standing its dwell there
    STOW = "stow"  # with the shelf to a vacant slot, put down
    CHARGE = "charge"  # to a charging pile


@dataclass(frozen=True)
class VehicleView:
    vehicle: int
    pose: Pose
    t_free: float  # end of its last trajectory plus handling time
    next_task: TaskKind
    linked_cluster: str | None  # cluster of its current or last subtask (MLP input, Eq. 7)
    linked_kind: TaskKind | None


@dataclass(frozen=True)
class Target:
    """A candidate goal: a cluster's next stack, or a station."""

    name: str  # cluster or station name
    goals: tuple[Pose, ...]  # poses with the forks at the stack / station
    stack_cell: Cell | None = None
    stack_index: int | None = None
    remaining: int = 0  # G_d: stacks of the cluster still to do
    far: bool = False  # s1/s2-like clusters far from the stations (C5, C7)
    kind: TaskKind | None = None  # the subtask it is for, where the work decides it (orders)


@dataclass(frozen=True)
class Decision:
    """Which vehicle goes where, from which instant."""

    vehicle: int
    t_i: float
    kind: TaskKind
    target: Target
    postponed: bool  # decided for a later instant than the vehicle was free at


@dataclass(frozen=True)
class FailedChoice:
    """A vehicle chosen for the instant t_i and given no target it accepts: one decision
    failure (the seed's count), which the engine announces as it is."""

    vehicle: int
    t_i: float
    why: str  # which targets were refused, briefly


@dataclass
class DispatchOutcome:
    decision: Decision | None
    # Each time n_current or t_i changed without a decision (the seed's count), in order; at
    # least one when there is no decision.
    failures: list[FailedChoice] = field(default_factory=list)
    postponements: dict[int, float] = field(default_factory=dict)  # vehicle -> new t_free


# Where a vehicle may go next, as the mission's work offers it (what a policy asks).
TargetsFor = Callable[[VehicleView], list[Target]]
