"""Parameters of seed 000, Table 3, as frozen dataclasses (the values are used as given)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class VehicleDims:
    """Forklift body (Table 3). The fork side is the rear; P is the rear axle midpoint."""

    front_overhang: float = 0.3  # n
    rear_overhang: float = 1.0  # m
    wheelbase: float = 1.5  # l
    width: float = 1.0  # 2b

    @property
    def front(self) -> float:
        """Distance from P to the front (non-fork) end."""
        return self.wheelbase + self.front_overhang

    @property
    def rear(self) -> float:
        """Distance from P to the fork tips."""
        return self.rear_overhang


@dataclass(frozen=True)
class ManeuverTimes:
    """T1..T12 of Table 1 (seconds)."""

    T1: float = 4.0  # zero -> straight -> zero
    T2: float = 2.0  # zero <-> mid, straight
    T3: float = 1.25  # mid -> mid, straight
    T4: float = 0.75  # mid <-> high, straight
    T5: float = 0.5  # high -> high, straight
    T6: float = 8.0  # zero -> turn -> zero
    T7: float = 5.0  # zero <-> mid, turn
    T8: float = 3.0  # mid -> mid, turn
    T9: float = 12.0  # zero -> lane change -> zero
    T10: float = 8.0  # zero <-> mid, lane change
    T11: float = 5.0  # mid -> mid, lane change
    T12: float = 1.0  # stop


@dataclass(frozen=True)
class SearchParams:
    """Improved hybrid A* settings (Table 3)."""

    iter_search: int = 5000
    C11: float = 3.0
    p_turn: float = 4.0
    p_lane: float = 6.0
    p_inv: float = 6.0
    # Not from the seed: after this many expansions the search checks once, in a
    # safe-interval relaxation, whether other vehicles' reservations close every way to the
    # goal in time, and fails at once if they do (see planner; about 8 ms on paper)
    relaxation_check_at: int = 300


# Not from the seed: Algorithm 1 decides for a forklift at most this long after the earliest
# instant one with work is free (4 Δt_i, about one leg on `paper`). Without a bound the one
# whose plans succeed while the others' fail runs thousands of seconds ahead of them, and its
# commitments wall in the way they plan through (docs/dispatching.md). A mission may set
# another (`fleet run --lookahead`); its record names it then.
LOOKAHEAD_S = 40.0


@dataclass(frozen=True)
class DispatchParams:
    """Dispatching constants (Table 3)."""

    C1: float = 6.0
    C2: float = 1.5
    C3: float = 80.0
    C4: float = -40.0
    C5: float = 6.0
    C6: float = 0.5
    C7: float = -4.0
    C8: float = 2.0
    C9: float = 0.5
    C10: float = 0.5
    iter_pre: int = 500
    iter_dispatch: int = 10
    dt_postpone: float = 10.0  # Δt_i
    # Table 3's "time period to evaluate H"; cover_time's window is dt_entry, as long.
    dt_cover: float = 20.0
    dt_entry: float = 20.0
    t_claim: float = 5.0
    t_unload: float = 5.0
    # Not from the seed: the weight of H in J_d,0 (the seed's is 1; 0 switches the term off in
    # the ablation of `fleet bench strategies`, as C1 = 0 does G_d and C2 = 0 does I_d).
    cover_weight: float = 1.0
