"""`fleet analyze`: what a recording says about its run, and three verdicts.

Safety (fleet/analysis/safety.py, independent of the planner and the table): no two
forklifts on one cell at one instant or between two instants, no forklift outside its own
reservation, no cell held by two owners at once. Work: the mission finished, and every stack
of the layout was physically served exactly once, each cluster in its order, by forklifts
whose states are physically possible (fleet/analysis/served.py, fleet/analysis/motion.py).
Messages: every stream's sequence numbers are complete (a gap is a lost message,
fleet/analysis/streams.py), and every decision failure a dispatcher counted was announced
(fleet/analysis/failure_count.py).

A run recorded in segments (a recorder killed and restarted) has windows in which no
recorder ran: what was sent then is reported as not recorded, apart from what was lost in
transit, and what the verdicts could not check there is listed as not verified
(fleet/analysis/windows.py). The Report and its text are in fleet/analysis/report.py; each
forklift's time in fleet/analysis/time_use.py.
"""

from __future__ import annotations

import bisect
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

from fleet.analysis.battery import BatteryVerdict, Charge, battery_verdict
from fleet.analysis.failure_count import failure_counts
from fleet.analysis.lane_traffic import (
    ExecutedViolation,
    Grid,
    Meeting,
    Seen,
    cell_names,
    lane_breaches,
    meetings,
    tracks,
)
from fleet.analysis.motion import at_rest, grid_pose, impossible_states
from fleet.analysis.protocol5050 import protocol_verdict
from fleet.analysis.report import Report
from fleet.analysis.safety import (
    Body,
    Cell,
    Sample,
    double_bookings,
    on_goods,
    outside_reservation,
    overlaps,
    replay,
)
from fleet.analysis.served import (
    Announced,
    Delivery,
    NotServed,
    Standing,
    out_of_order,
    services,
)
from fleet.analysis.shelves import Announced as OrderAnnounced
from fleet.analysis.shelves import Carrying, Claim, OrdersVerdict, orders_verdict
from fleet.analysis.streams import (
    LOSS_NOTICED_WALL_S,
    Hole,
    sent_while_down,
    sequence_holes,
    stream_gaps,
)
from fleet.analysis.time_use import time_use
from fleet.analysis.windows import (
    SILENT,
    NotRecorded,
    SegmentRead,
    Unverified,
    recorder_down,
    reservations_unknown,
    silent_windows,
    stacks_not_recorded,
    states_unknown,
    unverified_windows,
)
from fleet.mission.driving import state_period
from fleet.mission.record import MissionSummary, SubtaskRecord
from fleet.mission.spec import EXTERNAL, ClockMode, MissionKind
from fleet.params import LOOKAHEAD_S, DispatchParams
from fleet.recording.format import NS
from fleet.recording.mission_record import (
    Final,
    dispatcher_restarts,
    final_record,
    summary_of,
    uncounted_tails,
)
from fleet.recording.reader import Recording, RecordingError
from fleet.wire.protocol import (
    Halt,
    MissionDone,
    MissionInfo,
    MqttTraffic,
    Resume,
    StackDone,
    StackReopened,
    VehicleState,
    WireChange,
)
from fleet.wire.topics import message_type
from fleet.world.layout import Layout

Finding = TypeVar("Finding")
# A vehicle's states further apart than this many state periods leave a hole between them:
# nothing is interpolated across it, and a stack's handling over it is not seen.
STATE_GAP_PERIODS = 1.5
DELIVERY = "deliver"  # the kind of a subtask to a stack (SubtaskEvent)
IN_PROCESS = "inprocess"  # the clock of a `fleet run --inprocess` recording (MissionInfo)


