"""Who may do what on the bus: user/password authentication and zenoh access control on the
router (zenoh 1.10: `transport/auth/usrpwd` and `access_control`).

Every process is a client of one router, and the router checks every message a client sends
it (flow "ingress") against the rules of the client's user name; a message that is not
allowed is dropped there, silently: the sender's put returns as usual, its get ends with no
reply, as if nobody served the key. A reply is checked on its own key, so a server answers on the
concrete key it may serve (a reply on a wildcard query's key expression is dropped). A
session without a user in the router's dictionary, or with the wrong password, is refused
during the handshake, so it never connects (zenoh.open retries until its connect timeout).
Only what goes through the router is checked: a session's own queryables and subscribers
still get what that session itself sends.

The principals, and why each gets what (`router_acl`; keys below fleet/<run>/). Each may
watch its own liveliness token: a container's health check logs in as the service it checks.
- `vehicle-N`, a forklift's agent: publishes only its own streams (vehicle/N/**: state,
  fault) and clock acks (clock/ack/N), so it cannot pose as another forklift; its token is
  vehicle/N/alive; it serves its own task and inject keys (declares the queryable and
  replies there, so it can answer no one else's task); it asks the reservation service only
  on reservation/request/vehicle-N, the key that names it, so the service can tell whose
  commit it is, and the dispatcher for an id (dispatch/claim); it reads the clock, the
  table's changes, the mission's end and the service's token.
- `dispatcher`: assigns tasks (get on vehicle/*/task), asks the service under its own name,
  publishes the mission (dispatch/**) and the clock, serves dispatch/mission, dispatch/done
  and dispatch/agv/history to a late or restarted recorder and dispatch/claim to
  forklifts, reads acks, states, faults, table changes and the recorder's status, and
  everyone's liveliness.
- `reservation`: serves reservation/request/** (every principal's request key), publishes
  reservation/change, and its token; reads the mission's end.
- `recorder`: reads everything (a subscriber on the whole run, a get of dispatch/mission,
  dispatch/done and dispatch/agv/history, asked each time the dispatcher's token comes);
  the one thing it writes is its own status (published and served on recorder/status) and
  its token.
- `operator`, `fleet run` with its fault injector: injects faults (get on vehicle/*/inject),
  acks the clock as the injector, reads everything, liveliness included.

On a seed-004 floor (`lifting`: vehicle_agent/lifting.py, dispatcher/remote004.py) the
vehicles, the dispatcher and the gateway get only what that run uses:
- `vehicle-N`, a lifting AGV's agent, publishes nothing: it serves its own task key only (the
  dispatcher's CellRequest and RouteRequest), holds its token, asks the reservation service
  only on reservation/request/vehicle-N (where, as for a forklift, the service lets it take
  and let go of its own cells only) and the dispatcher for an id and what the run is; it
  reads the run's description and end and the service's token (it follows neither the
  table's changes nor the clock).
- `dispatcher`: asks the AGVs on vehicle/*/task and the service under its own name (a closed
  zone is its commit, as ZONE; so are the cells of an AGV whose agent a fault killed, until
  its new one is up), publishes dispatch/** and the clock (which ticks only for the fault
  injector, at an agent's fault), serves dispatch/mission, dispatch/done,
  dispatch/agv/history and dispatch/claim, reads the
  acks, the recorder's status and everyone's liveliness; not the table's changes (it keeps
  the mission's table itself), no states or faults (a lifting AGV sends none).
- `vda5050`: nothing (no gateway runs on a seed-004 floor).

On several hosts (fleet/runtime/hosts.py) every host's router checks its own clients as
above, and the routers trust each other with everything of the run, since each has checked
what it forwards, but only each other: they link over TLS with certificates both ways, each
signed by a CA made for the run (fleet/runtime/certificates.py), and each router's access
control names the others by their certificates' common names (`router`, `router-NAME`).
Another host's router also logs in to the first host's as `router-NAME` (the first's
dictionary asks every session for a login). A zenoh id proves nothing (anyone may claim one),
a certificate the run signed does.

What the router sends to a client (flow "egress") is allowed for everyone on the whole run:
a client only gets what it subscribed to or asked for, which ingress already decides. It
must be allowed: a publisher sends nothing until the router has told it of a matching
subscriber, and a liveliness subscriber hears of tokens the same way.
"""

