"""Real zenoh helpers for tests: the reservation service as a process on its own loopback
port, sessions that connect to it, and waiting on liveliness instead of sleeping."""

import os
import signal
import subprocess
import sys
from pathlib import Path

import zenoh

from fleet.runtime.bus import BusConfig, free_port, open_session, wait_alive
from fleet.wire.topics import Keys

ROOT = Path(__file__).resolve().parent.parent


class Service:
    """The service process, listening on its own loopback port; the test's session connects
    to it and waits for its liveliness token (no sleeping)."""

    def __init__(self, tmp: Path, run: str) -> None:
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.journal = tmp / "journal.msgpack"
        self.keys = Keys(run)
        self.log = tmp / "service.log"
        self.proc: subprocess.Popen | None = None

    def start(self) -> None:
        with open(self.log, "ab") as log:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "reservation", "--run", self.keys.run, "--mode", "peer",
                 "--listen", self.endpoint, "--journal", str(self.journal)],
                cwd=ROOT, stderr=log, env={**os.environ, "PYTHONPATH": str(ROOT)})

    def kill(self) -> None:
        self.proc.kill()
        self.proc.wait()

    def stop(self) -> int:
        self.proc.send_signal(signal.SIGTERM)
        return self.proc.wait(timeout=30)


def client(svc: Service) -> zenoh.Session:
    session = open_session(BusConfig("peer", (svc.endpoint,), ()))
    assert wait_alive(session, svc.keys.reservation_alive, 30), "the service did not come up"
    return session