def analyze(recording: Recording) -> Report:
    info = recording.info
    if info is None:
        raise RecordingError(f"{recording.path}: no mission message from the dispatcher was "
                             f"recorded, so the run is unknown (was the recorder started "
                             f"after the mission?)")
    layout = recording.layout()
    restarts = dispatcher_restarts(recording)
    final = final_record(recording, restarts)
    record = summary_of(recording, (restarts, final))
    kind = layout.vehicle_kind
    outline = kind.outline  # numbers only: the verifier has its own geometry
    body = Body(outline.front, outline.rear, outline.width, layout.cell_size, layout.origin)
    period = state_period(info.clock, info.speed)
    states = [(r.envelope.sim_time, m) for r, m in recording.of(VehicleState)]
    usable = [(t, m) for t, m in states
              if all(math.isfinite(v) for v in (t, m.x, m.y, m.theta))]
    samples = [Sample(m.vehicle, t, m.x, m.y, m.theta) for t, m in usable]
    standing = standing_samples(recording, sorted({s.t for s in samples}))
    samples += standing
    held = replay(_unique_revisions(recording))
    done = [m for _, m in recording.of(MissionDone)]
    holes = sequence_holes(recording)
    down_halts = [m for _, m in recording.of(Halt) if not m.moving]
    # A forklift's messages sent into its cut link never arrived: on the real-time clock its
    # halt may come a little after the cut; on the fast clock the hole must span the halt
    # (a docker network disconnect may catch a clock ack in flight, between two ticks).
    late = LOSS_NOTICED_WALL_S * info.speed if info.clock == ClockMode.REALTIME else 0.0
    cut_off = [h for h in holes if not h.window and sent_while_down(h, down_halts, late)]
    lost = [h for h in holes if not h.window and h not in cut_off]
    unrecorded = [h for h in holes if h.window]
    gaps = stream_gaps(lost)
    downs = {g: recorder_down(recording, g) for g in recording.gaps}
    unverified = unverified_windows(recording, unrecorded, downs) + \
        silent_windows(states, down_halts, period) + _cut_off_windows(cut_off)
    outside, outside_unknown = _judged(
        outside_reservation(samples, held, body),
        lambda o: reservations_unknown(unverified, o.vehicle, o.t, o.t))
    bookings, bookings_unknown = _judged(
        double_bookings(held),
        lambda d: any(reservations_unknown(unverified, v, d.t0, d.t1) for v in d.vehicles))
    announced = announced_stacks(recording)
    stacks = Counter((a.cluster, a.index) for a in announced)
    goods_seen = on_goods(samples, _goods(info.kind, layout, announced), body)
    cells = {(s.cluster, s.index): s.cell for s in layout.stacks}
    clusters: dict[str, list[int]] = {}
    for s in layout.stacks:
        clusters.setdefault(s.cluster, []).append(s.index)
    expected = set() if info.kind == EXTERNAL else set(cells)  # a master's, not ours
    fill = info.kind == MissionKind.FILL.value
    params = DispatchParams()  # seed 000's Table 3: the parameters every mission runs with
    where = [Standing(m.vehicle, t, grid_pose(body, m.x, m.y, m.theta)
                      if at_rest(m, kind.is_wait) else None) for t, m in usable]
    where += [Standing(s.vehicle, s.t, grid_pose(body, s.x, s.y, s.theta)) for s in standing]
    judged = services([a for a in announced if (a.cluster, a.index) in expected], cells, where,
                      params.t_unload if fill else params.t_claim,
                      STATE_GAP_PERIODS * period, kind.handled_cell,
                      lambda v, t0, t1: states_unknown(unverified, v, t0, t1))
    served = {(j.announced.cluster, j.announced.index) for j in judged if j.served}
    finished = bool(done) and done[-1].ok
    positions = _positions(usable, standing, STATE_GAP_PERIODS * period)
    breaches, met = ([], []) if not layout.has_lanes else \
        _lane_traffic(layout, positions, STATE_GAP_PERIODS * period)
    from_record = stacks_not_recorded(done, unrecorded, expected - set(stacks), any(
        cls is StackDone for _, cls in uncounted_tails(recording, restarts, final is not None)))
    return Report(
        path=str(recording.path), complete=recording.complete, problem=recording.problem,
        recovered_span_s=recording.span_s, recovered_sim_s=recording.last_sim_time,
        mission=_mission(info),
        finished=finished,
        mission_error=done[-1].error if done else "",
        end_time_s=record.end_time_s,
        all_parked_s=record.all_parked_s,
        stacks_expected=len(expected),
        stacks_done=len(served | from_record),
        stacks_announced=len((set(stacks) & expected) | from_record),
        stacks_duplicated=sorted(f"{c}#{i}" for (c, i), n in stacks.items() if n > 1),
        stacks_lost=sorted(f"{c}#{i}" for c, i in expected - served - from_record),
        stacks_not_served=[NotServed(j.announced.stack, j.announced.vehicle, j.announced.t,
                                     j.why) for j in judged if not j.served],
        stacks_unverified=sorted(j.announced.stack for j in judged if j.unverified),
        stacks_out_of_order=out_of_order(
            clusters, (lambda i: i) if fill else (lambda i: -i),
            [Delivery(s.target, s.stack, s.t_i) for s in decision_order(recording, record, final)
             if s.kind == DELIVERY and s.stack is not None],
            [(m.cluster, m.index) for _, m in recording.of(StackReopened)]),
        impossible_states=impossible_states(usable, body, kind.max_speed_mps, kind.is_wait),
        subtasks=len(record.subtasks),
        decision_failures=record.decision_failures,
        plans_failed=sum(f.stage == "plan" for f in record.failures),
        undecided=sum(f.stage == "dispatch" for f in record.failures),
        failure_counts=failure_counts(recording, restarts, final),
        commit_conflicts=len(done[-1].rejections) if done else 0,
        vehicles=time_use(record.subtasks, [m for _, m in recording.of(Halt)],
                          [m for _, m in recording.of(Resume)], info.vehicles,
                          max(record.end_time_s, record.all_parked_s), info.kind,
                          layout.vehicle_kind),
        messages=dict(Counter(r.envelope.message.TYPE for r in recording.messages
                              if r.genuine)),
        messages_lost=sum(g.missing for g in gaps), gaps=gaps,
        messages_cut_off=sum(h.missing for h in cut_off),
        malformed=sum(r.envelope is None for r in recording.messages)
        + len(states) - len(usable),
        foreign=len(recording.foreign),
        overlaps=overlaps(samples, body, kind.max_speed_mps, STATE_GAP_PERIODS * period),
        outside_reservation=outside,
        double_bookings=bookings,
        on_goods=goods_seen,
        segments=[SegmentRead(str(s.path), s.messages, s.complete, s.problem,
                              None if s.first_log_ns is None else s.first_log_ns / NS,
                              None if s.last_log_ns is None else s.last_log_ns / NS,
                              s.duplicates) for s in recording.segments],
        recorder_gaps=list(downs.values()),
        not_recorded=[NotRecorded(h.key, h.sender, h.missing, h.first, h.window[0].start_ns / NS,
                                  h.window[-1].end_ns / NS) for h in unrecorded],
        messages_not_recorded=sum(h.missing for h in unrecorded),
        unverified=unverified,
        outside_reservation_unverified=outside_unknown,
        double_bookings_unverified=bookings_unknown,
        stacks_not_recorded=sorted(f"{c}#{i}" for c, i in from_record),
        incomplete=list(record.incomplete),
        vehicle_noun=kind.noun,
        lane_layout=layout.has_lanes,
        orders=_orders(recording, layout, positions, finished, record)
        if info.kind == MissionKind.ORDERS.value else None,
        lane_breaches=breaches,
        meetings=met,
        battery=_battery(info, layout, usable),
        protocol=protocol_verdict((m for _, m in recording.of(MqttTraffic)), kind.name)
        if info.kind == EXTERNAL or info.dispatch != "internal" else None,
    )