from __future__ import annotations

import json
import os
import secrets
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import zenoh

from fleet.errors import UserError
from fleet.wire.topics import DISPATCHER, GATEWAY, RECORDER, RESERVATION, vehicle_sender

# The principals log in under their sender names (fleet.wire.topics); the operator is the
# one without a stream of its own name (its fault injector sends as the injector).
OPERATOR = "operator"
SERVICES = (DISPATCHER, RESERVATION, RECORDER, OPERATOR, GATEWAY)

# zenoh's names for the messages a rule can govern (`access_control/rules/*/messages`).
PUBLISH = ("put",)
SUBSCRIBE = ("declare_subscriber",)
ASK = ("query",)
SERVE = ("declare_queryable", "reply")
TOKEN = ("liveliness_token",)
WATCH = ("declare_liveliness_subscriber", "liveliness_query")
MESSAGES = ("put", "delete", "declare_subscriber", "query", "declare_queryable", "reply",
            "liveliness_token", "declare_liveliness_subscriber", "liveliness_query")


def principals(vehicles: int) -> list[str]:
    return [*SERVICES, *(vehicle_sender(v) for v in range(1, vehicles + 1))]


@dataclass(frozen=True)
class Login:
    user: str
    password: str


@dataclass(frozen=True)
class Credentials:
    """One run's logins: per principal (the user name, see `principals`) a random password."""

    run: str
    logins: dict[str, Login]

    def __getitem__(self, principal: str) -> Login:
        return self.logins[principal]

    def vehicle(self, vehicle: int) -> Login:
        return self.logins[vehicle_sender(vehicle)]


def generate_credentials(run: str, vehicles: int, routers: Sequence[str] = ()) -> Credentials:
    """A random password for each principal of a run of `vehicles`, and for each of these
    other hosts' routers."""
    # token_urlsafe: letters, digits, - and _; never the ':' that ends a user in the dictionary
    return Credentials(run, {name: Login(name, secrets.token_urlsafe(24))
                             for name in (*principals(vehicles), *routers)})


def write_private(path: str | Path, text: str) -> Path:
    """Write a secret: readable by its owner only, from the first byte on."""
    path = Path(path)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.chmod(path, 0o600)  # an existing file keeps its mode through O_CREAT
    return path


def write_dictionary(logins: Iterable[Login], path: str | Path) -> Path:
    """A router's user/password dictionary (`transport/auth/usrpwd/dictionary_file`) of the
    logins it checks: one `user:password` line each, readable by its owner only."""
    return write_private(path, dictionary_text(logins))


def dictionary_text(logins) -> str:
    return "".join(f"{login.user}:{login.password}\n" for login in logins)


def read_dictionary(path: Path) -> dict[str, str]:
    """A `user:password` dictionary (as `write_dictionary` writes), user -> password."""
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise UserError(f"{path}: {exc.strerror}") from None
    logins = {}
    for n, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        user, colon, password = line.strip().partition(":")
        if not (user and colon and password):
            raise UserError(f"{path}:{n}: not a 'user:password' line")
        logins[user] = password
    return logins


Grants = dict[str, list[tuple[tuple[str, ...], list[str]]]]


