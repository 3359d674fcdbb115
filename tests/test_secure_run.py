"""`fleet run --secure`: a whole mission behind zenoh access control with a login per
process, and a rogue process that tries what it must not (tests/test_access.py proves every
rule against a bare router; this proves them in a running mission)."""

import json

import pytest
import zenoh

from fleet.cli import main
from fleet.commands import run004 as run004_command
from fleet.dispatching.decision import Strategy
from fleet.mission.engine import run_mission
from fleet.mission.record import digest
from fleet.mission.spec import Mission, MissionKind
from fleet.recording.reader import read_recording
from fleet.runtime.bus import BusConfig, Requester, free_port, open_session, wait_alive
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.wire.protocol import (
    CellRequest,
    CommitRequest,
    MissionDone,
    TaskRequest,
    VehicleState,
    encode,
)
from reservation.journal import Journal

MISSION = Mission("small", MissionKind.FILL, Strategy.TRAFFIC)


def test_a_secure_mission_refuses_a_rogue_with_no_or_a_forklifts_credentials(tmp_path):
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    tried = {}

    def on_ready(session, keys, launcher):
        # No credentials: the router refuses the session during the handshake.
        with pytest.raises(zenoh.ZError):
            open_session(BusConfig("client", (endpoint,), connect_timeout_ms=3000))
        password = (tmp_path / "secrets" / "local" / "vehicle-1.password").read_text()
        rogue = open_session(BusConfig("client", (endpoint,), connect_timeout_ms=30_000,
                                       user="vehicle-1", password=password))
        try:
            # Forklift 1's login, posing as forklift 2: a fake state, a commit of forklift
            # 2's reservation under its key, a task assigned to it, a forged mission result.
            rogue.put(keys.vehicle_state(2), encode(
                VehicleState(2, "0,0,E", 2, "forward", False), "vehicle-2", 999_999, 3.0))
            commit = CommitRequest("rogue:1", 2, [(0, 0, 0.0, 1e9)])
            tried["commit"] = [r for r in rogue.get(
                keys.reservation_request("vehicle-2"),
                payload=encode(commit, "vehicle-2", 1, 0.0), timeout=5) if r.ok is not None]
            # Under its own key the service itself refuses another forklift's reservation.
            tried["own_key"] = Requester(rogue, "vehicle-1").request(
                keys.reservation_request("vehicle-1"),
                CommitRequest("rogue:2", 2, [(0, 0, 0.0, 1e9)])).message
            task = TaskRequest("rogue:3", 2, "return", "0,0,E", 1.0, ["1,1,E"], [], False, 0)
            tried["task"] = [r for r in rogue.get(
                keys.vehicle_task(2), payload=encode(task, "dispatcher", 1, 0.0), timeout=5)
                if r.ok is not None]
            rogue.put(keys.dispatch_done, encode(MissionDone(True, digest="FORGED"),
                                                 "dispatcher", 1, 0.0))
        finally:
            rogue.close()

    outcome = run_processes(RunSpec(MISSION, 2, tmp_path, port=port, secure=True),
                            on_ready=on_ready)
    assert tried["commit"] == [] and tried["task"] == []  # nobody was reached: no reply
    assert not tried["own_key"].ok
    assert "vehicle-1 may change only its own reservations" in tried["own_key"].reason
    # The mission never noticed: the same record as in one process, nothing forged in it.
    assert outcome.error == "" and outcome.done.digest == digest(run_mission(MISSION))
    ids = [c.request_id for c in Journal(tmp_path / "reservation.journal").replay().changes]
    assert not any(i.startswith("rogue") for i in ids)
    recording = read_recording(tmp_path)
    assert not any(r.envelope.seq == 999_999 for r, _ in recording.of(VehicleState))
    assert all(m.digest != "FORGED" for _, m in recording.of(MissionDone))
    assert recording.foreign == [] and len(list(recording.of(MissionDone))) == 1


