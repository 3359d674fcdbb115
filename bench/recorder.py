"""Recorder benchmark: how many messages a second the recorder takes without losing one, and
what recording costs a mission's wall time.

1. Throughput. A real router and a real recorder process (`fleet router`, `fleet recorder`,
   clients on loopback), and a publisher process (`python -m bench.recorder`, spawned: a
   zenoh session does not survive fork) that publishes vehicle states from N streams, one per
   vehicle, at a target total rate for a few seconds, paced by the wall clock in batches of
   about 2 ms. The streams drop under congestion (zenoh's default for states), so an
   overloaded path shows as lost messages, not as a slowed publisher; the publisher reports
   how many it sent. Once it is done, the recorder's status is polled until its count equals
   what was sent or stops growing; the recorder is stopped (SIGTERM: it writes what it holds
   and finishes the file) and the MCAP read back: recorded messages, and lost ones by each
   stream's sequence numbers.
2. Wall time. Fast-mode fills (`run_processes`) with the recorder and without, alternated;
   the cost is the ratio of the medians minus one.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
GOAL_RATE = 10_000  # 10x a 100-forklift run's states at 10 Hz
GOAL_COST = 0.05  # recording may add at most 5 % to a mission's wall time
MIN_ACHIEVED = 0.95  # a rate counts only if the publisher reached 95 % of it
BATCH_S = 0.002  # pacing: the publisher sends what is due about every 2 ms
LATE_S = 0.1  # what is still due this long after the window is not sent
STALL_S = 1.5  # the recorder's count not growing for this long: it has all it will get,
KEEPS_UP_S = 0.5  # ... and it keeps up when it holds everything within this of the end
DRAIN_TIMEOUT_S = 180.0
STARTUP_TIMEOUT_S = 30.0


# ----------------------------------------------------------------------- the publisher


def publish(streams: list, rate: float, seconds: float) -> tuple[int, float]:
    """Publish vehicle states round-robin from `streams` (one per vehicle) at `rate`
    messages a second in all, for at most `seconds`; how many were sent, in how long."""
    from fleet.wire.protocol import VehicleState

    n = len(streams)
    total = round(rate * seconds)
    batch = max(1, round(rate * BATCH_S))
    sent = 0
    start = time.perf_counter()
    end = start + seconds
    while sent < total:
        now = time.perf_counter()
        if now >= end + LATE_S:  # a publisher that falls behind stops all the same
            break
        due = min(total, int((now - start) * rate) + 1)  # message i is due at i / rate
        if sent >= due:
            # pacing: sleep until the next batch is due (always before the end)
            time.sleep(max(0.0, start + (sent + batch - 1) / rate - now))
            continue
        for _ in range(min(due - sent, batch)):
            k, v = divmod(sent, n)
            streams[v].put(VehicleState(v + 1, f"{k % 40},{v + 1},E", 2, "forward",
                                        k % 2 == 0, 0.1 * (k % 400), 2.0 * (v + 1), 0.0),
                           k * n / rate)
            sent += 1
    return sent, time.perf_counter() - start


def _publisher_main(argv: list[str]) -> int:
    """`python -m bench.recorder --connect E --run R --publishers N --rate X --seconds S`:
    once every stream has a subscriber, publishes, prints one JSON line (sent, elapsed_s),
    then keeps its session open until its stdin closes, so nothing still queued is cut off
    by closing it."""
    import threading

    from fleet.runtime.bus import BusConfig, Stream, open_session
    from fleet.wire.topics import Keys, vehicle_sender

    p = argparse.ArgumentParser(prog="python -m bench.recorder")
    p.add_argument("--connect", required=True)
    p.add_argument("--run", required=True)
    p.add_argument("--publishers", type=int, required=True)
    p.add_argument("--rate", type=float, required=True)
    p.add_argument("--seconds", type=float, required=True)
    args = p.parse_args(argv)
    session = open_session(BusConfig("client", (args.connect,), connect_timeout_ms=30_000))
    try:
        keys = Keys(args.run)
        # reliable=False: congestion drops, so an overloaded path shows as lost messages
        streams = [Stream(session, keys.vehicle_state(v), vehicle_sender(v), reliable=False)
                   for v in range(1, args.publishers + 1)]
        for stream in streams:  # the router must have heard of the recorder's subscriber
            matched = threading.Event()
            listener = stream.publisher.declare_matching_listener(
                lambda status, ev=matched: ev.set() if status.matching else None)
            if not (stream.publisher.matching_status.matching
                    or matched.wait(STARTUP_TIMEOUT_S)):
                raise RuntimeError(f"nobody subscribes to {stream.publisher.key_expr}")
            listener.undeclare()
        sent, elapsed = publish(streams, args.rate, args.seconds)
        print(json.dumps({"sent": sent, "elapsed_s": elapsed}), flush=True)
        sys.stdin.read()  # until the benchmark is done with us
        for stream in streams:
            stream.undeclare()
    finally:
        session.close()
    return 0


# ----------------------------------------------------------------------- throughput


def _status(session, keys) -> int | None:
    """The recorder's message count, or None if it did not answer."""
    from fleet.wire.protocol import ProtocolError, RecorderStatus, decode

    for reply in session.get(keys.recorder_status, timeout=5.0):
        if reply.ok is None:
            continue
        try:
            status = decode(reply.ok.payload.to_bytes()).message
        except ProtocolError:
            continue
        if isinstance(status, RecorderStatus):
            return status.messages
    return None