def _battery(info: MissionInfo, layout: Layout, states: list[tuple[float, VehicleState]]
             ) -> BatteryVerdict | None:
    """The batteries' verdict (fleet/analysis/battery.py), where the states carry a charge."""
    if not any(m.battery is not None for _, m in states):
        return None
    grid = Grid(layout.origin, layout.cell_size)
    last: dict[int, tuple[float, float]] = {}
    seen = []
    for t, m in sorted(states, key=lambda s: (s[1].vehicle, s[0])):
        if m.battery is None:
            continue
        moved = last.get(m.vehicle, (m.x, m.y)) != (m.x, m.y)
        seen.append(Charge(m.vehicle, t, m.battery, grid.cell_of(m.x, m.y), moved, m.loaded))
        last[m.vehicle] = (m.x, m.y)
    piles = {tuple(p.cell) for p in layout.piles}
    places = piles | {tuple(p.cell) for group in (layout.slots, layout.packing) for p in group}
    return battery_verdict(seen, piles, places, info.drain_per_s, info.charge_per_s,
                           info.charge_below)


@dataclass(frozen=True)
class _Position:
    """Where a vehicle was at an instant: a state of its own, or, while it was down, where
    its halt says it stood (carrying what its last state said)."""

    vehicle: int
    t: float
    x: float
    y: float
    loaded: bool
    unseen: bool  # its positions just before are not known (further than the state gap)


