"""Access control on a real router (fleet.runtime.access): a router process with the run's ACL and
user/password dictionary, a client session per principal, and proofs that it refuses what a
principal may not do while the legitimate flows still arrive.

Refusals are silent (the router drops the message), so a refusal is proven by what comes
after it on the same path: the same session sends the forbidden message, then a permitted
marker; zenoh keeps one session's messages in order through the router, so once the marker
is received the forbidden one would have been too. Before a receiver is relied on, its
session does a round trip through the router (a query it may send), which the router handles
after the declarations that session made before."""

import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest
import zenoh

from fleet.runtime.access import (
    OPERATOR,
    configure_client,
    generate_credentials,
    principals,
    router_acl,
    write_dictionary,
)
from fleet.runtime.bus import RELIABLE, BusConfig, free_port, wait_alive
from fleet.wire.topics import (
    CLOCK,
    DISPATCHER,
    GATEWAY,
    INJECTOR,
    RECORDER,
    RESERVATION,
    TOPICS,
    Keys,
    TopicKind,
    vehicle_sender,
)

ROOT = Path(__file__).resolve().parent.parent
VEHICLES = 3
TIMEOUT_S = 10.0

ROUTER = """
import json, sys
import zenoh
from fleet.runtime.access import configure_router
from fleet.runtime.bus import BusConfig
endpoint, acl, dictionary = sys.argv[1:]
config = BusConfig("router", (), (endpoint,)).zenoh_config()
with open(acl) as f:
    configure_router(config, json.load(f), dictionary)
session = zenoh.open(config)
print("ready", flush=True)
sys.stdin.read()  # until the test closes our stdin
session.close()
"""


def request_key(keys: Keys, principal: str) -> str:
    return f"{keys.root}/reservation/request/{principal}"


class Inbox:
    """What a subscriber received, as (key, payload) pairs, and a way to wait for one."""

    def __init__(self) -> None:
        self.samples: list[tuple[str, str]] = []
        self.changed = threading.Condition()

    def __call__(self, sample: zenoh.Sample) -> None:
        with self.changed:
            self.samples.append((str(sample.key_expr), sample.payload.to_string()))
            self.changed.notify_all()

    def wait_for(self, payload: str) -> bool:
        with self.changed:
            return self.changed.wait_for(lambda: payload in self.payloads(), TIMEOUT_S)

    def wait_for_key(self, key: str) -> bool:
        with self.changed:
            return self.changed.wait_for(lambda: key in self.seen_keys(), TIMEOUT_S)

    def payloads(self) -> list[str]:
        with self.changed:
            return [p for _, p in self.samples]

    def seen_keys(self) -> list[str]:
        with self.changed:
            return [k for k, _ in self.samples]


def ask(session: zenoh.Session, key: str, payload: str = "") -> list[str]:
    """Every reply to a get (errors as 'ERR:...'); a get the router refuses ends at once with
    none, like one nobody serves."""
    return [reply.ok.payload.to_string() if reply.ok is not None
            else "ERR:" + reply.err.payload.to_string()
            for reply in session.get(key, payload=payload, timeout=TIMEOUT_S,
                                     consolidation=zenoh.ConsolidationMode.NONE)]


