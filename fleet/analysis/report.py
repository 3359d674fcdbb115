"""The analysis of a recording as a Report: its fields, the verdicts, and the text of
`fleet analyze` and of `fleet run`'s summary."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from fleet.analysis.battery import BatteryVerdict
from fleet.analysis.failure_count import FailureCount
from fleet.analysis.lane_traffic import ExecutedViolation, Meeting
from fleet.analysis.motion import Impossible
from fleet.analysis.protocol5050 import ProtocolVerdict
from fleet.analysis.served import NotServed, OutOfOrder
from fleet.analysis.shelves import OrdersVerdict
from fleet.analysis.streams import Gap
from fleet.analysis.time_use import VehicleStats
from fleet.analysis.windows import SILENT, NotRecorded, RecorderDown, SegmentRead, Unverified
from fleet.mission.spec import EXTERNAL
from fleet.wire.protocol import GOODS


@dataclass
class Report:
    """What a recording says about its run, and the verdicts (its fields, flat, are the JSON
    of `fleet analyze --json`, docs/metrics.md)."""

    path: str
    complete: bool  # the file ended with its footer
    problem: str  # why reading stopped early
    recovered_span_s: float  # receive-time span of what could be read
    recovered_sim_s: float  # the latest sim time in it
    mission: dict[str, Any]
    finished: bool  # the dispatcher's result is in the recording
    mission_error: str
    end_time_s: float
    all_parked_s: float  # the last trajectory's end
    stacks_expected: int
    stacks_done: int  # physically served (fleet.analysis.served), or known done from the record
    stacks_announced: int  # announced done by the dispatcher (at commit), not taken back
    stacks_duplicated: list[str]
    stacks_lost: list[str]  # not done
    subtasks: int
    # The dispatcher's count (docs/metrics.md): a chosen forklift given no goal it accepts, or
    # a decided trajectory that could not be planned; each announced as a dispatch.failure.
    decision_failures: int  # those announced
    plans_failed: int
    undecided: int  # dispatches without a decision (each iter_dispatch choices without a goal)
    # Each dispatcher's count against its announcements: they must agree (messages verdict).
    failure_counts: list[FailureCount]
    commit_conflicts: int
    vehicles: list[VehicleStats]  # fleet.analysis.time_use: where each forklift's time went
    messages: dict[str, int]  # per message type
    messages_lost: int
    gaps: list[Gap]
    messages_cut_off: int  # sent by a forklift around the time it was down: never arrived
    malformed: int  # payloads that were no valid message (recorded as they came)
    foreign: int  # valid messages on a key not theirs, or from a sender not the key's
    overlaps: list = field(default_factory=list)
    outside_reservation: list = field(default_factory=list)
    double_bookings: list = field(default_factory=list)
    on_goods: list = field(default_factory=list)  # a body on a stack holding goods
    # The work as the forklifts' states show it: announced stacks they did not serve, stacks
    # taken on the dispatcher's word (their forklift's states then not recorded), stacks
    # served out of their cluster's order, and states no vehicle of the kind can be in.
    stacks_not_served: list[NotServed] = field(default_factory=list)
    stacks_unverified: list[str] = field(default_factory=list)
    stacks_out_of_order: list[OutOfOrder] = field(default_factory=list)
    impossible_states: list[Impossible] = field(default_factory=list)
    # A run recorded in segments (docs/recording.md): the files, the windows without a
    # recorder, what was sent then, and what the verdicts could not check because of it.
    segments: list[SegmentRead] = field(default_factory=list)
    recorder_gaps: list[RecorderDown] = field(default_factory=list)
    not_recorded: list[NotRecorded] = field(default_factory=list)
    messages_not_recorded: int = 0
    unverified: list[Unverified] = field(default_factory=list)
    # Findings set aside, not failed: inside a window whose reservations are not known.
    outside_reservation_unverified: list = field(default_factory=list)
    double_bookings_unverified: list = field(default_factory=list)
    # Stacks counted done from the dispatcher's final record: their dispatch/stack message
    # was sent while no recorder was running.
    stacks_not_recorded: list[str] = field(default_factory=list)
    # Why the numbers (subtasks, decision failures, end time, each forklift's time) leave
    # something out: what a dispatcher announced that neither a recorder nor its final record
    # kept (fleet.recording.mission_record). Empty: they are whole.
    incomplete: list[str] = field(default_factory=list)
    vehicle_noun: str = "forklift"  # what the layout's vehicle kind is called
    lane_layout: bool = False  # seed 002's lanes: the lane verdicts apply
    # An order mission's work (seed 002), in place of the stacks: fleet/analysis/shelves.py.
    orders: OrdersVerdict | None = None
    # A lane layout's traffic (seed 002), from the executed moves: fleet/analysis/
    # lane_traffic.py. Moves against the lane rules, and AGVs at one node, swapping or
    # crossing diagonals.
    lane_breaches: list[ExecutedViolation] = field(default_factory=list)
    meetings: list[Meeting] = field(default_factory=list)
    # Seed 002's batteries, from the states' charge (fleet/analysis/battery.py); None: the
    # states carry none.
    battery: BatteryVerdict | None = None
    protocol: ProtocolVerdict | None = None  # a run through the VDA 5050 gateway: its traffic

    @property
    def safe(self) -> bool:
        return not (self.overlaps or self.outside_reservation or self.double_bookings
                    or self.on_goods or self.meetings)

    @property
    def lanes_kept(self) -> bool:
        return not self.lane_breaches

    @property
    def work_done(self) -> bool:
        if self.orders is not None:
            return self.finished and self.orders.passed and not self.impossible_states
        return (self.finished and self.stacks_done == self.stacks_expected
                and not (self.stacks_duplicated or self.stacks_lost or self.stacks_not_served
                         or self.stacks_out_of_order or self.impossible_states))

    @property
    def failures_unannounced(self) -> list[FailureCount]:
        """The dispatchers whose count of decision failures is not the number announced."""
        return [c for c in self.failure_counts if not c.agrees]

    @property
    def messages_whole(self) -> bool:
        return self.messages_lost == 0 and not self.failures_unannounced

    @property
    def batteries_kept(self) -> bool:
        return self.battery is None or self.battery.passed

    @property
    def passed(self) -> bool:
        return (self.safe and self.lanes_kept and self.work_done and self.batteries_kept
                and self.messages_whole and (self.protocol is None or self.protocol.passed))

    def to_json(self) -> dict[str, Any]:
        data = asdict(self)
        for name in ("overlaps", "outside_reservation", "double_bookings", "on_goods",
                     "outside_reservation_unverified", "double_bookings_unverified",
                     "stacks_not_served", "stacks_out_of_order", "impossible_states",
                     "lane_breaches", "meetings"):
            data[name] = len(getattr(self, name))
            data[f"{name}_first"] = [_jsonable(asdict(x)) for x in getattr(self, name)[:20]]
        data["overlaps_between"] = sum(o.between for o in self.overlaps)
        if self.orders is not None:
            faults = self.orders.shelf_faults
            data["orders"]["shelf_faults"] = len(faults)
            data["orders"]["shelf_faults_first"] = [_jsonable(asdict(f)) for f in faults[:20]]
        if self.battery is not None:
            faults = self.battery.faults
            data["battery"]["faults"] = len(faults)
            data["battery"]["faults_first"] = [_jsonable(asdict(f)) for f in faults[:20]]
        if self.protocol is not None:
            data["protocol"] = {**_jsonable(asdict(self.protocol)),
                                "passed": self.protocol.passed}
        data.update(safe=self.safe, lanes_kept=self.lanes_kept, work_done=self.work_done,
                    batteries_kept=self.batteries_kept,
                    messages_whole=self.messages_whole, passed=self.passed)
        return _jsonable(data)

    def verdict_lines(self) -> list[str]:
        def mark(ok: bool) -> str:
            return "pass" if ok else "FAIL"

        unchecked = ""
        if self.unverified:
            set_aside = (len(self.outside_reservation_unverified)
                         + len(self.double_bookings_unverified))
            silent = sum(u.why.startswith(SILENT) for u in self.unverified)
            why = ", ".join(part for part in (
                f"{len(self.unverified) - silent} with no recorder running"
                if len(self.unverified) > silent else "",
                f"{silent} of a forklift {SILENT}" if silent else "") if part)
            unchecked = (f"; {len(self.unverified)} windows not verified ({why})"
                         + (f", {set_aside} findings in them not judged" if set_aside else ""))
        kinds = Counter(m.kind for m in self.meetings)
        lanes = [] if not self.lane_layout else [
            f"lanes              {mark(self.lanes_kept)}: {len(self.lane_breaches)} moves "
            f"against the lane rules"]
        return [
            f"safety             {mark(self.safe)}: {len(self.overlaps)} overlaps, "
            f"{len(self.outside_reservation)} moments outside a reservation, "
            f"{len(self.double_bookings)} double-booked cells"
            + ("" if self.lane_layout else f", {len(self.on_goods)} moments on goods")
            + (f", {kinds['node']} AGVs met at a node, {kinds['swap']} swaps, "
               f"{kinds['diagonal']} crossed diagonals" if self.lane_layout else "")
            + unchecked,
            *lanes,
            *([] if self.battery is None else [
                f"battery            {mark(self.batteries_kept)}: lowest "
                f"{self.battery.lowest:.1f} %, {self.battery.charged} charges, "
                f"{len(self.battery.faults)} faults (bounds, rates, the "
                f"{self.mission.get('charge_below', 20):g} % rule)"]),
            self._orders_line(mark) if self.orders is not None else
            f"work               {mark(self.work_done)}: no mission of ours, a VDA 5050 "
            f"master gave the orders; {len(self.impossible_states)} impossible states"
            + ("" if self.finished else "; the session did not end cleanly")
            if self.mission.get("kind") == EXTERNAL else
            f"work               {mark(self.work_done)}: {self.stacks_done} of "
            f"{self.stacks_expected} stacks served"
            + (f" ({self.stacks_announced} announced)"
               if self.stacks_announced != self.stacks_done else "")
            + f", {len(self.stacks_duplicated)} twice, {len(self.stacks_lost)} lost"
            + (f" ({len(self.stacks_not_recorded)} known done from the dispatcher's record "
               f"only)" if self.stacks_not_recorded else "")
            + (f", {len(self.stacks_not_served)} announced but not served"
               if self.stacks_not_served else "")
            + f", {len(self.stacks_out_of_order)} out of order, "
            f"{len(self.impossible_states)} impossible states"
            + (f"; {len(self.stacks_unverified)} served on the dispatcher's word (their "
               f"forklift's states not recorded)" if self.stacks_unverified else "")
            + ("" if self.finished else "; the mission did not finish"
               + (f" ({self.mission_error})" if self.mission_error
                  else " (no result recorded)")),
            *([] if self.protocol is None else [
                self.protocol.line(mark(self.protocol.passed))]),
            f"messages           {mark(self.messages_whole)}: "
            f"{sum(self.messages.values())} recorded, {self.messages_lost} lost, "
            + (f"{self.messages_cut_off} sent while cut off, " if self.messages_cut_off
               else "")
            + (f"{self.messages_not_recorded} not recorded (no recorder running), "
               if self.recorder_gaps else "")
            + f"{self.malformed} malformed, {self.foreign} foreign"
            + "".join(f"; {c.line()}" for c in self.failures_unannounced),
        ]

    def _orders_line(self, mark: Callable[[bool], str]) -> str:
        o = self.orders
        assert o is not None
        return (f"work               {mark(self.work_done)}: {o.done} of {o.expected} orders "
                f"done (packed, shelf put back)"
                + (f" ({o.announced} announced)" if o.announced != o.done else "")
                + f", {len(o.duplicated)} twice, {len(o.lost)} lost"
                + (f", {len(o.not_served)} announced but not done" if o.not_served else "")
                + (f", {len(o.misnamed)} misnamed" if o.misnamed else "")
                + f", {len(o.shelf_faults)} shelf faults, "
                f"{len(self.impossible_states)} impossible states"
                + (f"; {len(o.unverified)} done on the dispatcher's word (their AGV's states "
                   f"not recorded)" if o.unverified else "")
                + (f"; {len(o.unseen)} not verified (their shelves moved while neither a "
                   f"recorder nor the dispatcher's word was there)" if o.unseen else "")
                + ("" if self.finished else "; the mission did not finish"
                   + (f" ({self.mission_error})" if self.mission_error
                      else " (no result recorded)")))

    def numbers_lines(self) -> list[str]:
        """End time, subtasks, decision failures and waiting: as `fleet run` and `fleet analyze`
        print them (docs/metrics.md)."""
        no_goal = self.decision_failures - self.plans_failed
        stopped = sum(v.stopped_s for v in self.vehicles)
        postponed = sum(v.postponed_s for v in self.vehicles)
        o = self.orders
        work = (f"  stacks             {self.stacks_done} of {self.stacks_expected}"
                + (f" ({self.stacks_announced} announced)"
                   if self.stacks_announced != self.stacks_done else "")) if o is None else \
            (f"  orders             {o.done} of {o.expected}"
             + (f" ({o.announced} announced)" if o.announced != o.done else ""))
        return [
            f"  end time           {self.end_time_s:.2f} s (last "
            f"{'stack' if o is None else 'order'} done); every {self.vehicle_noun} parked at "
            f"{self.all_parked_s:.2f} s",
            work,
            f"  subtasks           {self.subtasks}",
            f"  decision failures  {self.decision_failures}: {self.plans_failed} plans failed, "
            f"{no_goal} choices without a goal"
            + (f" ({self.undecided} dispatches without a decision)" if self.undecided else ""),
            f"  waiting            {stopped + postponed:.2f} s in all: {stopped:.2f} s stopped, "
            f"{postponed:.2f} s postponed",
            *self.incomplete_lines(),
        ]

    def incomplete_lines(self) -> list[str]:
        """That the numbers are not whole, and why (nothing when they are)."""
        if not self.incomplete:
            return []
        return ["  incomplete         these figures miss what no recorder or record kept:",
                *(f"                     {why}" for why in self.incomplete)]

    def vehicle_lines(self, distance: bool = False) -> list[str]:
        """Each forklift's time (fleet.analysis.time_use), with its distance if asked; a down
        column only when some forklift was down."""
        down = any(v.down_s for v in self.vehicles)
        head = f"  {self.vehicle_noun:>8}" + (" distance m" if distance else "") + \
            " busy s stopped s postponed s handling s" + (" down s" if down else "") + \
            " idle s busy %"
        out = [head]
        for v in self.vehicles:
            out.append(f"  {v.vehicle:>8}" + (f" {v.distance_m:10.1f}" if distance else "")
                       + f" {v.busy_s:6.1f} {v.stopped_s:9.1f} {v.postponed_s:11.1f}"
                       f" {v.handling_s:10.1f}" + (f" {v.down_s:6.1f}" if down else "")
                       + f" {v.idle_s:6.1f} {v.utilisation:6.0%}")
        return out

    def lines(self) -> list[str]:
        m = self.mission
        out = [f"recording {self.path}"]
        if not self.complete:
            out.append(f"  truncated: {self.problem}; recovered {self.recovered_span_s:.1f} s "
                       f"of messages, up to sim time {self.recovered_sim_s:.1f} s")
        if len(self.segments) > 1:
            out.append(f"  segments           {len(self.segments)}: " + ", ".join(
                f"{Path(s.path).name} ({s.messages} messages"
                + ("" if s.complete else ", torn") + ")" for s in self.segments))
        for g in self.recorder_gaps:
            sim = "" if g.sim_from_s is None or g.sim_to_s is None else \
                f", sim time {g.sim_from_s:.2f} to {g.sim_to_s:.2f} s"
            out.append(f"  no recorder        {g.duration_s:.2f} s between {Path(g.after).name} "
                       f"and {Path(g.before).name}{sim}")
        out += [
            f"  mission            {m.get('kind')} on {m.get('layout')} with "
            f"{m.get('vehicles')} {self.vehicle_noun}s, strategy {m.get('strategy')}, clock "
            f"{m.get('clock')}, seed {m.get('seed')}" + _lookahead(m),
            f"  finished           {'yes' if self.finished else 'no'}"
            + (f" ({self.mission_error})" if self.mission_error else ""),
            *self.numbers_lines(),
            f"  commit conflicts   {self.commit_conflicts}",
            *self.vehicle_lines(distance=True),
        ]
        out.append("  messages           " + ", ".join(
            f"{k} {n}" for k, n in sorted(self.messages.items())))
        out += self._listed(LOSSES)
        out += [f"  {line}" for line in self.verdict_lines()]
        out += self._listed(FINDINGS)
        if self.stacks_not_recorded:
            out.append(f"  done, not recorded {', '.join(self.stacks_not_recorded[:20])}"
                       + (" ..." if len(self.stacks_not_recorded) > 20 else ""))
        if self.orders is not None:
            o = self.orders
            for label, rows in (("done twice", o.duplicated), ("misnamed", o.misnamed),
                                ("not done", o.not_served), ("lost", o.lost),
                                ("not verified", o.unseen)):
                out += [f"  {label:<19}{row}" for row in rows[:10]]
                if len(rows) > 10:
                    out.append(f"  {label:<19}... {len(rows) - 10} more")
            if self.battery is not None:
                out += [f"  battery fault      t={f.t:.2f} s AGV {f.vehicle}: {f.why}"
                        for f in self.battery.faults[:10]]
            out += [f"  shelf fault        t={f.t:.2f} s"
                    + ("" if f.vehicle is None else f" AGV {f.vehicle}") + f": {f.why}"
                    for f in o.shelf_faults[:10]]
        if self.stacks_lost:
            out.append(f"  not done           {', '.join(self.stacks_lost[:20])}"
                       + (" ..." if len(self.stacks_lost) > 20 else ""))
        return out

    def _listed(self, listings: tuple[Listing, ...]) -> list[str]:
        """The first rows of each listing, one a line under its label."""
        out = []
        for listing in listings:
            rows = getattr(self, listing.rows)
            out += [f"  {listing.label:<19}{listing.line(row)}" for row in rows[:listing.limit]]
            if listing.more and len(rows) > listing.limit:
                out.append(f"  {listing.label:<19}... {len(rows) - listing.limit} "
                           f"{listing.more} more")
        return out


@dataclass(frozen=True)
class Listing:
    """Rows of a Report field listed one a line: at most `limit`, then, if `more` names
    them, how many more there are."""

    rows: str  # the Report field
    label: str
    line: Callable[[Any], str]
    limit: int = 10
    more: str = ""


def _unverified(u: Unverified) -> str:
    owner = "the goods'" if u.vehicle == GOODS else f"forklift {u.vehicle}"
    return f"{owner} {u.check} from sim time {u.sim_from_s:.2f} to {u.sim_to_s:.2f} s: {u.why}"


# Before the verdicts: what was lost, and what was sent while no recorder ran.
LOSSES = (
    Listing("gaps", "gap", lambda g: f"{g.missing} lost on {g.key} from {g.sender} at seq "
            f"{g.first_missing}"),
    Listing("not_recorded", "not recorded", lambda n: f"{n.missing} on {n.key} from "
            f"{n.sender} at seq {n.first_missing} (no recorder running)", more="streams"),
)
# After them: what could not be checked, and what failed.
FINDINGS = (
    Listing("unverified", "not verified", _unverified, limit=20, more="windows"),
    Listing("outside_reservation_unverified", "not judged", lambda o: f"t={o.t:.2f} s "
            f"forklift {o.vehicle} on {list(o.cells)}: its reservations then are not known"),
    Listing("double_bookings_unverified", "not judged", lambda d: f"cell {d.cell} by "
            f"{d.vehicles} over [{d.t0:.2f}, {d.t1:.2f}): the reservations then are not known"),
    Listing("overlaps", "overlap", lambda o: f"t={o.t:.2f} s forklifts {o.vehicles} on "
            f"{list(o.cells)}" + (" (between their states)" if o.between else "")),
    Listing("outside_reservation", "outside", lambda o: f"t={o.t:.2f} s forklift {o.vehicle} "
            f"on {list(o.cells)}"),
    Listing("double_bookings", "double-booked", lambda d: f"cell {d.cell} by {d.vehicles} "
            f"over [{d.t0:.2f}, {d.t1:.2f})"),
    Listing("on_goods", "on goods", lambda o: f"t={o.t:.2f} s forklift {o.vehicle} on the "
            f"goods of {list(o.cells)}"),
    Listing("lane_breaches", "against the lanes", lambda b: f"t={b.t:.2f} s AGV {b.vehicle} "
            f"{b.move[0]} -> {b.move[1]}: {b.rule}: {b.detail}", more="moves"),
    Listing("meetings", "met", lambda m: f"t={m.t:.2f} s AGVs {m.vehicles}: {m.kind} at "
            f"{m.where} {list(m.cells)}", more="meetings"),
    Listing("stacks_duplicated", "done twice", str),
    Listing("stacks_not_served", "not served", lambda n: f"{n.stack}, announced done by "
            f"forklift {n.vehicle} at t={n.t:.2f} s: {n.why}", more="stacks"),
    Listing("stacks_out_of_order", "out of order", lambda o: f"{o.cluster}#{o.taken} taken up "
            f"at t={o.t:.2f} s, before {o.cluster}#{o.first}"),
    Listing("impossible_states", "impossible", lambda i: f"t={i.t:.2f} s forklift "
            f"{i.vehicle} {i.why}", more="states"),
)


def _jsonable(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    return value


def _lookahead(mission: dict) -> str:
    """", lookahead 30 s" when the mission ran with one of its own (the default goes unsaid)."""
    if "lookahead" not in mission:
        return ""
    value = mission["lookahead"]
    return ", no lookahead" if value is None else f", lookahead {value:g} s"