def test_a_secure_seed004_run_gives_the_in_process_record_and_refuses_a_rogue_agv(
        tmp_path, capsys, monkeypatch):
    """`fleet run --layout paper004 --secure`: the lifting AGVs and their dispatcher behind
    access control with the grants of a seed-004 run. A rogue with AGV 1's login asks AGV 2's
    agent to take a cell, commits as AGV 2 and serves AGV 2's task key: nobody is reached,
    the service refuses under AGV 1's own key a change to AGV 2's cells, and the mission ends
    with the in-process run's record, every verdict passing."""
    tried: dict[str, object] = {}
    rogue_asked: list[str] = []
    rogue: dict[str, object] = {}  # its session and queryable, closed once the run is over

    def on_ready(session, keys, launcher):
        assert wait_alive(session, keys.vehicle_alive(2), 60.0)  # the agent a get would reach
        password = (tmp_path / "run" / "secrets" / "local" / "vehicle-1.password").read_text()
        session = rogue["session"] = open_session(BusConfig(
            "client", (f"tcp/127.0.0.1:{port}",), connect_timeout_ms=30_000, user="vehicle-1",
            password=password))
        take = CellRequest("rogue:1", 2, (0, 0), 0.0, True)  # AGV 2 told to take a cell
        tried["task"] = list(session.get(keys.vehicle_task(2), timeout=5,
                                         payload=encode(take, "dispatcher", 1, 0.0)))
        commit = CommitRequest("rogue:2", 2, [(0, 0, 0.0, 1e9)])
        tried["commit"] = list(session.get(keys.reservation_request("vehicle-2"), timeout=5,
                                           payload=encode(commit, "vehicle-2", 1, 0.0)))
        tried["own_key"] = Requester(session, "vehicle-1").request(
            keys.reservation_request("vehicle-1"),
            CommitRequest("rogue:3", 2, [(0, 0, 0.0, 1e9)])).message
        # Declared after its own gets (a session's queryable hears that session's gets):
        # the dispatcher's requests to AGV 2 from now on would reach it, were it let through.
        rogue["queryable"] = session.declare_queryable(
            keys.vehicle_task(2), lambda query: rogue_asked.append(str(query.key_expr)))

    def with_rogue(spec, progress):
        return run_processes(spec, progress, on_ready=on_ready)

    port = free_port()
    monkeypatch.setattr(run004_command, "run_processes", with_rogue)
    small = ["run", "--layout", "paper004", "--orders", "6", "--vehicles", "3", "--json"]
    try:
        assert main([*small, "--secure", "--port", str(port), "--out",
                     str(tmp_path / "run")]) == 0
    finally:
        if "queryable" in rogue:
            rogue["queryable"].undeclare()
        if "session" in rogue:
            rogue["session"].close()
    secure = json.loads(capsys.readouterr().out)
    assert main([*small, "--inprocess", "--out", str(tmp_path / "inprocess")]) == 0
    reference = json.loads(capsys.readouterr().out)
    assert secure["finished"] and secure["verdicts"]["passed"], secure["verdicts"]
    assert all(secure["verdicts"].values()) and secure["picked"] == 6
    assert secure["digest"] == reference["digest"]  # the record of the run in one process
    assert tried["task"] == [] and tried["commit"] == [] and rogue_asked == []
    assert not tried["own_key"].ok
    assert "vehicle-1 may change only its own reservations" in tried["own_key"].reason
    ids = [c.request_id for c in Journal(tmp_path / "run" / "reservation.journal")
           .replay().changes]
    assert not any(i.startswith("rogue") for i in ids)
    # The router ran a seed-004 run's rules: an AGV's login may put nothing at all.
    acl = json.loads((tmp_path / "run" / "secrets" / "local" / "acl.json").read_text())
    rules = {r["id"]: r for r in acl["rules"]}
    (agv1,) = [p for p in acl["policies"] if p["id"] == "vehicle-1"]
    assert not any("put" in rules[i]["messages"] for i in agv1["rules"]
                   if rules[i]["flows"] == ["ingress"])
