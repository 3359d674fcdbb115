"""A real MQTT broker: Debian's mosquitto, started as a child process on a free port of
127.0.0.1 and stopped afterwards (by `fleet run --dispatch external` when no --mqtt is given,
and by the tests); the compose deployment's broker service runs it with the same settings
(`mosquitto_config`).

    with mosquitto(tmp_path) as url:   # "mqtt://127.0.0.1:PORT"
        ...
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from fleet.errors import UserError

HOST = "127.0.0.1"
START_TIMEOUT = 10.0  # s until the port answers: mosquitto takes some 10 ms here
ATTEMPTS = 3  # fresh ports to try: another test may take a free port before mosquitto binds it


class MosquittoMissing(UserError):
    """mosquitto is not installed on this machine."""


@dataclass(frozen=True)
class Broker:
    """A running mosquitto: where it listens and the process."""

    port: int
    process: subprocess.Popen[bytes]
    log: Path

    @property
    def url(self) -> str:
        return f"mqtt://{HOST}:{self.port}"


def mosquitto_binary() -> str:
    """The mosquitto executable; Debian puts it in /usr/sbin, which a user's PATH may lack."""
    path = os.pathsep.join([os.environ.get("PATH", ""), "/usr/sbin", "/usr/local/sbin"])
    found = shutil.which("mosquitto", path=path)
    if found is None:
        raise MosquittoMissing(
            "mosquitto is not installed: give a broker with --mqtt URL, or install one "
            "(Debian: apt-get install -y mosquitto; deploy/install-test-deps does)"
        )
    return found


@contextmanager
def mosquitto(directory: Path) -> Iterator[str]:
    """Run a mosquitto (anonymous, no persistence) with its config and log in `directory`;
    yield its URL once it accepts connections, stop it on exit."""
    broker = start_mosquitto(directory)
    try:
        yield broker.url
    finally:
        stop(broker)


def start_mosquitto(directory: Path, port: int | None = None) -> Broker:
    """A mosquitto that accepts connections (on `port`, or a free one), or RuntimeError with
    its log."""
    binary = mosquitto_binary()
    directory.mkdir(parents=True, exist_ok=True)
    failures = []
    for attempt in range(1 if port else ATTEMPTS):
        port = port or _free_port()
        config = directory / f"mosquitto-{attempt}.conf"
        config.write_text(mosquitto_config(port, HOST))
        log = directory / f"mosquitto-{attempt}.log"
        with log.open("wb") as out:
            process = subprocess.Popen(
                [binary, "-c", str(config)],
                stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
            )
        broker = Broker(port, process, log)
        if _wait_until_listening(broker, time.monotonic() + START_TIMEOUT):
            return broker
        stop(broker)
        failures.append(f"port {port}: {log.read_text(errors='replace').strip() or 'no log'}")
    raise RuntimeError(f"mosquitto did not start ({binary}):\n" + "\n".join(failures))


def mosquitto_config(port: int, host: str) -> str:
    """Anonymous, no persistence (a session's retained messages live as long as its broker),
    the log on stderr (a file of ours, or the container's log: mosquitto may drop root to
    its own user and could not open one)."""
    return (f"listener {port} {host}\n"
            "allow_anonymous true\n"
            "persistence false\n"
            "log_dest stderr\n"
            "log_type error\nlog_type warning\nlog_type notice\nlog_type information\n")


def stop(broker: Broker) -> None:
    if broker.process.poll() is None:
        broker.process.terminate()
        try:
            broker.process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            broker.process.kill()
            broker.process.wait()


def _wait_until_listening(broker: Broker, deadline: float) -> bool:
    """True once the port takes a connection; False if mosquitto exits or the deadline
    passes first."""
    while time.monotonic() < deadline:
        try:
            with socket.create_connection((HOST, broker.port), timeout=0.5):
                return broker.process.poll() is None  # not another process on the port
        except OSError:
            pass
        try:  # the pause between tries, cut short if mosquitto exits (port taken, bad config)
            broker.process.wait(timeout=0.02)
            return False
        except subprocess.TimeoutExpired:
            continue
    return False


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((HOST, 0))
        return s.getsockname()[1]
