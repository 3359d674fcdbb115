"""The work of a mission, by its kind: seed 000's stacks (fleet/mission/work.py) or seed
002's orders (fleet/mission/order_work.py)."""

from __future__ import annotations

from fleet.dispatching.decision import Strategy
from fleet.errors import UserError
from fleet.mission.order_log import WorkLog
from fleet.mission.order_work import OrderWork
from fleet.mission.spec import Mission, MissionKind
from fleet.mission.work import MissionWork, stack_work
from fleet.params import DispatchParams
from fleet.planning.reservations import ReservationView
from fleet.vehicles.kind import Planners
from fleet.world.layout import Layout


def mission_work(mission: Mission, layout: Layout, params: DispatchParams,
                 store: ReservationView, planners: Planners, vehicles: int,
                 log: WorkLog | None = None) -> MissionWork:
    """The work of the mission on the layout, or a UserError saying why the layout cannot
    host it (stack missions need stacks, order missions slots, packing stations and piles),
    and which strategy each kind takes. `log`: where an order mission journals what it is
    fed (a stack mission's work is read back from the store's goods instead)."""
    nearest = mission.strategy is Strategy.NEAREST
    if mission.kind is MissionKind.ORDERS:
        if not nearest:
            raise UserError(f"order missions are dispatched by the order book (strategy "
                            f"nearest), not {mission.strategy.value}")
        work = OrderWork(layout, mission, vehicles)
        work.log = log
        return work
    if not layout.stacks:
        raise UserError(f"layout {layout.name} has no stacks for a {mission.kind.value} "
                        f"mission: it runs order missions (fleet run --orders N)")
    if nearest:
        raise UserError(f"strategy nearest dispatches order missions (--orders N), not "
                        f"{mission.kind.value} missions")
    return stack_work(mission.kind, layout, params, store, planners)