def _positions(states: list[tuple[float, VehicleState]], standing: list[Sample],
               max_gap: float) -> list[_Position]:
    """Every vehicle's positions, by vehicle, then time."""
    own = sorted(((m.vehicle, t, m.x, m.y, m.loaded) for t, m in states))
    loads: dict[int, tuple[list[float], list[bool]]] = {}
    for v, t, _, _, loaded in own:
        times, values = loads.setdefault(v, ([], []))
        times.append(t)
        values.append(loaded)
    def load_at(v: int, t: float) -> bool:
        times, values = loads.get(v, ([], []))
        k = bisect.bisect_right(times, t) - 1
        return values[k] if k >= 0 else False
    merged = sorted(own + [(s.vehicle, s.t, s.x, s.y, load_at(s.vehicle, s.t))
                           for s in standing])
    out: list[_Position] = []
    for v, t, x, y, loaded in merged:
        gap = not out or out[-1].vehicle != v or t - out[-1].t > max_gap
        first = not out or out[-1].vehicle != v
        out.append(_Position(v, t, x, y, loaded, gap and not first))
    return out


def _lane_traffic(layout: Layout, positions: list[_Position], max_gap: float
                  ) -> tuple[list[ExecutedViolation], list[Meeting]]:
    """Seed 002's traffic verdicts on the AGVs' executed moves (fleet/analysis/
    lane_traffic.py): moves against the lane rules, and AGVs meeting as the paper's
    collision classes forbid."""
    pieces = tracks([Seen(p.vehicle, p.t, p.x, p.y) for p in positions],
                    Grid(layout.origin, layout.cell_size), max_gap)
    move_s = layout.cell_size / layout.vehicle_kind.max_speed_mps
    return lane_breaches(layout, pieces), meetings(pieces, move_s, cell_names(layout))


def _orders(recording: Recording, layout: Layout, positions: list[_Position],
            finished: bool, record: MissionSummary) -> OrdersVerdict:
    """What became of an order mission's orders and shelves (fleet/analysis/shelves.py)."""
    grid = Grid(layout.origin, layout.cell_size)
    last: dict[int, Seen] = {}
    seen = []
    for p in positions:
        now, before = Seen(p.vehicle, p.t, p.x, p.y), last.get(p.vehicle)
        passed = grid.passed(before, now) if before is not None else []
        cell = grid.cell_of(p.x, p.y)
        through = frozenset(c for c, _, _ in passed) or frozenset([cell] if cell else [])
        standing = before is not None and (before.x, before.y) == (p.x, p.y)
        seen.append(Carrying(p.vehicle, p.t, cell, through, p.loaded, standing, p.unseen))
        last[p.vehicle] = now
    claims = [Claim(s.vehicle, s.kind, s.target, s.t_end, s.t_done) for s in record.subtasks]
    # Announced as a stack is (dispatch/stack: the shelf and the order), less those a cut
    # return reopened (dispatch/reopen): the order is announced again when it is put back.
    announced = [OrderAnnounced(a.cluster, a.index, a.vehicle, a.t)
                 for a in announced_stacks(recording)]
    return orders_verdict(layout, list(recording.info.released), seen, announced, finished,
                          claims)


def _mission(info: MissionInfo) -> dict:
    """Which run it was, as the recording's mission message says."""
    out = {"layout": info.layout, "kind": info.kind, "strategy": info.strategy,
           "vehicles": info.vehicles, "seed": info.seed, "clock": info.clock,
           "speed": info.speed}
    if info.kind == MissionKind.ORDERS.value:
        out.update(orders=info.orders, order_area=info.order_area,
                   charge_below=info.charge_below)
    if info.lookahead != LOOKAHEAD_S:  # a JSON number, or null: none
        out["lookahead"] = info.lookahead
    return out


def _cut_off_windows(cut_off: list[Hole]) -> list[Unverified]:
    """The states a forklift sent while it was cut off never arrived: it is in no check
    between the instants around them."""
    return [Unverified("states", h.right.envelope.message.vehicle,
                       h.left.envelope.sim_time if h.left else 0.0, h.right.envelope.sim_time,
                       f"{SILENT} ({h.missing} states sent while cut off)")
            for h in cut_off if message_type(h.key) is VehicleState]


