"""`fleet run --secure`: a whole mission behind zenoh access control with a login per
process, and a rogue process that tries what it must not (tests/test_access.py proves every
rule against a bare router; this proves them in a running mission)."""

import pytest
import zenoh

from fleet.mission.engine import run_mission
from fleet.mission.record import digest
from fleet.mission.spec import Mission, MissionKind, Strategy
from fleet.recording.reader import read_recording
from fleet.runtime.bus import BusConfig, Requester, free_port, open_session
from fleet.runtime.local_run import RunSpec, run_processes
from fleet.wire.protocol import (
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
        password = (tmp_path / "secrets" / "vehicle-1.password").read_text()
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