def _grants(root: str, vehicles: int, lifting: bool = False) -> Grants:
    """Per principal, what it may send the router: (messages, key expressions) pairs
    (`lifting`: the fleet is seed 004's lifting AGVs)."""
    if lifting:
        return _lifting_grants(root, vehicles)
    grants = {
        DISPATCHER: [
            (ASK, [f"{root}/vehicle/*/task", f"{root}/reservation/request/{DISPATCHER}"]),
            (PUBLISH, [f"{root}/dispatch/**", f"{root}/clock"]),
            (SERVE, [f"{root}/dispatch/mission", f"{root}/dispatch/claim",
                     f"{root}/dispatch/agv/history", f"{root}/dispatch/done"]),
            (SUBSCRIBE, [f"{root}/clock/ack/*", f"{root}/vehicle/*/state",
                         f"{root}/vehicle/*/fault", f"{root}/reservation/change",
                         f"{root}/recorder/status", f"{root}/vda5050/*/leg"]),
            (TOKEN, [f"{root}/dispatch/alive"]),
            (WATCH, [f"{root}/**"])],
        RESERVATION: [
            (SERVE, [f"{root}/reservation/request/**"]),
            (PUBLISH, [f"{root}/reservation/change"]),
            (SUBSCRIBE, [f"{root}/dispatch/done"]),
            (TOKEN + WATCH, [f"{root}/reservation/alive"])],
        RECORDER: [
            (SUBSCRIBE, [f"{root}/**"]),
            (ASK, [f"{root}/dispatch/mission", f"{root}/dispatch/agv/history",
                   f"{root}/dispatch/done"]),
            (PUBLISH + SERVE, [f"{root}/recorder/status"]),
            (TOKEN + WATCH, [f"{root}/recorder/alive"]),
            (WATCH, [f"{root}/dispatch/alive"])],
        GATEWAY: [  # the VDA 5050 gateway: a master's orders as tasks, its MQTT traffic
            (ASK, [f"{root}/vehicle/*/task", f"{root}/reservation/request/{GATEWAY}",
                   f"{root}/dispatch/mission"]),
            (PUBLISH, [f"{root}/vda5050/**"]),
            (TOKEN, [f"{root}/vda5050/alive"]),
            (SUBSCRIBE, [f"{root}/clock", f"{root}/vehicle/*/state",
                         f"{root}/reservation/change", f"{root}/dispatch/mission"]),
            (WATCH, [f"{root}/reservation/alive", f"{root}/vehicle/*/alive"])],
        OPERATOR: [
            (ASK, [f"{root}/vehicle/*/inject"]),
            (PUBLISH, [f"{root}/clock/ack/injector"]),
            (SUBSCRIBE + WATCH, [f"{root}/**"])],
    }
    for v in range(1, vehicles + 1):
        grants[vehicle_sender(v)] = [
            (PUBLISH, [f"{root}/vehicle/{v}/**", f"{root}/clock/ack/{v}"]),
            (TOKEN, [f"{root}/vehicle/{v}/alive"]),
            (SERVE, [f"{root}/vehicle/{v}/task", f"{root}/vehicle/{v}/inject"]),
            (ASK, [f"{root}/reservation/request/{vehicle_sender(v)}", f"{root}/dispatch/claim",
                   f"{root}/dispatch/mission"]),
            (SUBSCRIBE, [f"{root}/clock", f"{root}/reservation/change",
                         f"{root}/dispatch/done", f"{root}/dispatch/mission"]),
            (WATCH, [f"{root}/reservation/alive", f"{root}/vehicle/{v}/alive"])]
    return grants


def _lifting_grants(root: str, vehicles: int) -> Grants:
    """A seed-004 run's grants: the services' as on any run, the vehicles', the dispatcher's
    and the gateway's cut to what that run uses (the module's docstring says why)."""
    grants = _grants(root, 0)
    grants[DISPATCHER] = [
        (ASK, [f"{root}/vehicle/*/task", f"{root}/reservation/request/{DISPATCHER}"]),
        (PUBLISH, [f"{root}/dispatch/**", f"{root}/clock"]),
        (SERVE, [f"{root}/dispatch/mission", f"{root}/dispatch/claim",
                 f"{root}/dispatch/agv/history", f"{root}/dispatch/done"]),
        (SUBSCRIBE, [f"{root}/clock/ack/*", f"{root}/recorder/status"]),
        (TOKEN, [f"{root}/dispatch/alive"]),
        (WATCH, [f"{root}/**"])]
    grants[GATEWAY] = []
    for v in range(1, vehicles + 1):
        grants[vehicle_sender(v)] = [
            (TOKEN, [f"{root}/vehicle/{v}/alive"]),
            (SERVE, [f"{root}/vehicle/{v}/task"]),
            (ASK, [f"{root}/reservation/request/{vehicle_sender(v)}", f"{root}/dispatch/claim",
                   f"{root}/dispatch/mission"]),
            (SUBSCRIBE, [f"{root}/dispatch/done", f"{root}/dispatch/mission"]),
            (WATCH, [f"{root}/reservation/alive", f"{root}/vehicle/{v}/alive"])]
    return grants


