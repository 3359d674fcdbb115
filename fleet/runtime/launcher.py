"""Child processes of one run: spawned (never forked: a forked zenoh session hangs), one log
file each, and stopped together, politely first (SIGTERM lets each close its zenoh session)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from fleet.runtime.lifecycle import PARENT_ENV

STOP_TIMEOUT_S = 10.0
STOPPED_LAST = ("recorder", "router")  # in this order, after every other child


@dataclass
class Child:
    name: str
    proc: subprocess.Popen
    log: Path
    killed: bool = False  # on purpose (a fault): its exit is no failure of the run
    prefix: tuple[str, ...] = ()  # the command that started it on its host


class Launcher:
    """`on_exit` is called (from a thread of its own) with each child the moment it exits,
    so whoever runs the children hears of a death at once instead of polling for it."""

    def __init__(self, log_dir: Path, on_exit: Callable[[Child], None] | None = None) -> None:
        self.log_dir = log_dir
        self.children: list[Child] = []
        self.on_exit = on_exit
        log_dir.mkdir(parents=True, exist_ok=True)

    def start(self, name: str, fleet_args: list[str], prefix: tuple[str, ...] = ()) -> Child:
        """Start `python -m fleet <fleet_args>` in its own process group (a Ctrl-C in the
        terminal reaches only us; we stop the children in order); `prefix` starts it on
        another host, in place (`ip netns exec NS`: signals reach it, fleet/runtime/hosts.py)."""
        path = self.log_dir / f"{name}.log"
        with open(path, "wb") as log:
            proc = subprocess.Popen([*prefix, sys.executable, "-m", "fleet", *fleet_args],
                                    stdin=subprocess.DEVNULL, stdout=log,
                                    stderr=subprocess.STDOUT, start_new_session=True,
                                    env={**os.environ, "PYTHONUNBUFFERED": "1",
                                         PARENT_ENV: str(os.getpid())})
        child = Child(name, proc, path, prefix=prefix)
        self.children.append(child)
        if self.on_exit is not None:
            threading.Thread(target=self._watch, args=(child,), daemon=True,
                             name=f"watch-{name}").start()
        return child

    def _watch(self, child: Child) -> None:
        child.proc.wait()
        self.on_exit(child)

    def exited(self) -> list[Child]:
        """Children that exited without being killed on purpose."""
        return [c for c in self.children if c.proc.poll() is not None and not c.killed]

    def running(self, name: str) -> Child:
        """The live child started as `name` or as a restart of it (`name-2`, ...)."""
        for child in reversed(self.children):
            if (child.name == name or child.name.startswith(f"{name}-")) and \
                    child.proc.poll() is None:
                return child
        raise RuntimeError(f"no {name} process is running")

    def restart(self, name: str, again: str, fleet_args: list[str]) -> Child:
        """Start `again` on the host where `name` was first started."""
        first = next((c for c in self.children if c.name == name), None)
        return self.start(again, fleet_args, first.prefix if first is not None else ())

    def kill(self, name: str) -> None:
        """SIGKILL (a fault: no chance to clean up) and reap it."""
        child = self.running(name)
        child.killed = True
        child.proc.kill()
        child.proc.wait()

    def signal(self, name: str, sig: signal.Signals) -> None:
        self.running(name).proc.send_signal(sig)

    def stop_all(self) -> None:
        """SIGTERM to the workers, wait, then the recorder (it records them leaving), then
        the router: a process closing its zenoh session while its router is already gone can
        hang. What does not stop in time gets SIGUSR1 (its stacks go to its log), then
        SIGKILL."""
        last = [[c for c in self.children if c.name.split("-")[0] == name]
                 for name in STOPPED_LAST]
        waves = [[c for c in self.children if c.name.split("-")[0] not in STOPPED_LAST]]
        waves += last
        for group in waves:
            for child in group:
                if child.proc.poll() is None:
                    child.proc.send_signal(signal.SIGCONT)  # a stalled child could not stop
                    child.proc.send_signal(signal.SIGTERM)
            for child in group:
                self._reap(child)

    @staticmethod
    def _reap(child: Child) -> None:
        try:
            child.proc.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            child.proc.send_signal(signal.SIGUSR1)
            try:
                child.proc.wait(1.0)
            except subprocess.TimeoutExpired:
                child.proc.kill()
                child.proc.wait()

    @staticmethod
    def death(child: Child, when: str) -> str:
        """How a child ended, in one line: its exit status (or signal), `when`, and its log's
        last line (its own error message when it refused to run)."""
        code = child.proc.returncode
        status = f"exited with status {code}"
        if code is not None and code < 0 and -code in signal.valid_signals():
            status += f" (killed by {signal.Signals(-code).name})"
        try:
            lines = [line.strip() for line in
                     child.log.read_text(errors="replace").splitlines() if line.strip()]
        except OSError:
            lines = []
        last = f"the last line of its log ({child.log}): {lines[-1]}" if lines \
            else f"its log ({child.log}) is empty"
        return f"{child.name} {status} {when}; {last}"