class Fleet:
    """The router process, a session per principal, and the servers the tests talk to: the
    reservation service (answers any request key), forklift 2's agent (task and inject; a
    lifting AGV's serves its task key only), the dispatcher's mission queryable. `lifting`:
    the rules of a seed-004 run."""

    def __init__(self, tmp: Path, lifting: bool = False) -> None:
        self.lifting = lifting
        self.keys = Keys(f"acl{os.getpid()}{'l' if lifting else ''}")
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.credentials = generate_credentials(self.keys.run, VEHICLES)
        dictionary = write_dictionary(self.credentials.logins.values(), tmp / "users.txt")
        acl = tmp / "acl.json"
        acl.write_text(json.dumps(router_acl(self.keys.root, VEHICLES, lifting)))
        self.log = tmp / "router.log"
        with open(self.log, "wb") as log:
            self.router = subprocess.Popen(
                [sys.executable, "-c", ROUTER, self.endpoint, str(acl), str(dictionary)],
                cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log,
                text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
        self.sessions: dict[str, zenoh.Session] = {}
        self.declared: list = []
        self.asked: dict[str, list[tuple[str, str]]] = {}  # server: (key, payload) queries

    def start(self) -> None:
        ready = self.router.stdout.readline()
        assert ready.strip() == "ready", f"the router did not start: {self.log.read_text()}"
        for principal in principals(VEHICLES):
            self.sessions[principal] = self.open(principal)
        keys = self.keys
        self.serve(RESERVATION, f"{keys.root}/reservation/request/*")
        self.declared.append(self[RESERVATION].liveliness().declare_token(
            keys.reservation_alive))
        self.serve(vehicle_sender(2), keys.vehicle_task(2))
        if not self.lifting:
            self.serve(vehicle_sender(2), keys.vehicle_inject(2))
        self.declared.append(self[vehicle_sender(2)].liveliness().declare_token(
            keys.vehicle_alive(2)))
        self.serve(DISPATCHER, keys.dispatch_mission)
        self.declared.append(self[DISPATCHER].liveliness().declare_token(
            keys.dispatcher_alive))
        # A token reaches the router after the queryables its session declared before it.
        for token in (keys.reservation_alive, keys.vehicle_alive(2), keys.dispatcher_alive):
            assert wait_alive(self[OPERATOR], token, TIMEOUT_S), token

    def __getitem__(self, principal: str) -> zenoh.Session:
        return self.sessions[principal]

    def open(self, principal: str | None, password: str | None = None,
             timeout_ms: int = 10_000) -> zenoh.Session:
        config = BusConfig("client", (self.endpoint,),
                           connect_timeout_ms=timeout_ms).zenoh_config()
        if principal is not None:
            login = self.credentials[principal]
            configure_client(config, login.user, password or login.password)
        return zenoh.open(config)

    def serve(self, principal: str, key: str) -> None:
        asked = self.asked.setdefault(principal, [])

        def answer(query: zenoh.Query) -> None:
            payload = query.payload.to_string() if query.payload is not None else ""
            asked.append((str(query.key_expr), payload))
            query.reply(query.key_expr, f"{principal} answers {payload}")

        self.declared.append(self[principal].declare_queryable(key, answer))

    def sync(self, principal: str) -> None:
        """A round trip through the router from `principal`'s session: after it, the router
        has handled every declaration that session made before."""
        keys = self.keys
        key = {DISPATCHER: request_key(keys, DISPATCHER), RECORDER: keys.dispatch_mission,
               OPERATOR: keys.vehicle_inject(2)}.get(principal, request_key(keys, principal))
        assert ask(self[principal], key, "sync"), f"{principal}'s round trip on {key}"

    def stop(self) -> None:
        for declared in self.declared:
            declared.undeclare()
        for session in self.sessions.values():  # before the router: see fleet/runtime/router.py
            session.close()
        self.router.stdin.close()
        assert self.router.wait(timeout=30) == 0


def _running(tmp_path_factory, lifting: bool):
    fleet = Fleet(tmp_path_factory.mktemp("access"), lifting)
    try:
        fleet.start()
        yield fleet
    finally:
        if fleet.router.poll() is None:
            fleet.stop()


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    yield from _running(tmp_path_factory, lifting=False)


@pytest.fixture(scope="module")
def lifting_fleet(tmp_path_factory):
    """The rules of a seed-004 run: lifting AGVs and their dispatcher."""
    yield from _running(tmp_path_factory, lifting=True)


@pytest.fixture(params=["forklifts", "lifting"])
def either_fleet(request):
    """What holds for a forklift's and a lifting AGV's login alike, proven on both rules."""
    return request.getfixturevalue("fleet" if request.param == "forklifts" else "lifting_fleet")


def test_credentials_and_acl_shape(tmp_path):
    credentials = generate_credentials("r", 2)
    assert set(credentials.logins) == {"dispatcher", "reservation", "recorder", "operator",
                                       "vda5050", "vehicle-1", "vehicle-2"}
    passwords = [login.password for login in credentials.logins.values()]
    assert len(set(passwords)) == len(passwords)
    assert all(len(p) >= 32 and ":" not in p for p in passwords)
    assert generate_credentials("r", 2).vehicle(1).password != credentials.vehicle(1).password
    path = write_dictionary(credentials.logins.values(), tmp_path / "d")
    assert path.stat().st_mode & 0o777 == 0o600
    lines = path.read_text().splitlines()
    assert sorted(lines) == sorted(f"{u}:{login.password}"
                                   for u, login in credentials.logins.items())
    acl = router_acl("fleet/r", 2)
    assert acl["enabled"] and acl["default_permission"] == "deny"
    rule_ids = [rule["id"] for rule in acl["rules"]]
    assert len(set(rule_ids)) == len(rule_ids)
    assert {p["id"] for p in acl["policies"]} == set(credentials.logins)
    assert all(k.startswith("fleet/r/") for rule in acl["rules"] for k in rule["key_exprs"])
    json.dumps(acl)  # JSON-able


def test_no_or_wrong_credentials_cannot_connect(either_fleet):
    fleet = either_fleet
    with pytest.raises(zenoh.ZError):
        fleet.open(None, timeout_ms=1000)
    with pytest.raises(zenoh.ZError):  # a user with another's password
        fleet.open(vehicle_sender(1), fleet.credentials.vehicle(2).password, timeout_ms=1000)
    fleet.open(vehicle_sender(1), timeout_ms=1000).close()  # the control: the right one does


def test_vehicle_publishes_only_its_own_state(fleet):
    keys, v1, v2 = fleet.keys, fleet[vehicle_sender(1)], fleet[vehicle_sender(2)]
    inbox = Inbox()
    subscriber = fleet[DISPATCHER].declare_subscriber(keys.vehicle_state("*"), inbox)
    try:
        fleet.sync(DISPATCHER)
        # The control: the key is delivered when its owner publishes it.
        v2.put(keys.vehicle_state(2), "vehicle 2 by vehicle 2")
        assert inbox.wait_for("vehicle 2 by vehicle 2")
        for key in (keys.vehicle_state(2), keys.vehicle_state("*")):
            v1.put(key, "forged by vehicle 1", congestion_control=RELIABLE)
        v1.put(keys.vehicle_state(1), "vehicle 1 by vehicle 1", congestion_control=RELIABLE)
        assert inbox.wait_for("vehicle 1 by vehicle 1")
        assert "forged by vehicle 1" not in inbox.payloads()
    finally:
        subscriber.undeclare()


def test_vehicle_commits_only_under_its_own_name(either_fleet):
    fleet = either_fleet
    keys, v1 = fleet.keys, fleet[vehicle_sender(1)]
    asked = fleet.asked[RESERVATION]
    asked.clear()
    assert ask(v1, request_key(keys, vehicle_sender(2)), "forged") == []
    assert ask(v1, f"{keys.root}/reservation/request/*", "forged") == []
    assert ask(v1, request_key(keys, vehicle_sender(1)), "commit") == [
        "reservation answers commit"]
    # The forged gets went first on the same path: the service would have seen them first.
    assert asked == [(request_key(keys, vehicle_sender(1)), "commit")]


def test_only_the_dispatcher_assigns_tasks_and_only_the_operator_injects(fleet):
    keys = fleet.keys
    asked = fleet.asked[vehicle_sender(2)]
    asked.clear()
    assert ask(fleet[vehicle_sender(1)], keys.vehicle_task(2), "forged") == []
    assert ask(fleet[OPERATOR], keys.vehicle_task(2), "forged") == []
    assert ask(fleet[DISPATCHER], keys.vehicle_inject(2), "forged") == []
    assert ask(fleet[vehicle_sender(1)], keys.vehicle_inject(2), "forged") == []
    assert ask(fleet[DISPATCHER], keys.vehicle_task(2), "task") == ["vehicle-2 answers task"]
    assert ask(fleet[OPERATOR], keys.vehicle_inject(2), "fault") == ["vehicle-2 answers fault"]
    # Each forged get ended (no reply) before the next get was sent.
    assert asked == [(keys.vehicle_task(2), "task"), (keys.vehicle_inject(2), "fault")]


def test_only_the_dispatcher_asks_a_lifting_agv(lifting_fleet):
    """Seed 004: AGV 2's agent takes and lets go of its cells and plans its legs only when
    the dispatcher asks (CellRequest, RouteRequest on its task key); AGV 1, the gateway
    (which may ask a forklift for legs), the operator, the recorder and the service ask it
    in vain."""
    fleet, keys = lifting_fleet, lifting_fleet.keys
    asked = fleet.asked[vehicle_sender(2)]
    asked.clear()
    for principal in (vehicle_sender(1), GATEWAY, OPERATOR, RECORDER, RESERVATION):
        assert ask(fleet[principal], keys.vehicle_task(2), "forged take") == [], principal
    assert ask(fleet[DISPATCHER], keys.vehicle_task(2), "take") == ["vehicle-2 answers take"]
    # Each forged get ended (no reply) before the next get was sent.
    assert asked == [(keys.vehicle_task(2), "take")]


def test_a_lifting_agv_serves_no_fault_injection(lifting_fleet):
    """A lifting AGV's agent takes no injected fault: its inject queryable never reaches the
    router, so the operator's get finds nobody (a forklift's would be answered)."""
    fleet, keys = lifting_fleet, lifting_fleet.keys
    v2 = fleet[vehicle_sender(2)]
    heard: list[str] = []

    def answer(query: zenoh.Query) -> None:
        heard.append(str(query.key_expr))
        query.reply(keys.vehicle_inject(2), "vehicle 2 takes the fault")

    queryable = v2.declare_queryable(keys.vehicle_inject(2), answer)
    try:
        fleet.sync(vehicle_sender(2))  # the router has handled the declaration
        assert ask(fleet[OPERATOR], keys.vehicle_inject(2), "fault") == []
        assert heard == []
    finally:
        queryable.undeclare()


def test_vehicle_asks_what_the_mission_is(either_fleet):
    """A forklift (or lifting AGV) takes its layout from the dispatcher's description of the
    run."""
    fleet = either_fleet
    keys = fleet.keys
    assert ask(fleet[vehicle_sender(1)], keys.dispatch_mission, "info") == \
        ["dispatcher answers info"]


def test_vehicle_cannot_pose_as_another(either_fleet):
    """Forklift 1 serves forklift 3's task key, declares its token and answers as it: none of
    it reaches the dispatcher, while forklift 1's own queryable, token and reply do (so a
    lifting AGV's login cannot answer the dispatcher's CellRequest or RouteRequest for
    another AGV)."""
    fleet = either_fleet
    keys, v1 = fleet.keys, fleet[vehicle_sender(1)]

    def answer(query: zenoh.Query) -> None:
        if str(query.key_expr) == keys.vehicle_task("*"):  # may answer on any vehicle's key
            query.reply(keys.vehicle_task(3), "forged reply as vehicle 3")
        query.reply(keys.vehicle_task(1), "vehicle 1 answers")

    def forge(query: zenoh.Query) -> None:
        query.reply(keys.vehicle_task(3), "forged reply as vehicle 3")

    # The forged queryable also gets what reaches forklift 1's session (the query for its
    # own key below): a session hands a query to each of its queryables that match.
    declared = [v1.declare_queryable(keys.vehicle_task(3), forge),
                v1.declare_queryable(keys.vehicle_task(1), answer),
                v1.liveliness().declare_token(keys.vehicle_alive(3)),
                v1.liveliness().declare_token(keys.vehicle_alive(1))]
    alive = Inbox()
    watch = fleet[DISPATCHER].liveliness().declare_subscriber(keys.vehicle_alive("*"), alive,
                                                             history=True)
    try:
        # vehicle 1's own token came after the forged one, through the same router.
        assert alive.wait_for_key(keys.vehicle_alive(1))
        assert keys.vehicle_alive(3) not in alive.seen_keys()
        dispatcher = fleet[DISPATCHER]
        assert ask(dispatcher, keys.vehicle_task(3)) == []
        assert ask(dispatcher, keys.vehicle_task(1)) == ["vehicle 1 answers"]
        # A wildcard get: forklift 1's forged reply goes before its own, and is dropped. A
        # reply is checked on its own key: forklift 2 answers on the query's key (as the
        # agents do), vehicle/*/task, which it may not, so its reply is dropped too.
        assert ask(dispatcher, keys.vehicle_task("*"), "all") == ["vehicle 1 answers"]
        assert fleet.asked[vehicle_sender(2)][-1] == (keys.vehicle_task("*"), "all")
    finally:
        watch.undeclare()
        for d in declared:
            d.undeclare()


def test_recorder_only_reads(fleet):
    keys, recorder = fleet.keys, fleet[RECORDER]
    seen_by_operator = Inbox()
    subscriber = fleet[OPERATOR].declare_subscriber(keys.everything, seen_by_operator)
    recorded = Inbox()
    recording = recorder.declare_subscriber(keys.everything, recorded)
    try:
        fleet.sync(OPERATOR)
        fleet.sync(RECORDER)
        for key in (keys.dispatch_done, keys.dispatch_mission, keys.vehicle_state(1),
                    keys.clock, f"{keys.root}/**"):
            recorder.put(key, "forged by the recorder", congestion_control=RELIABLE)
        recorder.put(keys.recorder_status, "recorder status", congestion_control=RELIABLE)
        assert seen_by_operator.wait_for("recorder status")
        assert "forged by the recorder" not in seen_by_operator.payloads()
        # What it reads: the dispatcher's result and, asked, the mission.
        fleet[DISPATCHER].put(keys.dispatch_done, "mission done", congestion_control=RELIABLE)
        assert recorded.wait_for("mission done")
        assert ask(recorder, keys.dispatch_mission, "info") == ["dispatcher answers info"]
    finally:
        recording.undeclare()
        subscriber.undeclare()


def test_clock_and_acks(fleet):
    """Only the dispatcher ticks the clock; the operator acks only as the injector; and a
    forklift hears the clock but not the dispatcher's other streams."""
    keys = fleet.keys
    v1 = fleet[vehicle_sender(1)]
    heard = Inbox()
    # Declared first, refused: forklift 1 may not read the dispatcher's streams.
    subscribers = [v1.declare_subscriber(f"{keys.root}/dispatch/**", heard),
                   v1.declare_subscriber(keys.clock, heard)]
    acks = Inbox()
    subscribers.append(fleet[DISPATCHER].declare_subscriber(keys.clock_ack("*"), acks))
    try:
        fleet.sync(vehicle_sender(1))
        fleet.sync(DISPATCHER)
        operator = fleet[OPERATOR]
        operator.put(keys.clock, "forged tick", congestion_control=RELIABLE)
        operator.put(keys.clock_ack(2), "forged ack", congestion_control=RELIABLE)
        operator.put(keys.injector_ack, "injector ack", congestion_control=RELIABLE)
        assert acks.wait_for("injector ack")
        assert "forged ack" not in acks.payloads()
        dispatcher = fleet[DISPATCHER]
        dispatcher.put(keys.dispatch_progress, "progress", congestion_control=RELIABLE)
        dispatcher.put(keys.clock, "tick", congestion_control=RELIABLE)
        assert heard.wait_for("tick")
        # The forged tick was sent before the injector's ack had come through the router.
        assert heard.payloads() == ["tick"]
    finally:
        for s in subscribers:
            s.undeclare()


# Who logs in for a sender the catalogue names: the clock is the dispatcher's, the injector
# runs under the operator's login.
LOGIN_OF = {CLOCK: DISPATCHER, INJECTOR: OPERATOR}


# What a seed-004 run has no use for: a lifting AGV sends no state, fault or clock ack and
# takes no injected fault; no VDA 5050 gateway runs on its floor.
NOT_SEED004 = {Keys.vehicle_state, Keys.vehicle_fault, Keys.vehicle_inject, Keys.clock_ack,
               Keys.vda5050_mqtt, Keys.vda5050_leg, Keys.vda5050_alive}


def permissions(acl: dict):
    """Whether `login` may send `message` on `key` by these rules (what the router does)."""
    rules = {r["id"]: r for r in acl["rules"]}
    allowed = {p["id"]: [rules[i] for i in p["rules"] if rules[i]["flows"] == ["ingress"]]
               for p in acl["policies"]}

    def may(login: str, message: str, key: str) -> bool:
        return any(message in r["messages"] and any(
            zenoh.KeyExpr(expr).includes(zenoh.KeyExpr(key)) for expr in r["key_exprs"])
            for r in allowed[login])

    return may


@pytest.mark.parametrize("lifting", [False, True], ids=["forklifts", "lifting"])
def test_every_catalogued_topic_is_granted_to_its_sender(lifting):
    """The router's rules are written beside the catalogue (fleet/wire/topics.py): each topic's
    sender may put its publications, ask its queryables and hold its tokens on the run's keys
    of it, so a row added to Keys without its grant fails here, not silently in a --secure
    run (on a seed-004 floor: each topic such a run uses)."""
    run, vehicles = "fleet/acl", 2
    may = permissions(router_acl(run, vehicles, lifting))
    topics = [t for t in TOPICS if not (lifting and t in NOT_SEED004)]
    checked = 0
    for topic in topics:
        if topic.sender is None:
            continue
        if topic.fields == ("vehicle",):
            keys = [topic.key("acl", v) for v in (1, vehicles)]
        elif topic.fields == ("principal",):
            keys = [topic.key("acl", p) for p in (DISPATCHER, vehicle_sender(1))]
        else:
            keys = [topic.key("acl")]
        for key in keys:
            sender = topic.sender_on(key)
            login = LOGIN_OF.get(sender, sender)
            for kind, message in ((TopicKind.PUBLICATION, "put"), (TopicKind.QUERYABLE, "query"),
                                  (TopicKind.TOKEN, "liveliness_token")):
                if kind in topic.kind and not (kind is TopicKind.QUERYABLE and
                                               TopicKind.PUBLICATION in topic.kind):
                    assert may(login, message, key), f"{login} may not {message} on {key}"
                    checked += 1
    assert checked > len(topics)
    assert not may(vehicle_sender(1), "put", Keys("acl").vehicle_state(2))  # and no more


def test_a_lifting_agvs_login_may_do_what_its_agent_does_and_no_more():
    """Seed 004's rules against the forklifts': what a lifting AGV's agent and its
    dispatcher do stays granted, what only a forklift's run needs is not, and nothing on
    another AGV's keys."""
    keys, v1 = Keys("acl"), vehicle_sender(1)
    forklifts = permissions(router_acl(keys.root, 2))
    lifting = permissions(router_acl(keys.root, 2, lifting=True))
    used = [(v1, "declare_queryable", keys.vehicle_task(1)), (v1, "reply", keys.vehicle_task(1)),
            (v1, "liveliness_token", keys.vehicle_alive(1)),
            (v1, "query", keys.reservation_request(v1)), (v1, "query", keys.dispatch_claim),
            (v1, "query", keys.dispatch_mission),
            (v1, "declare_subscriber", keys.dispatch_mission),
            (v1, "declare_subscriber", keys.dispatch_done),
            (v1, "declare_liveliness_subscriber", keys.reservation_alive),
            (DISPATCHER, "query", keys.vehicle_task(2)),
            (DISPATCHER, "query", keys.reservation_request(DISPATCHER)),
            (DISPATCHER, "put", keys.dispatch_agv), (DISPATCHER, "put", keys.dispatch_done),
            (DISPATCHER, "put", keys.clock),  # for the fault injector, at a killed agent
            (DISPATCHER, "declare_subscriber", keys.clock_ack("*")),
            (DISPATCHER, "declare_liveliness_subscriber", keys.vehicle_alive("*"))]
    for grant in used:
        assert lifting(*grant), grant
    forklift_only = [
        (v1, "put", keys.vehicle_state(1)), (v1, "put", keys.vehicle_fault(1)),
        (v1, "put", keys.clock_ack(1)), (v1, "declare_queryable", keys.vehicle_inject(1)),
        (v1, "declare_subscriber", keys.clock), (v1, "declare_subscriber",
                                                 keys.reservation_change),
        (DISPATCHER, "declare_subscriber", keys.vehicle_state("*")),
        (DISPATCHER, "declare_subscriber", keys.vehicle_fault("*")),
        (DISPATCHER, "declare_subscriber", keys.reservation_change),  # it keeps the table
        (GATEWAY, "query", keys.vehicle_task(1)),
        (GATEWAY, "query", keys.reservation_request(GATEWAY)),
        (GATEWAY, "put", keys.vda5050_leg(1))]
    for grant in forklift_only:
        assert forklifts(*grant) and not lifting(*grant), grant
    for grant in [(v1, "declare_queryable", keys.vehicle_task(2)),
                  (v1, "reply", keys.vehicle_task(2)), (v1, "query", keys.vehicle_task(2)),
                  (v1, "query", keys.reservation_request(vehicle_sender(2))),
                  (v1, "liveliness_token", keys.vehicle_alive(2))]:
        assert not lifting(*grant), grant
