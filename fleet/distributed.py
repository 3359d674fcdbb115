"""One mission as processes on this machine (what `fleet run` does): a zenoh router on a
loopback port, the reservation service, one agent per forklift and the dispatcher, all
clients of the router. This process follows the dispatcher's progress and result, and stops
every child when the mission ends, on Ctrl-C, or as soon as any child dies."""

from __future__ import annotations

import logging
import queue
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import zenoh

from fleet.bus import BusConfig, Keys, free_port, open_session, received
from fleet.launcher import Launcher
from fleet.mission import Mission
from fleet.protocol import MissionDone, Progress

ROUTER_TIMEOUT_MS = 30_000
log = logging.getLogger("fleet.run")


@dataclass
class RunSpec:
    mission: Mission
    vehicles: int
    run_dir: Path  # logs/ and the reservation journal go here
    clock: str = "fast"
    speed: float = 1.0
    weights: Path | None = None
    port: int | None = None  # router port on 127.0.0.1 (default: a free one)
    run: str = "default"
    extra: dict[str, list[str]] = field(default_factory=dict)  # more flags per process kind


@dataclass
class RunOutcome:
    done: MissionDone | None
    error: str
    endpoint: str
    log_dir: Path


class RunFailed(RuntimeError):
    pass


def dispatcher_args(spec: RunSpec) -> list[str]:
    m = spec.mission
    args = ["--layout", m.layout, "--mission", m.kind.value, "--strategy", m.strategy.value,
            "--vehicles", str(spec.vehicles), "--seed", str(m.seed), "--clock", spec.clock,
            "--speed", repr(spec.speed)]
    if spec.weights is not None:
        args += ["--weights", str(spec.weights)]
    return args


def run_processes(spec: RunSpec, on_progress: Callable[[Progress], None] | None = None,
                  on_ready: Callable[[zenoh.Session, Keys, Launcher], None] | None = None
                  ) -> RunOutcome:
    """Run the mission; `on_ready` is called with this process's session, the keys and the
    launcher once every child has been started (tests use it to watch or disturb the run)."""
    endpoint = f"tcp/127.0.0.1:{spec.port or free_port()}"
    keys = Keys(spec.run)
    log_dir = spec.run_dir / "logs"
    journal = spec.run_dir / "reservation.journal"
    journal.unlink(missing_ok=True)  # a new run starts from an empty table
    launcher = Launcher(log_dir)
    inbox: queue.Queue[tuple[str, object]] = queue.Queue()
    session = None
    try:
        launcher.start("router", ["router", "--listen", endpoint])
        session = open_session(BusConfig("client", (endpoint,),
                                         connect_timeout_ms=ROUTER_TIMEOUT_MS))
        subscribers = [session.declare_subscriber(key, lambda s: inbox.put(("sample", s)))
                       for key in (keys.dispatch_progress, keys.dispatch_done)]
        common = ["--run", spec.run, "--connect", endpoint]
        launcher.start("reservation", ["reservation", *common, "--journal", str(journal),
                                       *spec.extra.get("reservation", [])])
        for v in range(1, spec.vehicles + 1):
            launcher.start(f"agent-{v}", ["agent", *common, "--id", str(v), "--layout",
                                          spec.mission.layout, *spec.extra.get("agent", [])])
        launcher.start("dispatcher", ["dispatcher", *common, *dispatcher_args(spec),
                                      *spec.extra.get("dispatcher", [])])
        if on_ready is not None:
            on_ready(session, keys, launcher)
        done = _follow(inbox, launcher, on_progress)
        for subscriber in subscribers:
            subscriber.undeclare()
        return RunOutcome(done, "" if done.ok else done.error, endpoint, log_dir)
    except RunFailed as exc:
        return RunOutcome(None, str(exc), endpoint, log_dir)
    finally:
        launcher.stop_all()
        if session is not None:
            session.close()


def _follow(inbox: queue.Queue, launcher: Launcher,
            on_progress: Callable[[Progress], None] | None) -> MissionDone:
    while True:
        try:
            _, sample = inbox.get(timeout=0.5)  # the timeout only paces the liveness check
        except queue.Empty:
            dead = launcher.exited()
            if dead:
                done = _last_word(inbox)
                if done is not None:
                    return done  # the dispatcher's account of it, when it has one
                child = dead[0]
                raise RunFailed(f"{child.name} exited with status {child.proc.returncode} "
                                f"before the mission ended; the end of {child.log}:\n"
                                f"{launcher.tail(child)}") from None
            continue
        message = received(sample, (MissionDone, Progress), log)
        if isinstance(message, MissionDone):
            return message
        if isinstance(message, Progress) and on_progress is not None:
            on_progress(message)


def _last_word(inbox: queue.Queue, within_s: float = 3.0) -> MissionDone | None:
    """The dispatcher's result if it arrives soon (it notices a dead forklift by liveliness
    and says which one and when)."""
    deadline = time.monotonic() + within_s
    while (left := deadline - time.monotonic()) > 0:
        try:
            _, sample = inbox.get(timeout=left)
        except queue.Empty:
            return None
        message = received(sample, (MissionDone, Progress), log)
        if isinstance(message, MissionDone):
            return message
    return None
