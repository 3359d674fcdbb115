"""`fleet analyze` on recordings made by hand: a clean run passes; a collision, a forklift
outside its reservation, a stack done twice, a missing stack and a lost message are each
caught; a truncated file is read up to its last complete chunk."""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections import Counter
from pathlib import Path

import mcap.reader
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fleet.analysis.analyze import analyze
from fleet.cli import main
from fleet.dispatching.decision import Strategy
from fleet.errors import UserError
from fleet.mission.engine import engine_options
from fleet.mission.spec import Mission, MissionKind
from fleet.recording.inprocess import Outgoing, recorded_run, write_recording
from fleet.recording.reader import RecordingError, read_recording
from fleet.recording.writer import RecordingWriter
from fleet.wire.protocol import StackDone, VehicleState, WireChange, encode
from fleet.wire.topics import Keys
from fleet.world.layout_file import load_layout

LAYOUT = "small"


@pytest.fixture(scope="module")
def clean_stream() -> list[Outgoing]:
    """What a fault-free fill of the small layout puts on the wire."""
    mission = Mission(LAYOUT, MissionKind.FILL, Strategy.GREEDY)
    layout = load_layout(LAYOUT)
    return recorded_run(mission, layout, engine_options(mission, layout, None))[1]


def analyze_stream(tmp_path: Path, stream: list[Outgoing], *flags: str,
                   capsys) -> tuple[int, dict]:
    path = tmp_path / "run.mcap"
    write_recording(path, stream, load_layout(LAYOUT))
    status = main(["analyze", str(path), "--json", *flags])
    return status, json.loads(capsys.readouterr().out)


def states_at(stream: list[Outgoing], t: float) -> dict[int, int]:
    """Index in the stream of each forklift's state at sim time t."""
    return {o.message.vehicle: k for k, o in enumerate(stream)
            if isinstance(o.message, VehicleState) and o.sim_time == t}


def moving_instant(stream: list[Outgoing]) -> float:
    """A grid instant at which forklift 1 is driving and forklift 2 is somewhere else."""
    for o in stream:
        if isinstance(o.message, VehicleState) and o.message.vehicle == 1 and \
                o.message.maneuver not in ("", "stop") and o.sim_time > 20:
            return o.sim_time
    raise AssertionError("forklift 1 never drives")


def test_a_clean_recording_passes_every_verdict(clean_stream, tmp_path, capsys):
    status, report = analyze_stream(tmp_path, clean_stream, capsys=capsys)
    assert status == 0
    assert report["overlaps"] == 0 and report["outside_reservation"] == 0
    assert report["stacks_done"] == report["stacks_expected"] == 24
    assert report["stacks_duplicated"] == [] and report["stacks_lost"] == []
    assert report["messages_lost"] == 0 and report["complete"]
    assert report["end_time_s"] == clean_stream[-1].message.record["end_time_s"]
    assert {v["vehicle"] for v in report["vehicles"]} == {1, 2}
    assert all(v["distance_m"] > 100 and v["busy_s"] > 100 for v in report["vehicles"])


def test_a_collision_is_caught(clean_stream, tmp_path, capsys):
    t = moving_instant(clean_stream)
    at = states_at(clean_stream, t)
    stream = list(clean_stream)
    one = stream[at[1]].message
    # Forklift 2 reports forklift 1's pose: two bodies on the same cells at the same instant.
    stream[at[2]] = dataclasses.replace(stream[at[2]], message=dataclasses.replace(
        one, vehicle=2))
    status, report = analyze_stream(tmp_path, stream, capsys=capsys)
    assert status == 1
    assert report["overlaps"] == 1
    first = report["overlaps_first"][0]
    assert first["t"] == t and first["vehicles"] == [1, 2] and first["cells"]
    assert report["outside_reservation"] >= 1  # forklift 2 is also off its own cells


def test_a_forklift_outside_its_reservation_is_caught(clean_stream, tmp_path, capsys):
    t = moving_instant(clean_stream)
    k = states_at(clean_stream, t)[1]
    stream = list(clean_stream)
    state = stream[k].message
    cell = load_layout(LAYOUT).cell_size
    stream[k] = dataclasses.replace(stream[k], message=dataclasses.replace(
        state, y=state.y + 3 * cell))  # three cells off its path, where nobody is
    status, report = analyze_stream(tmp_path, stream, capsys=capsys)
    assert status == 1
    assert report["overlaps"] == 0
    assert report["outside_reservation"] == 1
    assert report["outside_reservation_first"][0]["t"] == t
    assert report["outside_reservation_first"][0]["vehicle"] == 1


