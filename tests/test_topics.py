"""The catalogue of topics (fleet.wire.topics) against what processes really publish and the
recorder really records."""

import mcap.reader
import pytest

from fleet.dispatching.decision import Strategy
from fleet.mission.engine import engine_options
from fleet.mission.faults import load_scenario
from fleet.mission.spec import Mission, MissionKind
from fleet.recording.inprocess import recorded_run
from fleet.recording.reader import read_recording
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.wire.protocol import ClockAck, ClockTick, Envelope, VehicleState
from fleet.wire.topics import (
    CLOCK,
    DISPATCHER,
    GATEWAY,
    INJECTOR,
    PUBLICATIONS,
    RECORDER,
    RESERVATION,
    TOPICS,
    VEHICLE,
    Keys,
    Topic,
    genuine,
    topic_of,
    vehicle_of,
    vehicle_sender,
)
from fleet.world.layout_file import load_layout

# A breakdown and a closed zone on the small layout: the faults' own streams (a forklift's
# fault, the injector's acks, the dispatcher's halt, resume and zone) are heard too.
SCENARIO = """name = "topics"
[[fault]]
kind = "vehicle_breakdown"
at = 30.0
vehicle = 1
duration = 20.0

[[fault]]
kind = "close_zone"
at = 100.0
duration = 30.0
cells = "6,1..7,1"
"""
SAMPLE = {"vehicle": 7, "principal": "vehicle-7", "host": "b"}  # a value for each placeholder


def test_every_key_of_a_run_is_of_exactly_one_topic_and_names_its_vehicle():
    keys = Keys("run-7")
    for name, topic in vars(Keys).items():
        if not isinstance(topic, Topic):
            continue
        values = [SAMPLE[f] for f in topic.fields]
        key = getattr(keys, name)(*values) if values else getattr(keys, name)
        assert key == topic.key("run-7", *values) and key.startswith(keys.root + "/")
        assert [t for t in TOPICS if t.match(key) is not None] == [topic], key
        assert topic_of(key) is topic
        assert topic.match(key) == {f: str(SAMPLE[f]) for f in topic.fields}
        assert Keys.vehicle_in(key) == (7 if "vehicle" in topic.fields else None)
    assert topic_of("fleet/run-7/vehicle/7/nothing") is None
    assert topic_of("fleet/run-7/clock/ack/someone") is None


def test_each_sender_publishes_each_message_type_on_one_topic():
    senders = {t.sender for t in PUBLICATIONS}
    assert senders == {VEHICLE, RESERVATION, CLOCK, INJECTOR, DISPATCHER, RECORDER, GATEWAY}
    for sender in senders:
        types = [t.message for t in PUBLICATIONS if t.sender == sender]
        assert len(types) == len(set(types)), sender


@pytest.mark.parametrize("vehicle", [1, 12, 250])
def test_a_forklifts_sender_name_is_read_back_as_its_id(vehicle):
    assert vehicle_sender(vehicle) == f"vehicle-{vehicle}"
    assert vehicle_of(vehicle_sender(vehicle)) == vehicle


@pytest.mark.parametrize("sender", ["dispatcher", "vehicle-", "vehicle-1x", "vehicle/1",
                                    "claim:vehicle-1", "vehicle-1 ", "injector"])
def test_no_other_sender_is_taken_for_a_forklift(sender):
    assert vehicle_of(sender) is None


def test_a_message_is_believed_only_of_its_keys_type_from_its_keys_sender():
    keys = Keys("r")
    ack = ClockAck(1, 1)
    assert genuine(keys.clock_ack(1), Envelope(ack, "vehicle-1", 1, 0.0))
    assert not genuine(keys.clock_ack(1), Envelope(ack, "vehicle-2", 1, 0.0))
    assert genuine(keys.injector_ack, Envelope(ClockAck(1, 0), "injector", 1, 0.0))
    assert not genuine(keys.injector_ack, Envelope(ack, "vehicle-1", 1, 0.0))
    assert not genuine(keys.clock_ack(1), Envelope(ClockTick(1, "fast", 0.0), "vehicle-1", 1,
                                                   0.0))
    state = VehicleState(1, "0,0,E", 0, "", False)
    assert not genuine(keys.vehicle_task(1), Envelope(state, "vehicle-1", 1, 0.0))  # a query's
    assert not genuine("elsewhere/vehicle/1/state", Envelope(state, "vehicle-1", 1, 0.0))


def test_a_run_of_processes_records_only_catalogued_streams_from_their_senders(tmp_path):
    (tmp_path / "topics.toml").write_text(SCENARIO)
    scenario = load_scenario(tmp_path / "topics.toml")
    mission = Mission("small", MissionKind.FILL, Strategy.ANN)
    run_dir = tmp_path / "run"
    outcome = run_processes(RunSpec(mission, 2, run_dir, faults=scenario,
                                    faults_source=str(tmp_path / "topics.toml")))
    assert outcome.error == "" and outcome.done.ok
    recording = read_recording(run_dir)
    heard: dict[Topic, set[tuple[str, str, str]]] = {}
    for r in recording.messages:
        (topic,) = [t for t in TOPICS if t.match(r.key) is not None]
        assert topic in PUBLICATIONS, r.key
        assert r.envelope is not None, r.error
        assert type(r.message) is topic.message, r.key
        assert r.envelope.sender == topic.sender_on(r.key), r.key
        heard.setdefault(topic, set()).add((r.key, r.envelope.sender, r.message.TYPE))
    assert recording.foreign == []
    # every sender's but the VDA 5050 gateway's (tests/test_vda5050_gateway.py records it)
    assert {t.sender for t in heard} == {t.sender for t in PUBLICATIONS} - {GATEWAY}
    # No delivery cut short, no deadlock to break, the mission finished (tests/
    # test_failed_runs.py has one that did not), and no leg postponed (seed 002's AGVs only:
    # tests/test_agv_missions.py records them), and no seed-004 tracking event (its lifting
    # AGVs only: tests/test_runtime004.py records them), and nothing of the VDA 5050 gateway
    # (tests/test_vda5050_dispatch.py records its traffic and legs).
    assert set(PUBLICATIONS) - set(heard) == {Keys.dispatch_reopen, Keys.dispatch_deadlock,
                                              Keys.dispatch_stopped, Keys.dispatch_amended,
                                              Keys.dispatch_agv, Keys.vda5050_mqtt,
                                              Keys.vda5050_leg}
    # The recorder chose each channel's schema by its key's topic.
    with open(run_dir / "run.mcap", "rb") as f:
        summary = mcap.reader.make_reader(f).get_summary()
    for channel in summary.channels.values():
        if not channel.topic.startswith("/view/"):
            assert summary.schemas[channel.schema_id].name == topic_of(
                channel.topic).message.TYPE
    # The in-process run of the same mission puts each message on the key, and in the name,
    # the processes do.
    layout = load_layout("small")
    _, stream = recorded_run(mission, layout, engine_options(mission, layout, None),
                             scenario=scenario)
    inprocess = {(o.key, o.sender, o.message.TYPE) for o in stream}
    assert inprocess <= set().union(*heard.values())
