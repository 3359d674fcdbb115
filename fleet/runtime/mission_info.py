"""What the run is, as its dispatcher says (dispatch/mission): the processes that plan or
speak for the vehicles (agents, the VDA 5050 gateway) take the layout and the fleet from it,
as a recorder does, so every process works on the very map the dispatcher decides on."""

from __future__ import annotations

import logging
import threading
import time

import zenoh

from fleet.errors import UserError
from fleet.planning.trajectory import Pose
from fleet.wire.protocol import MissionInfo, ProtocolError, decode
from fleet.wire.topics import Keys, genuine
from fleet.world.layout import Layout
from fleet.world.layout_file import parse_layout

log = logging.getLogger("fleet.mission_info")
MISSION_WAIT_S = 120.0  # for the dispatcher to say what the mission is (as it waits for us)
ASK_TIMEOUT_S = 5.0
ASK_PERIOD_S = 0.5


def mission_layout(session: zenoh.Session, keys: Keys, timeout_s: float = MISSION_WAIT_S
                   ) -> tuple[MissionInfo, Layout, tuple[Pose, ...]]:
    """What the dispatcher says the run is (dispatch/mission, as a recorder learns it), the
    layout its mission runs on and its vehicles' start poses, so every process plans on the
    very map the dispatcher decides on; asked until it answers."""
    deadline = time.monotonic() + timeout_s
    said = False
    heard: list[MissionInfo] = []  # the dispatcher also publishes it once, when it starts:
    # heard that way too, a query the router could not route to it does not hold us up
    published = threading.Event()

    def on_sample(sample: zenoh.Sample) -> None:
        info = _believed(sample.payload.to_bytes(), str(sample.key_expr))
        if info is not None:
            heard.append(info)
            published.set()

    with session.declare_subscriber(keys.dispatch_mission, on_sample):
        while True:
            for reply in session.get(keys.dispatch_mission, timeout=ASK_TIMEOUT_S):
                if reply.ok is not None:
                    info = _believed(reply.ok.payload.to_bytes(), str(reply.ok.key_expr))
                    if info is not None:
                        heard.append(info)
            if heard:
                return _described(heard[0])
            if time.monotonic() > deadline:
                raise UserError(f"no dispatcher said what the mission is (on "
                                f"{keys.dispatch_mission}) within {timeout_s:g} s")
            if not said:
                log.info("waiting for the dispatcher to say what the mission is")
                said = True
            if published.wait(ASK_PERIOD_S):  # else asks again: it may not be up yet
                return _described(heard[0])


def _described(info: MissionInfo) -> tuple[MissionInfo, Layout, tuple[Pose, ...]]:
    try:
        starts = tuple(Pose.parse(p) for p in info.starts)
        return info, parse_layout(info.layout_toml, f"the mission's layout "
                                  f"{info.layout}"), starts
    except ValueError as exc:  # a LayoutError too
        raise UserError(f"the dispatcher's mission: {exc}") from None


def _believed(payload: bytes, key: str) -> MissionInfo | None:
    """The run's description in a reply or a sample, believed only from the dispatcher."""
    try:
        envelope = decode(payload)
    except ProtocolError as exc:
        log.warning("rejected a message on %s: %s", key, exc)
        return None
    if not (isinstance(envelope.message, MissionInfo) and genuine(key, envelope)):
        log.warning("ignored a %s from %r on %s: only the dispatcher says what the mission "
                    "is", envelope.message.TYPE, envelope.sender, key)
        return None
    return envelope.message
