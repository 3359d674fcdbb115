"""How many forklift agents keep real time: a generated large layout, the whole runtime as
processes (router, reservation service, N agents, the dispatcher running a fill mission with
the real-time clock at speed 1), and a listener that receives every state message.

A fleet keeps real time when, over the measuring window, at least 90 % of the expected state
messages (N x 10 Hz) arrive and the 99th percentile of their lateness (receive instant minus
the sim time they carry, on the published clock) stays under 100 ms.
"""

from __future__ import annotations

import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

from bench.stats import percentile
from fleet.runtime.bus import BusConfig, free_port, open_session
from fleet.runtime.launcher import Launcher
from fleet.wire.protocol import ClockTick, ProtocolError, decode
from fleet.wire.topics import Keys
from fleet.world.generator import Shape, generate_toml

STATE_HZ = 10.0
MIN_RECEIVED = 0.9
MAX_P99_LATE_S = 0.1


def measure(agents: int, layout: Path, window_s: float, startup_timeout_s: float) -> dict:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    keys = Keys("scale")
    common = ["--run", keys.run, "--connect", endpoint]
    received: list[tuple[float, float]] = []  # (receive wall, sim time carried)
    clock: list[ClockTick] = []
    clock_started = threading.Event()
    lock = threading.Lock()

    def on_state(sample) -> None:
        wall = time.time()
        try:
            t = decode(sample.payload.to_bytes()).sim_time
        except ProtocolError:
            return
        with lock:
            received.append((wall, t))

    def on_tick(sample) -> None:
        message = decode(sample.payload.to_bytes()).message
        if isinstance(message, ClockTick):
            clock.append(message)
            clock_started.set()

    with tempfile.TemporaryDirectory(prefix="fleet-scale-") as tmp:
        launcher = Launcher(Path(tmp) / "logs")
        session = None
        try:
            launcher.start("router", ["router", "--listen", endpoint])
            session = open_session(BusConfig("client", (endpoint,), connect_timeout_ms=30_000))
            subs = [session.declare_subscriber(keys.vehicle_state("*"), on_state),
                    session.declare_subscriber(keys.clock, on_tick)]
            launcher.start("reservation", ["reservation", *common, "--journal",
                                           str(Path(tmp) / "journal")])
            for v in range(1, agents + 1):
                launcher.start(f"agent-{v}", ["agent", *common, "--id", str(v), "--layout",
                                              str(layout)])
            launcher.start("dispatcher", ["dispatcher", *common, "--layout", str(layout),
                                          "--vehicles", str(agents), "--strategy", "traffic",
                                          "--clock", "realtime", "--speed", "1",
                                          "--startup-timeout", str(startup_timeout_s)])
            deadline = time.monotonic() + startup_timeout_s
            # the dispatcher starts the clock once every agent is up
            while not clock_started.wait(1.0):  # the timeout paces the check on the children
                for child in launcher.exited():
                    raise RuntimeError(f"{agents} agents: "
                                       f"{launcher.death(child, 'before the clock started')}")
                if time.monotonic() > deadline:
                    raise RuntimeError(f"{agents} agents: the clock did not start within "
                                       f"{startup_timeout_s:g} s")
            time.sleep(2.0)  # let every agent hear the clock before the window opens
            with lock:
                received.clear()
            start = time.time()
            time.sleep(window_s)
            end = time.time()
            with lock:
                window = [(w, t) for w, t in received if start <= w < end]
            rss = [_rss_mb(c.proc.pid) for c in launcher.children if c.name.startswith("agent")]
            for sub in subs:
                sub.undeclare()
        finally:
            launcher.stop_all()
            if session is not None:
                session.close()
    tick = clock[-1]
    late = [(w - tick.wall) * tick.speed + tick.t - t for w, t in window]
    expected = agents * STATE_HZ * (end - start)
    p99 = percentile(late, 0.99) if late else float("inf")
    return {"agents": agents, "received": len(window), "expected": round(expected),
            "received_share": round(len(window) / expected, 3),
            "late_p50_ms": round(percentile(late, 0.5) * 1000, 1) if late else None,
            "late_p99_ms": round(p99 * 1000, 1),
            "rss_per_agent_mb": round(sum(rss) / len(rss), 1) if rss else None,
            "keeps_real_time": len(window) >= MIN_RECEIVED * expected and p99 < MAX_P99_LATE_S}


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return 0.0


def run(sizes: list[int], window_s: float = 15.0, startup_timeout_s: float = 600.0,
        progress: Callable[[str], None] | None = None) -> dict:
    """Fleets of growing size until one does not keep real time."""
    shape = Shape(aisles=12, depth=20, vehicles=max(sizes))
    rows = []
    with tempfile.TemporaryDirectory(prefix="fleet-scale-layout-") as tmp:
        layout = Path(tmp) / "large.toml"
        layout.write_text(generate_toml(shape, "large"))
        for n in sizes:
            if progress:
                progress(f"{n} agents ...")
            row = measure(n, layout, window_s, startup_timeout_s)
            rows.append(row)
            if progress:
                progress(f"{n} agents: {row}")
            if not row["keeps_real_time"]:
                break
    passing = [r["agents"] for r in rows if r["keeps_real_time"]]
    return {"layout": f"generated {shape.aisles} aisles x depth {shape.depth} "
                      f"({shape.cols} x {shape.rows} cells)",
            "fleets": rows, "max_realtime_agents": max(passing, default=0)}
