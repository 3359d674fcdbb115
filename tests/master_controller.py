"""A VDA 5050 master controller nobody here wrote, for the tests: vda-5050-lib's
MasterController (Siemens, npm) in tests/vda5050_master/master.mjs, run as a child that takes
commands and reports what it sees as JSON lines.

    with running_master("mqtt://127.0.0.1:PORT", tmp_path, "fleet-emulator") as master:
        master.send(cmd="order", serialNumber="forklift-1", order={...}, id=1)
        master.expect("the order sent", lambda e: e.get("id") == 1)
"""

from __future__ import annotations

import functools
import itertools
import json
import os
import queue
import shutil
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from fleet.vda5050.map import Node, edge_id, node_position, nodes
from fleet.vda5050.messages import serial_number
from fleet.world.layout_file import load_layout

MASTER_DIR = Path(__file__).parent / "vda5050_master"
DEADLINE = 10.0  # s for any one awaited event; each comes within some 100 ms here

Message = dict[str, Any]


@functools.cache
def map_nodes(layout: str) -> dict[str, Node]:
    return {n.node_id: n for n in nodes(load_layout(layout))}


def serial(vehicle: int, kind: str = "forklift") -> str:
    return serial_number(kind, vehicle)


def order(order_id: str, path: list[str], *, update: int = 0, first_sequence: int = 0,
          actions: dict[int, list[str]] | None = None, released: int | None = None,
          layout: str = "paper") -> Message:
    """An order along `path` (node ids of `layout`'s map; an unknown id goes without a
    position); `actions` by the node's place in the path (pick/drop, HARD), the first
    `released` nodes in the base (default all)."""
    known = map_nodes(layout)
    actions = actions or {}
    ids = itertools.count()
    released = len(path) if released is None else released

    def node(k: int, node_id: str) -> Message:
        return {"nodeId": node_id, "sequenceId": first_sequence + 2 * k,
                "released": k < released,
                **({"nodePosition": node_position(known[node_id], layout)}
                   if node_id in known else {}),
                "actions": [{"actionId": f"{order_id}-{update}-{kind}-{next(ids)}",
                             "actionType": kind, "blockingType": "HARD"}
                            for kind in actions.get(k, [])]}

    def edge(k: int, a: str, b: str) -> Message:
        return {"edgeId": edge_id(a, b), "sequenceId": first_sequence + 2 * k + 1,
                "released": k + 1 < released, "startNodeId": a, "endNodeId": b, "actions": []}

    return {"orderId": order_id, "orderUpdateId": update,
            "nodes": [node(k, n) for k, n in enumerate(path)],
            "edges": [edge(k, a, b) for k, (a, b) in enumerate(itertools.pairwise(path))]}


@dataclass
class Master:
    """master.mjs as a child: commands in as JSON lines, its events out as JSON lines."""

    process: subprocess.Popen[str]
    stderr: Path
    events: queue.Queue[Message | None] = field(default_factory=queue.Queue)
    seen: list[Message] = field(default_factory=list)
    reader: threading.Thread = field(init=False)

    def __post_init__(self) -> None:
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            try:
                self.events.put(json.loads(line))
            except json.JSONDecodeError:
                self.events.put({"event": "notJson", "line": line})
        self.events.put(None)  # its stdout closed: it ended

    def send(self, **command: Any) -> None:
        assert self.process.stdin is not None
        self.process.stdin.write(json.dumps(command) + "\n")
        self.process.stdin.flush()

    def expect(self, what: str, match: Callable[[Message], bool],
               within: float = DEADLINE) -> Message:
        """The next event that `match`es, read within `within` seconds; the events before it
        are kept in `seen`."""
        deadline = time.monotonic() + within
        while (left := deadline - time.monotonic()) > 0:
            try:
                event = self.events.get(timeout=left)
            except queue.Empty:
                break
            if event is None:
                self.events.put(None)
                break
            self.seen.append(event)
            if match(event):
                return event
        raise AssertionError(
            f"the master did not report {what} within {within:g} s; it reported:\n"
            + "\n".join(json.dumps(e) for e in self.seen[-20:])
            + f"\nits stderr: {self.stderr.read_text(errors='replace')[-2000:]}"
        )

    def find(self, what: str, match: Callable[[Message], bool], within: float = DEADLINE
             ) -> Message:
        """The first event that `match`es, seen already or still to come."""
        for event in self.seen:
            if match(event):
                return event
        return self.expect(what, match, within)


@contextmanager
def running_master(broker: str, tmp_path: Path, manufacturer: str) -> Iterator[Master]:
    node = shutil.which("node")
    if node is None:
        pytest.fail("node is not installed: the VDA 5050 master controller runs on Node")
    if not (MASTER_DIR / "node_modules" / "vda-5050-lib").is_dir():
        pytest.fail(f"vda-5050-lib is not installed: run `npm ci` in {MASTER_DIR} "
                    "(.ci/run does)")
    port = broker.rsplit(":", 1)[1]
    stderr = tmp_path / "master.stderr"
    with stderr.open("w") as err:
        process = subprocess.Popen(
            [node, str(MASTER_DIR / "master.mjs"), "--host", "127.0.0.1", "--port", port,
             "--interface", "uagv", "--manufacturer", manufacturer],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=err, text=True,
            env={**os.environ, "NO_COLOR": "1"},
        )
    master = Master(process, stderr)
    try:
        master.expect("ready", lambda e: e["event"] in ("ready", "fatal"))
        assert master.seen[-1]["event"] == "ready", master.seen[-1]
        yield master
    finally:
        if process.poll() is None:
            master.send(cmd="quit")
            try:
                process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        master.reader.join(timeout=5)  # it reads to the end of stdout, then let go of the pipe
        for pipe in (process.stdin, process.stdout):
            if pipe is not None:
                pipe.close()