def _wait_drained(session, keys, sent: int) -> tuple[int | None, float]:
    """Poll the recorder until it holds `sent` messages or its count stops growing; its
    last count and how long after the call it last grew (its backlog, in seconds)."""
    start = time.monotonic()
    last, grew = None, start
    while time.monotonic() - start < DRAIN_TIMEOUT_S:
        count = _status(session, keys)  # None (no answer) says nothing either way
        if count is not None:
            if count != last:
                last, grew = count, time.monotonic()
            if count >= sent or time.monotonic() - grew >= STALL_S:
                break
        time.sleep(0.1)  # polling the recorder's count: it has no event to wait on
    return last, grew - start


def measure_rate(endpoint: str, launcher, tmp: Path, rate: int, publishers: int,
                 seconds: float, session) -> dict:
    """One target rate against a fresh recorder."""
    from fleet.analysis.streams import sequence_gaps
    from fleet.recording.reader import read_recording
    from fleet.runtime.bus import wait_alive
    from fleet.wire.protocol import VehicleState
    from fleet.wire.topics import Keys

    keys = Keys(f"benchrec{rate}")
    out = tmp / f"rate-{rate}.mcap"
    recorder = launcher.start(f"recorder-{rate}", ["recorder", "--run", keys.run,
                                                   "--connect", endpoint, "--out", str(out)])
    if not wait_alive(session, keys.recorder_alive, STARTUP_TIMEOUT_S):
        raise RuntimeError(f"the recorder did not start; see {recorder.log}")
    publisher = subprocess.Popen(
        [sys.executable, "-m", "bench.recorder", "--connect", endpoint, "--run", keys.run,
         "--publishers", str(publishers), "--rate", str(rate), "--seconds", str(seconds)],
        cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        line = publisher.stdout.readline()
        if not line:
            raise RuntimeError(f"the publisher exited with status {publisher.wait()} "
                               f"before reporting")
        report = json.loads(line)
        sent = report["sent"]
        count, drain_s = _wait_drained(session, keys, sent)
    finally:
        publisher.stdin.close()
        try:
            publisher.wait(30)
        except subprocess.TimeoutExpired:
            publisher.kill()
            publisher.wait()
    recorder.proc.send_signal(signal.SIGTERM)  # it writes what it holds, then the footer
    recorder.proc.wait(DRAIN_TIMEOUT_S)
    recording = read_recording(out)
    streams: dict[tuple[str, str], set[int]] = {}
    recorded = 0
    for r in recording.messages:
        if r.genuine and isinstance(r.envelope.message, VehicleState):
            recorded += 1
            streams.setdefault((r.key, r.envelope.sender), set()).add(r.envelope.seq)
    distinct = sum(len(seqs) for seqs in streams.values())
    achieved = sent / max(seconds, report["elapsed_s"])
    lost = sent - distinct
    lossless = lost == 0 and achieved >= MIN_ACHIEVED * rate
    return {"rate": rate, "sent": sent, "achieved_rate": round(achieved),
            "publish_s": round(report["elapsed_s"], 3), "recorded": recorded, "lost": lost,
            "lost_in_sequence": sum(g.missing for g in sequence_gaps(recording)),
            "duplicates": recorded - distinct, "status_count": count,
            "drain_s": round(drain_s, 2),
            "write_rate": round(recorded / (report["elapsed_s"] + drain_s)),
            "file_complete": recording.complete, "file_mb": round(out.stat().st_size / 1e6, 2),
            "lossless": lossless, "keeps_up": lossless and drain_s <= KEEPS_UP_S}


def throughput(rates: list[int], seconds: float, publishers: int,
               progress: Callable[[str], None] | None = None) -> dict:
    from fleet.runtime.bus import BusConfig, free_port, open_session
    from fleet.runtime.launcher import Launcher

    rows = []
    with tempfile.TemporaryDirectory(prefix="fleet-bench-recorder-") as tmp_name:
        tmp = Path(tmp_name)
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        launcher = Launcher(tmp / "logs")
        session = None
        try:
            launcher.start("router", ["router", "--listen", endpoint])
            session = open_session(BusConfig("client", (endpoint,), connect_timeout_ms=30_000))
            for rate in rates:
                if progress:
                    progress(f"recorder at {rate} msg/s for {seconds:g} s ...")
                row = measure_rate(endpoint, launcher, tmp, rate, publishers, seconds, session)
                rows.append(row)
                if progress:
                    progress(f"  sent {row['sent']} ({row['achieved_rate']} msg/s), recorded "
                             f"{row['recorded']}, lost {row['lost']}; the recorder caught up "
                             f"{row['drain_s']} s after the publisher stopped")
        finally:
            launcher.stop_all()
            if session is not None:
                session.close()
    best = max((r["rate"] for r in rows if r["lossless"]), default=0)
    sustained = max((r["rate"] for r in rows if r["keeps_up"]), default=0)
    return {"publishers": publishers, "seconds": seconds, "rates": rows,
            "max_lossless_rate": best, "max_sustained_rate": sustained,
            "goal_rate": GOAL_RATE, "goal_met": best >= GOAL_RATE,
            "goal_met_sustained": sustained >= GOAL_RATE}


# ----------------------------------------------------------------------- wall time


def wall_cost(layout: str = "paper", repeats: int = 3, vehicles: int = 4,
              progress: Callable[[str], None] | None = None) -> dict:
    """Fast-mode ANN fills as processes with the recorder and without, alternated (the
    order flips every repeat, so a drift in the machine's speed hits both alike), with
    `vehicles` forklifts or as many as the layout has start poses."""
    from fleet.mission.spec import Mission, MissionKind, Strategy
    from fleet.runtime.local_run import RunSpec, run_processes
    from fleet.world.layout_file import load_layout

    vehicles = min(vehicles, len(load_layout(layout).vehicle_starts))
    mission = Mission(layout=layout, kind=MissionKind.FILL, strategy=Strategy.ANN,
                      vehicles=vehicles)
    walls: dict[str, list[float]] = {"with": [], "without": []}
    digests = set()
    with tempfile.TemporaryDirectory(prefix="fleet-bench-recorder-runs-") as tmp:
        for k in range(repeats):
            order = ("without", "with") if k % 2 == 0 else ("with", "without")
            for name in order:
                run_dir = Path(tmp) / f"{name}-{k + 1}"
                start = time.perf_counter()
                outcome = run_processes(RunSpec(mission, vehicles, run_dir,
                                                record=name == "with"))
                wall = time.perf_counter() - start
                if outcome.done is None or not outcome.done.ok:
                    raise RuntimeError(f"the {name}-recorder run failed: {outcome.error}")
                walls[name].append(wall)
                digests.add(outcome.done.digest)
                if progress:
                    progress(f"fill {k + 1}/{repeats} {name} recorder: {wall:.1f} s")
    with_s, without_s = statistics.median(walls["with"]), statistics.median(walls["without"])
    cost = with_s / without_s - 1
    return {"layout": layout, "vehicles": vehicles, "repeats": repeats,
            "with_recorder_s": round(with_s, 2), "without_recorder_s": round(without_s, 2),
            "walls_with_s": [round(w, 2) for w in walls["with"]],
            "walls_without_s": [round(w, 2) for w in walls["without"]],
            "recording_cost": round(cost, 4), "goal_cost": GOAL_COST,
            "goal_met": cost < GOAL_COST, "same_record": len(digests) == 1}


def run(rates: list[int], seconds: float = 5.0, publishers: int = 4, repeats: int = 3,
        layout: str = "paper", progress: Callable[[str], None] | None = None) -> dict:
    """Both measurements; `repeats` 0 skips the wall-time one."""
    result = throughput(rates, seconds, publishers, progress)
    if repeats > 0:
        result["wall_time"] = wall_cost(layout, repeats, progress=progress)
    return result


def table(result: dict) -> str:
    lines = [f"recorder throughput: {result['publishers']} state streams for "
             f"{result['seconds']:g} s per rate (dropped under congestion)",
             f"  {'target/s':>9} {'sent':>8} {'achieved/s':>10} {'recorded':>9} {'lost':>7} "
             f"{'backlog s':>9} {'written/s':>9}  lossless  keeps up"]
    for r in result["rates"]:
        lines.append(f"  {r['rate']:>9} {r['sent']:>8} {r['achieved_rate']:>10} "
                     f"{r['recorded']:>9} {r['lost']:>7} {r['drain_s']:>9} "
                     f"{r['write_rate']:>9}  {'yes' if r['lossless'] else 'no':<8}  "
                     f"{'yes' if r['keeps_up'] else 'no'}")
    lines.append(f"  max lossless rate {result['max_lossless_rate']} msg/s, goal "
                 f"{result['goal_rate']}: {'met' if result['goal_met'] else 'missed'}; "
                 f"without a backlog {result['max_sustained_rate']} msg/s: "
                 f"{'met' if result['goal_met_sustained'] else 'missed'}")
    wall = result.get("wall_time")
    if wall:
        lines.append(f"fast-mode ANN fill of {wall['layout']} with {wall['vehicles']} "
                     f"forklifts, median of {wall['repeats']} (alternated):")
        lines.append(f"  with recorder {wall['with_recorder_s']} s, without "
                     f"{wall['without_recorder_s']} s: cost {wall['recording_cost']:+.1%}; "
                     f"goal < {wall['goal_cost']:.0%}: "
                     f"{'met' if wall['goal_met'] else 'missed'} "
                     f"(same record: {wall['same_record']})")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(_publisher_main(sys.argv[1:]))