def _judged(findings: list[Finding], unknown: Callable[[Finding], bool]
            ) -> tuple[list[Finding], list[Finding]]:
    """The findings judged, and those set aside: inside a window whose reservations are not
    known (each list in the findings' order)."""
    flags = [unknown(f) for f in findings]
    return ([f for f, set_aside in zip(findings, flags, strict=True) if not set_aside],
            [f for f, set_aside in zip(findings, flags, strict=True) if set_aside])


def standing_samples(recording: Recording, instants: list[float]) -> list[Sample]:
    """Where a forklift that was down stood at each recorded instant until it moved again:
    it says nothing then, the dispatcher's halt says where (so the check covers it too)."""
    resumes = sorted((m.vehicle, m.t) for _, m in recording.of(Resume))
    # A forklift heard again was resumed, even if the resume was sent while no recorder ran.
    heard = sorted((m.vehicle, r.envelope.sim_time) for r, m in recording.of(VehicleState))
    out = []
    for _, halt in recording.of(Halt):
        if halt.moving:
            continue
        until = min([t for v, t in resumes if v == halt.vehicle and t >= halt.t]
                    + [t for v, t in heard if v == halt.vehicle and t > halt.t],
                    default=math.inf)
        first = bisect.bisect_left(instants, halt.t)
        last = bisect.bisect_left(instants, until)
        out += [Sample(halt.vehicle, t, halt.x, halt.y, halt.theta)
                for t in instants[first:last]]
    return out


def decision_order(recording: Recording, record: MissionSummary, final: Final | None = None
                   ) -> list[SubtaskRecord]:
    """The subtasks whose order of decision is known, in that order: those of the last
    dispatcher's final record (it lists them as decided) and, of a run of processes, those
    recorded as published. An in-process recording holds the events in sim-time order (a
    subtask at its start, which may come after a later decision's): there, only the final
    record's."""
    final = final_record(recording, dispatcher_restarts(recording)) if final is None else final
    own = set(final.subtasks) if final is not None else set()
    processes = recording.info.clock != IN_PROCESS  # read once: it looks through everything
    return [s for s in record.subtasks if processes or s in own]


def _goods(kind: str, layout: Layout, announced: list[Announced]
           ) -> dict[Cell, list[tuple[float, float]]]:
    """When goods stand on each stack, by the mission's own account: a fill's from the
    instant a stack is announced filled on, an empty's from the start until it is announced
    emptied (never: all along); none for any other mission (a master's goods are the store's,
    which the reservation check covers)."""
    first: dict[tuple[str, int], float] = {}
    for a in announced:
        first.setdefault((a.cluster, a.index), a.t)
    if kind == MissionKind.FILL.value:
        return {s.cell: [(first[s.cluster, s.index], math.inf)] for s in layout.stacks
                if (s.cluster, s.index) in first}
    if kind == MissionKind.EMPTY.value:
        return {s.cell: [(0.0, first.get((s.cluster, s.index), math.inf))]
                for s in layout.stacks}
    return {}


def announced_stacks(recording: Recording) -> list[Announced]:
    """The stacks the dispatcher announced done, without those it reopened: a reopening
    (a forklift cut off before it arrived) takes back that forklift's last announcement of
    the stack before it whose handling was to end after the reopening. A delivery decided
    again after the reopening is announced after it, and stays."""
    left: list[Announced] = []
    for r in recording.messages:
        if not r.genuine:
            continue
        m = r.envelope.message
        if isinstance(m, StackDone):
            left.append(Announced(m.cluster, m.index, m.vehicle, m.t))
        elif isinstance(m, StackReopened):
            taken = [a for a in left if (a.cluster, a.index, a.vehicle) ==
                     (m.cluster, m.index, m.vehicle) and a.t > m.t]
            if taken:
                left.remove(taken[-1])
    return left


def _unique_revisions(recording: Recording) -> list[tuple]:
    """The table's changes in revision order, each once (a retried publish may repeat)."""
    by_revision: dict[int, WireChange] = {}
    for _, m in recording.of(WireChange):
        by_revision.setdefault(m.revision, m)
    return [(m.op, m.vehicle, m.intervals, m.release_from, m.release_cells)
            for _, m in sorted(by_revision.items())]