def test_a_stack_done_twice_is_caught(clean_stream, tmp_path, capsys):
    k, first = next((k, o) for k, o in enumerate(clean_stream)
                    if isinstance(o.message, StackDone))
    again = dataclasses.replace(first, sim_time=first.sim_time + 1)
    stream = [*clean_stream[:k + 1], again, *clean_stream[k + 1:]]
    status, report = analyze_stream(tmp_path, stream, capsys=capsys)
    assert status == 1
    assert report["stacks_duplicated"] == [f"{first.message.cluster}#{first.message.index}"]
    assert report["stacks_lost"] == [] and report["messages_lost"] == 0


def test_a_missing_stack_is_caught(clean_stream, tmp_path, capsys):
    last = max(k for k, o in enumerate(clean_stream) if isinstance(o.message, StackDone))
    missing = clean_stream[last].message
    stream = clean_stream[:last] + clean_stream[last + 1:]  # never sent: no sequence gap
    status, report = analyze_stream(tmp_path, stream, capsys=capsys)
    assert status == 1
    assert report["stacks_lost"] == [f"{missing.cluster}#{missing.index}"]
    assert report["stacks_done"] == 23 and report["messages_lost"] == 0


def write_numbered(path: Path, stream: list[Outgoing], numbered: list[int]) -> None:
    """Write the stream with the given sequence numbers (each stream of its own)."""
    writer = RecordingWriter(path)
    writer.describe(stream[0].message)
    for o, seq in zip(stream, numbered, strict=True):
        writer.write(o.key, encode(o.message, o.sender, seq, o.sim_time), 0, o.sim_time)
    writer.close()


def numbers(stream: list[Outgoing]) -> list[int]:
    count: Counter = Counter()
    out = []
    for o in stream:
        count[o.key, o.sender] += 1
        out.append(count[o.key, o.sender])
    return out


def test_a_sequence_gap_is_a_lost_message(clean_stream, tmp_path, capsys):
    t = moving_instant(clean_stream)
    k = states_at(clean_stream, t)[2]
    path = tmp_path / "run.mcap"
    numbered = numbers(clean_stream)
    # Forklift 2's state at t was sent (it has its number) but never recorded.
    write_numbered(path, clean_stream[:k] + clean_stream[k + 1:], numbered[:k] + numbered[k + 1:])
    status = main(["analyze", str(path), "--json"])
    report = json.loads(capsys.readouterr().out)
    assert status == 1
    assert report["messages_lost"] == 1
    (gap,) = report["gaps"]
    assert gap["key"] == "fleet/default/vehicle/2/state" and gap["sender"] == "vehicle-2"
    assert gap["first_missing"] == numbered[k]
    assert report["overlaps"] == 0 and report["stacks_lost"] == []


def test_forged_and_absurd_messages_neither_fool_nor_break_the_analysis(clean_stream,
                                                                        tmp_path):
    keys = Keys()
    first_change = next(o for o in clean_stream if isinstance(o.message, WireChange))
    forged = [
        # Someone else claiming the table released forklift 1 and a stack was done twice.
        Outgoing(keys.reservation_change, dataclasses.replace(
            first_change.message, op="release", release_from=0.0), "evil", 0.0),
        Outgoing(keys.dispatch_stack, StackDone("s1", 1, 1, 5.0), "evil", 5.0),
        # A state in forklift 1's name from nowhere a run can be.
        Outgoing(keys.vehicle_state(1), VehicleState(1, "0,0,E", 0, "", False, math.inf,
                                                     1e300, 0.0), "vehicle-1", 1e300),
    ]
    path = tmp_path / "run.mcap"
    write_numbered(path, [*clean_stream, *forged],
                   [*numbers(clean_stream), 1, 1, 2**40])
    report = analyze(read_recording(path))
    assert report.foreign == 2  # told apart by sender, and believed nowhere
    assert report.stacks_duplicated == [] and report.outside_reservation == []
    assert report.malformed == 1  # the state nobody can stand in
    assert report.messages_lost == 2**40 - 1 - len(states_of(clean_stream, 1))
    assert report.gaps[0].first_missing == len(states_of(clean_stream, 1)) + 1


def states_of(stream: list[Outgoing], vehicle: int) -> list[Outgoing]:
    return [o for o in stream if isinstance(o.message, VehicleState)
            and o.message.vehicle == vehicle]


def test_a_truncated_recording_gives_its_complete_chunks(clean_stream, tmp_path, capsys):
    path = tmp_path / "run.mcap"
    write_recording(path, clean_stream, load_layout(LAYOUT))
    whole = read_recording(path)
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    part = read_recording(cut)
    assert whole.complete and not part.complete and part.problem
    assert 0 < len(part.messages) < len(whole.messages)
    assert part.messages == whole.messages[: len(part.messages)]  # a prefix, nothing invented
    assert main(["analyze", str(cut)]) == 1  # stacks after the cut are not done
    out = capsys.readouterr().out
    assert "truncated" in out and "recovered" in out


