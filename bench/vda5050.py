"""`fleet bench vda5050`: a fleet of forklifts behind the VDA 5050 gateway under load.

A generated warehouse with a park per forklift, `fleet run --dispatch external` on a
mosquitto of its own, and a measuring master (a paho client of this process) that sends
every forklift an order at once, from its park to the nearest free stack node, then, once
every one is driven, an order back to its park (the agents warm: each has planned once),
and reads every state:

- order-to-motion latency: from an order's publication to the forklift's first state with
  `driving` true (the gateway's check, the agent's plan and commit, the first step), p50 and
  p99 over the fleet, for the first orders (fresh agents) and the second (warm ones);
- states per second held: every state received while the fleet works its orders, over that
  window (states go out on events and every 10 s), and the visualizations (every 0.5 s);
- messages lost: the gaps in each forklift's state and visualization headerIds (they count
  up by one).
"""

from __future__ import annotations

import itertools
import json
import math
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import paho.mqtt.client as mqtt

from fleet.errors import UserError
from fleet.runtime.mqtt_broker import start_mosquitto, stop
from fleet.vda5050.map import STACK, nodes, released_order
from fleet.vda5050.messages import timestamp
from fleet.world.generator import Shape, generate_toml
from fleet.world.layout_file import load_layout

ONLINE_TIMEOUT_S = 600.0  # every agent up and its AGV online (50 processes on two cores)
DONE_TIMEOUT_S = 900.0  # every order driven


class _Listener:
    """The measuring master's ears: each forklift's states as they come."""

    def __init__(self, port: int, manufacturer: str) -> None:
        self.lock = threading.Lock()
        self.online: set[str] = set()
        self.states: dict[str, list[tuple[float, dict]]] = {}
        self.visualizations: dict[str, list[tuple[float, int]]] = {}  # (when, headerId)
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="bench-master")
        root = f"uagv/v2/{manufacturer}/+"
        self.client.on_connect = lambda c, *_: c.subscribe([
            (f"{root}/state", 0), (f"{root}/visualization", 0), (f"{root}/connection", 1)])
        self.client.on_message = self._on_message
        self.client.connect("127.0.0.1", port)
        self.client.loop_start()

    def _on_message(self, client, userdata, message) -> None:
        now = time.monotonic()
        serial, topic = message.topic.split("/")[-2:]
        body = json.loads(message.payload)
        with self.lock:
            if topic == "connection" and body.get("connectionState") == "ONLINE":
                self.online.add(serial)
            elif topic == "state":
                self.states.setdefault(serial, []).append((now, body))
            elif topic == "visualization":
                self.visualizations.setdefault(serial, []).append((now, body["headerId"]))

    def wait(self, what: str, until: Callable[[], bool], timeout_s: float,
             fleet: subprocess.Popen, log: Path) -> None:
        deadline = time.monotonic() + timeout_s
        while True:
            with self.lock:
                if until():
                    return
            if fleet.poll() is not None:
                said = log.read_text(errors="replace").strip().splitlines()[-3:]
                raise UserError(f"waiting for {what}, the fleet run ended (exit "
                                f"{fleet.returncode}): " + " / ".join(said))
            if time.monotonic() > deadline:
                raise UserError(f"{what} did not happen within {timeout_s:g} s")
            time.sleep(0.2)  # a poll of what the MQTT thread collected, not a synchronisation

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


def _orders(layout_path: Path, vehicles: int) -> tuple[dict[int, dict], dict[int, dict]]:
    """Each forklift's two orders: from its park to the nearest stack node no other takes,
    and back."""
    layout = load_layout(str(layout_path))
    found = nodes(layout)
    stacks = [n for n in found if n.place == STACK]
    taken: set = set()
    there, back = {}, {}

    for v in range(1, vehicles + 1):
        park = next(n for n in found if n.node_id == f"park-{v}")
        target = min((n for n in stacks if n.cell not in taken),
                     key=lambda n: math.hypot(n.x - park.x, n.y - park.y))
        taken.add(target.cell)
        there[v] = released_order(f"bench-{v}", 0, [park, target], layout.name)
        back[v] = released_order(f"back-{v}", 0, [target, park], layout.name)
    return there, back


def _percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, math.ceil(q * len(ordered)) - 1)]