@dataclass(frozen=True)
class TlsFiles:
    """What a router needs to link with the others' over TLS, certificates both ways: the
    run's CA certificate, its own certificate and its private key (PEM files)."""

    ca: Path
    certificate: Path
    private_key: Path


@dataclass(frozen=True)
class LinkedRouter:
    """Another host's router, as this one's access control knows it: by the common name of
    its certificate and, when it logs in here, its user name ("": it does not)."""

    common_name: str
    user: str = ""


def router_acl(keys_root: str, vehicles: int, lifting: bool = False,
               linked: tuple[LinkedRouter, ...] = ()) -> dict:
    """The router's `access_control` section for one run (keys_root: `fleet/<run>`): deny
    by default; each principal's user name may send what `_grants` lists, and receive
    anything of the run. `lifting`: the vehicles are seed 004's lifting AGVs. `linked`: the
    other hosts' routers, which may send anything of the run (their own access control
    checked it)."""
    rules = [{"id": "egress", "messages": list(MESSAGES), "flows": ["egress"],
              "permission": "allow", "key_exprs": [f"{keys_root}/**"]}]
    subjects = []
    policies = []
    if linked:
        rules.append({"id": "routers", "messages": list(MESSAGES), "flows": ["ingress"],
                      "permission": "allow", "key_exprs": [f"{keys_root}/**"]})
        for router in linked:  # every listed property must match (certificate, login)
            name = f"linked {router.common_name}"
            subjects.append({"id": name, "cert_common_names": [router.common_name],
                             **({"usernames": [router.user]} if router.user else {})})
            policies.append({"id": name, "rules": ["routers", "egress"], "subjects": [name]})
    for principal, grants in _grants(keys_root, vehicles, lifting).items():
        ids = []
        for i, (messages, key_exprs) in enumerate(grants):
            ids.append(f"{principal}/{i}")
            rules.append({"id": ids[-1], "messages": list(messages), "flows": ["ingress"],
                          "permission": "allow", "key_exprs": key_exprs})
        subjects.append({"id": principal, "usernames": [principal]})
        policies.append({"id": principal, "rules": [*ids, "egress"], "subjects": [principal]})
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": subjects, "policies": policies}


def configure_router(config: zenoh.Config, acl: dict, dictionary_file: str | Path
                     ) -> zenoh.Config:
    """Make a router's config authenticate every session against the dictionary and enforce
    `acl` (from `router_acl`) on them."""
    config.insert_json5("access_control", json.dumps(acl))
    config.insert_json5("transport/auth/usrpwd/dictionary_file",
                        json.dumps(str(dictionary_file)))
    return config


def configure_tls(config: zenoh.Config, tls: TlsFiles) -> zenoh.Config:
    """Make a router's TLS links (listened on or connected to) show its certificate and take
    only peers whose certificate the run's CA signed."""
    mine = {"private_key": str(tls.private_key), "certificate": str(tls.certificate)}
    config.insert_json5("transport/link/tls", json.dumps({
        "root_ca_certificate": str(tls.ca), "enable_mtls": True,
        **{f"{side}_{what}": path for side in ("listen", "connect")
           for what, path in mine.items()}}))
    return config


def configure_client(config: zenoh.Config, user: str, password: str) -> zenoh.Config:
    """Make a session log in to its router as `user`."""
    config.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
    config.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
    return config