def test_the_recording_opens_with_mcap_tooling(clean_stream, tmp_path):
    path = tmp_path / "run.mcap"
    write_recording(path, clean_stream, load_layout(LAYOUT))
    with open(path, "rb") as f:
        reader = mcap.reader.make_reader(f)
        summary = reader.get_summary()
        topics = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        attachments = [a.name for a in reader.iter_attachments()]
    assert topics["fleet/default/vehicle/1/state"].name == "vehicle.state"
    assert topics["fleet/default/vehicle/1/state"].encoding == "jsonschema"
    assert summary.channels[next(i for i, c in summary.channels.items()
                                 if c.topic == "fleet/default/dispatch/stack")
                            ].message_encoding == "msgpack"
    views = {t: s for t, s in topics.items() if t.startswith("/view/")}
    assert views and all(s.name.startswith("foxglove.") and s.encoding == "protobuf"
                         for s in views.values())
    assert metadata["run"]["layout"] == LAYOUT and metadata["run"]["strategy"] == "greedy"
    assert attachments == ["layout.toml"]


def test_not_a_recording_is_a_clear_error(tmp_path, capsys):
    bad = tmp_path / "mission.json"
    bad.write_text("{}")
    assert main(["analyze", str(bad)]) == 2
    assert "not an MCAP recording" in capsys.readouterr().err


def test_the_recorder_never_overwrites_a_recording(tmp_path, capsys):
    old = tmp_path / "run.mcap"
    old.write_bytes(b"an earlier run")
    assert main(["recorder", "--out", str(old)]) == 2  # refused before it connects anywhere
    assert "never overwritten" in capsys.readouterr().err
    assert old.read_bytes() == b"an earlier run"


@settings(max_examples=int(os.environ.get("FLEET_FUZZ_EXAMPLES", 60)), deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_any_damaged_recording_reads_as_far_as_it_goes_or_is_refused(clean_stream, tmp_path,
                                                                     data):
    """Cut anywhere, bytes flipped anywhere: reading and analysing either work on what is
    left or refuse the file with an error that names the problem (a RecordingError, or a
    LayoutError for a damaged layout attachment); nothing else escapes."""
    path = tmp_path / "whole.mcap"
    if not path.exists():
        write_recording(path, clean_stream, load_layout(LAYOUT))
    whole = bytearray(path.read_bytes())
    cut = data.draw(st.integers(0, len(whole)), label="cut")
    damaged = whole[:cut]
    for _ in range(data.draw(st.integers(0, 3), label="flips")):
        if damaged:
            k = data.draw(st.integers(0, len(damaged) - 1), label="at")
            damaged[k] ^= data.draw(st.integers(1, 255), label="xor")
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(bytes(damaged))
    try:
        recording = read_recording(broken)
        report = analyze(recording)
    except (RecordingError, UserError):
        return
    assert len(recording.messages) <= len(clean_stream)
    assert report.stacks_done <= 24


def test_a_message_lost_as_its_sender_went_down_was_sent_while_cut_off(tmp_path, capsys):
    """A docker network disconnect may catch a forklift's message in flight on the fast clock
    too (tests/test_compose.py saw a clock ack go): a hole in its own stream spanning its
    halt is counted as sent while cut off; the same hole away from any halt is lost."""
    from fleet.mission.faults import parse_scenario
    from fleet.wire.protocol import Halt

    mission = Mission(LAYOUT, MissionKind.FILL, Strategy.GREEDY)
    layout = load_layout(LAYOUT)
    scenario = parse_scenario('name = "k"\ndescription = "k"\n[[fault]]\nkind = "kill_vehicle"\n'
                              'at = 100.3\nvehicle = 2\nduration = 20.0\n', "k")
    stream = recorded_run(mission, layout, engine_options(mission, layout, None),
                          scenario=scenario)[1]
    halt = next(o.message for o in stream if isinstance(o.message, Halt)
                and o.message.vehicle == 2 and not o.message.moving)
    mine = [k for k, o in enumerate(stream)
            if isinstance(o.message, VehicleState) and o.message.vehicle == 2]
    at_halt = max(k for k in mine if stream[k].sim_time <= halt.t)
    numbered = numbers(stream)
    for k, cut_off in ((at_halt, True), (mine[len(mine) // 4], False)):
        path = tmp_path / f"run-{k}.mcap"
        write_numbered(path, stream[:k] + stream[k + 1:], numbered[:k] + numbered[k + 1:])
        status = main(["analyze", str(path), "--json"])
        report = json.loads(capsys.readouterr().out)
        assert (report["messages_cut_off"], report["messages_lost"]) == \
            ((1, 0) if cut_off else (0, 1))
        assert status == (0 if cut_off else 1)