def run(vehicles: int = 50, progress: Callable[[str], None] | None = None) -> dict:
    say = progress or (lambda line: None)
    manufacturer = "fleet-emulator"
    aisles = max(1, math.ceil(vehicles / 6))  # six parks an aisle at depth 8
    shape = Shape(aisles=aisles, depth=8, lane_depth=5, vehicles=vehicles)
    with tempfile.TemporaryDirectory(prefix="fleet-bench-vda5050-") as tmp:
        folder = Path(tmp)
        layout_path = folder / "bench.toml"
        layout_path.write_text(generate_toml(shape, "bench-vda5050"))
        rounds = _orders(layout_path, vehicles)
        broker = start_mosquitto(folder / "broker")
        listener = _Listener(broker.port, manufacturer)
        log_path = folder / "fleet-run.log"
        log = log_path.open("wb")
        fleet = subprocess.Popen([sys.executable, "-m", "fleet", "run", "--layout",
                                  str(layout_path), "--vehicles", str(vehicles), "--dispatch",
                                  "external", "--mqtt", broker.url, "--out",
                                  str(folder / "run"), "--quiet"],
                                 stdout=log, stderr=subprocess.STDOUT)
        try:
            say(f"starting {vehicles} forklifts and the gateway")
            started = time.monotonic()
            listener.wait(f"{vehicles} forklifts online",
                          lambda: len(listener.online) >= vehicles, ONLINE_TIMEOUT_S, fleet,
                          log_path)
            up_s = time.monotonic() - started
            sent: list[dict[str, float]] = []
            header = itertools.count()
            say(f"all online after {up_s:.0f} s")
            for k, orders in enumerate(rounds):
                say(f"sending {vehicles} orders at once ({'fresh' if k == 0 else 'warm'} "
                    "agents)")
                sent.append({})
                for v, order in orders.items():
                    serial = f"forklift-{v}"
                    message = {"headerId": next(header), "timestamp": timestamp(time.time()),
                               "version": "2.0.0", "manufacturer": manufacturer,
                               "serialNumber": serial, **order}
                    sent[-1][serial] = time.monotonic()
                    listener.client.publish(f"uagv/v2/{manufacturer}/{serial}/order",
                                            json.dumps(message), qos=1)

                def finished(v: int, order_id: str) -> bool:
                    return any(s["orderId"] == order_id and not s["nodeStates"]
                               and not s["driving"]
                               for _, s in listener.states.get(f"forklift-{v}", []))

                listener.wait("every order driven", lambda orders=orders: all(
                    finished(v, o["orderId"]) for v, o in orders.items()), DONE_TIMEOUT_S,
                    fleet, log_path)
                say(f"every order driven in {time.monotonic() - min(sent[-1].values()):.0f} s")
            t0, t1 = min(sent[0].values()), time.monotonic()
        finally:
            if fleet.poll() is None:
                fleet.send_signal(signal.SIGINT)
                try:
                    fleet.wait(timeout=120)
                except subprocess.TimeoutExpired:
                    fleet.kill()
            listener.close()
            stop(broker)
            log.close()
        with listener.lock:
            states = {k: list(v) for k, v in listener.states.items()}
            shown = {k: list(v) for k, v in listener.visualizations.items()}
    latencies: list[list[float]] = [[], []]  # fresh agents, warm ones
    for k, times in enumerate(sent):
        for serial, t_sent in times.items():
            first = next((t for t, s in states.get(serial, []) if t >= t_sent and s["driving"]),
                         None)
            if first is not None:
                latencies[k].append(first - t_sent)
    cold, warm = latencies
    window = [t for series in states.values() for t, _ in series if t0 <= t <= t1]
    lost = sum(max(0, b["headerId"] - a["headerId"] - 1)
               for series in states.values()
               for (_, a), (_, b) in itertools.pairwise(series))
    shown_window = [t for series in shown.values() for t, _ in series if t0 <= t <= t1]
    shown_lost = sum(max(0, b - a - 1) for series in shown.values()
                     for (_, a), (_, b) in itertools.pairwise(series))
    return {"vehicles": vehicles, "layout": f"generated {shape.cols} x {shape.rows} cells",
            "startup_s": round(up_s, 1), "orders": len(sent[0]), "moved": len(cold),
            "latency_p50_s": round(statistics.median(cold), 3) if cold else None,
            "latency_p99_s": round(_percentile(cold, 0.99), 3) if cold else None,
            "warm_moved": len(warm),
            "warm_latency_p50_s": round(statistics.median(warm), 3) if warm else None,
            "warm_latency_p99_s": round(_percentile(warm, 0.99), 3) if warm else None,
            "window_s": round(t1 - t0, 1), "states": len(window),
            "states_per_s": round(len(window) / (t1 - t0), 1),
            "states_lost": lost,
            "visualizations_per_s": round(len(shown_window) / (t1 - t0), 1),
            "visualizations_lost": shown_lost}
