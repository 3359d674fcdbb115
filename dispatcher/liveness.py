"""Who is alive: the liveliness tokens of the agents and the reservation service."""

from __future__ import annotations

import threading
import time

import zenoh

from fleet.errors import UserError
from fleet.wire.topics import Keys

# An agent whose token is here may not yet be reachable: when a cut link or host comes back,
# zenoh may propagate the token before the queryable (eclipse-zenoh/zenoh#588, #2767), so a
# request nobody serves is asked again for this long while the token stays.
UNSERVED_RETRY_S = 10.0


class ParticipantLost(UserError):
    """A process the mission depends on went away (its liveliness token is gone)."""


class Liveness:
    def __init__(self, session: zenoh.Session, keys: Keys) -> None:
        self.keys = keys
        self.alive: set[int] = set()
        self.appeared: dict[int, int] = {}  # how many times each token came (back)
        self.service_alive = False
        self.recorder_alive = False
        self.changed = threading.Condition()
        self._vehicles = session.liveliness().declare_subscriber(
            keys.vehicle_alive("*"), self._on_vehicle, history=True)
        self._service = session.liveliness().declare_subscriber(
            keys.reservation_alive, self._on_service, history=True)
        self._recorder = session.liveliness().declare_subscriber(
            keys.recorder_alive, self._on_recorder, history=True)

    def _on_vehicle(self, sample: zenoh.Sample) -> None:
        vehicle = Keys.vehicle_in(str(sample.key_expr))
        if vehicle is None:
            return
        with self.changed:
            if sample.kind == zenoh.SampleKind.PUT:
                if vehicle not in self.alive:  # history and live may both report a token
                    self.appeared[vehicle] = self.appeared.get(vehicle, 0) + 1
                self.alive.add(vehicle)
            else:
                self.alive.discard(vehicle)
            self.changed.notify_all()

    def _on_service(self, sample: zenoh.Sample) -> None:
        with self.changed:
            self.service_alive = sample.kind == zenoh.SampleKind.PUT
            self.changed.notify_all()

    def _on_recorder(self, sample: zenoh.Sample) -> None:
        with self.changed:
            self.recorder_alive = sample.kind == zenoh.SampleKind.PUT
            self.changed.notify_all()

    def wait_for_recorder(self, timeout: float) -> None:
        with self.changed:
            if not self.changed.wait_for(lambda: self.recorder_alive, timeout):
                raise ParticipantLost(f"no recorder has run for {timeout:g} s")

    def wait_for_service(self, timeout: float) -> None:
        with self.changed:
            if not self.changed.wait_for(lambda: self.service_alive, timeout):
                raise ParticipantLost(f"no reservation service came up within {timeout:g} s")

    def wait_for(self, vehicles: list[int], timeout: float) -> None:
        with self.changed:
            if not self.changed.wait_for(lambda: set(vehicles) <= self.alive, timeout):
                missing = sorted(set(vehicles) - self.alive)
                raise ParticipantLost(f"forklift agents {missing} did not come up within "
                                      f"{timeout:g} s")

    def appearances(self, vehicle: int) -> int:
        """How many times the vehicle's token has come (back) so far."""
        with self.changed:
            return self.appeared.get(vehicle, 0)

    def wait_back(self, vehicle: int, appeared_before: int, quiet_s: float,
                  timeout: float) -> None:
        """Once a vehicle's link was silent (its process stopped, its link cut): return when
        it is known which session it is on, that is when its token came back since
        (`appeared_before`: how many times it had come before), or when it has stayed for
        `quiet_s` from now (long enough for its router to have dropped a session whose
        lease ran out during the silence, and said so)."""
        now = time.monotonic()
        quiet_until, deadline = now + quiet_s, now + timeout
        with self.changed:
            while not (vehicle in self.alive and (self.appeared.get(vehicle, 0) > appeared_before
                                                  or now >= quiet_until)):
                if now >= deadline:
                    raise ParticipantLost(f"the agent of vehicle {vehicle} did not come back "
                                          f"within {timeout:g} s")
                wake = deadline if vehicle not in self.alive else min(quiet_until, deadline)
                self.changed.wait(wake - now)
                now = time.monotonic()

    def wait_gone(self, vehicle: int, timeout: float) -> bool:
        """Give the liveliness subscriber a moment to hear of a vehicle that just went."""
        with self.changed:
            return self.changed.wait_for(lambda: vehicle not in self.alive, timeout)

    def close(self) -> None:
        self._vehicles.undeclare()
        self._service.undeclare()
        self._recorder.undeclare()
