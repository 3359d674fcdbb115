"""Faults on the real-time clock (docs/faults.md): every kind in one run of real processes
on paper with four forklifts at 40x. Nothing waits for a fault here: the dispatcher notices
each one as it comes and freezes a margin ahead of now, so that every forklift that can
still move hears of it first. The mission completes, the recording passes every verdict,
and each fault was seen within the issue's bounds (a killed agent within 1 s, a stall or a
lost link within 2 s: the zenoh lease is 1 s)."""

from pathlib import Path

from mission_check import journal_overlaps

from bench.faults import timings
from fleet.analysis.analyze import analyze
from fleet.analysis.windows import SILENT
from fleet.dispatching.decision import Strategy
from fleet.mission.faults import load_scenario
from fleet.mission.spec import ClockMode, Mission, MissionKind
from fleet.recording.reader import read_recording
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.wire.protocol import Halt, Resume, VehicleState, ZoneClosed
from reservation.journal import Journal

MISSION = Mission("paper", MissionKind.FILL, Strategy.ANN, 4, 0)
SPEED = 40.0
# Durations are sim seconds: at 40x, 100 s is 2.5 s of wall time, longer than the lease, so
# the stall and the cut link are noticed (a shorter one passes unseen, as it would for real).
SCENARIO = """
name = "realtime"
[[fault]]
kind = "kill_vehicle"
at = 100.0
vehicle = 2
duration = 60.0
[[fault]]
kind = "stall_vehicle"
at = 300.5
vehicle = 3
duration = 100.0
[[fault]]
kind = "cut_link"
at = 600.5
vehicle = 1
duration = 100.0
[[fault]]
kind = "vehicle_breakdown"
at = 900.5
vehicle = 4
duration = 60.0
[[fault]]
kind = "close_zone"
at = 1100.0
duration = 100.0
cells = "4,5..13,6"
[[fault]]
kind = "kill_service"
at = 1250.0
service = "reservation"
downtime = 1.0
[[fault]]
kind = "kill_service"
at = 1350.0
service = "recorder"
downtime = 1.0
[[fault]]
kind = "kill_service"
at = 1450.0
service = "dispatcher"
downtime = 1.0
"""


def test_every_kind_of_fault_on_the_real_time_clock(tmp_path: Path):
    source = tmp_path / "realtime.toml"
    source.write_text(SCENARIO)
    scenario = load_scenario(str(source))
    out = tmp_path / "run"
    outcome = run_processes(RunSpec(MISSION, 4, out, ClockMode.REALTIME, SPEED, faults=scenario,
                                    faults_source=str(source)))
    assert outcome.error == "" and outcome.done.ok
    report = analyze(read_recording(out))
    assert report.passed, report.verdict_lines()
    assert (len(report.overlaps), len(report.outside_reservation), report.stacks_done,
            report.stacks_duplicated, report.stacks_lost) == (0, 0, 136, [], [])
    # The table never held a cell twice and no request was applied twice.
    assert journal_overlaps(out / "reservation.journal") == []
    ids = [c.request_id for c in Journal(out / "reservation.journal").replay().changes
           if c.request_id]
    assert len(ids) == len(set(ids))

    recording = read_recording(out)
    # Every forklift spoke all along, but for its faults: states on a 0.5 s grid (40x), in
    # every half second some forklift's state was recorded in. While the recorder is down
    # nothing is (how long its restart takes depends on the machine's load).
    said = {v: {round(r.envelope.sim_time * 2) for r, m in recording.of(VehicleState)
                if m.vehicle == v} for v in (1, 2, 3, 4)}
    heard = set().union(*said.values())
    assert len(heard) > 0.5 * 2 * report.end_time_s, len(heard)
    for v, grid in said.items():
        assert len(grid) > 0.8 * len(heard), (v, len(grid), len(heard))
    down = {m.vehicle: m for _, m in recording.of(Halt) if not m.moving}
    assert set(down) == {1, 2, 3, 4}  # each forklift's fault stopped it ...
    assert {m.vehicle for _, m in recording.of(Resume)} == {1, 2, 3, 4}  # ... and it moved on
    for fault in scenario.faults:
        if fault.vehicle is not None:  # frozen after the fault, a margin after noticing it
            assert fault.at < down[fault.vehicle].t < fault.until
    assert down[4].cause == "breakdown"
    (zone,) = [m for _, m in recording.of(ZoneClosed)]
    assert 1100.0 <= zone.t0 < zone.t1 == 1200.0
    # A forklift killed, stalled or cut off is silent from its fault until its freeze: the
    # report says those windows were not verified rather than pretend they were.
    silent = {u.vehicle for u in report.unverified if u.why.startswith(SILENT)}
    assert {1, 2, 3} <= silent
    # Seen within the bounds: the injector's wall clock against the dispatcher's.
    detect, _, rejoin = timings(outcome, recording)
    assert len(detect) == 4 and len(rejoin) == 4, (detect, rejoin)
    killed, stalled, cut, broken = detect
    assert killed <= 1.0 and stalled <= 2.0 and cut <= 2.0 and broken <= 1.0, detect
    # Every halt reached its forklift before its instant; the restarted services took over.
    logs = out / "logs"
    assert not [p.name for p in logs.glob("agent-*.log") if "came late" in p.read_text()]
    assert "picked the mission up at t=" in (logs / "dispatcher-2.log").read_text()
    assert (out / "run-2.mcap").exists() and len(recording.segments) == 2
