"""The compose deployment's configuration and forklift id claims, without docker: the
settings from the environment, each service's command line, and the claim roster. The
claims also run for real between processes here (agents started with --id auto)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from dispatcher.claims import Roster
from fleet.analysis.analyze import analyze
from fleet.cli import build_parser, main
from fleet.commands import service as service_command
from fleet.dispatching.decision import Strategy
from fleet.errors import UserError
from fleet.mission.engine import engine_options, run_mission
from fleet.mission.record import digest
from fleet.mission.spec import Mission, MissionKind
from fleet.recording.reader import read_recording
from fleet.runtime.access import generate_credentials, read_dictionary, router_acl
from fleet.runtime.bus import BusConfig, free_port, open_session, wait_alive
from fleet.runtime.deploy import (
    MAX_VEHICLES,
    DeployConfig,
    config_from_env,
    secret_files,
    service_config,
)
from fleet.wire.protocol import MissionDone
from fleet.wire.topics import Keys
from fleet.world.layout_file import load_layout
from vehicle_agent.process import claim

ROOT = Path(__file__).resolve().parent.parent


def test_unset_or_empty_variables_keep_the_defaults():
    assert config_from_env({}) == DeployConfig()
    assert config_from_env({"FLEET_LAYOUT": "", "FLEET_SEED": "  "}) == DeployConfig()


def test_every_setting_comes_from_its_variable():
    config = config_from_env({"FLEET_RUN": "r", "FLEET_LAYOUT": "small", "FLEET_MISSION":
                              "empty", "FLEET_STRATEGY": "greedy", "FLEET_VEHICLES": "2",
                              "FLEET_SEED": "7", "FLEET_CLOCK": "realtime",
                              "FLEET_SPEED": "20", "FLEET_GATHER_S": "1.5"})
    assert config == DeployConfig(run="r", layout="small", mission="empty", strategy="greedy",
                                  vehicles="2", seed=7, clock="realtime", speed=20.0,
                                  gather_s=1.5)
    args = service_config("dispatcher", config).argv()
    for flag, value in (("--layout", "small"), ("--mission", "empty"), ("--strategy",
                        "greedy"), ("--vehicles", "2"), ("--seed", "7"),
                        ("--clock", "realtime"), ("--speed", "20.0"), ("--gather", "1.5"),
                        ("--run", "r")):
        assert args[args.index(flag) + 1] == value


@pytest.mark.parametrize("env, named", [
    ({"FLEET_SEED": "x"}, "FLEET_SEED"), ({"FLEET_SPEED": "-1"}, "FLEET_SPEED"),
    ({"FLEET_SPEED": "nan"}, "FLEET_SPEED"), ({"FLEET_CLOCK": "slow"}, "FLEET_CLOCK"),
    ({"FLEET_STRATEGY": "best"}, "FLEET_STRATEGY"), ({"FLEET_VEHICLES": "0"}, "FLEET_VEHICLES"),
    ({"FLEET_VEHICLES": "many"}, "FLEET_VEHICLES"), ({"FLEET_MISSION": "x"}, "FLEET_MISSION"),
    ({"FLEET_DISPATCH": "vda"}, "FLEET_DISPATCH"), ({"FLEET_MANUFACTURER": "a/b"},
                                                    "FLEET_MANUFACTURER"),
    ({"FLEET_DISPATCH": "external", "FLEET_CLOCK": "fast"}, "FLEET_CLOCK=fast")])
def test_a_bad_setting_is_an_error_naming_the_variable(env, named):
    with pytest.raises(UserError, match=named):
        config_from_env(env)


def test_every_service_command_line_parses_as_the_cli_defines_it():
    parser = build_parser()
    for service in ("router", "reservation", "dispatcher", "vehicle", "recorder", "gateway"):
        args = parser.parse_args(service_config(service, DeployConfig()).argv())
        assert args.handler is not None
    dispatcher = parser.parse_args(service_config("dispatcher", DeployConfig()).argv())
    assert dispatcher.claims and dispatcher.vehicles is None  # "auto": who claims an id
    assert dispatcher.connect == ["tcp/router:7447"] and dispatcher.exit_when_done
    vehicle = parser.parse_args(service_config("vehicle", DeployConfig()).argv())
    assert vehicle.id is None and vehicle.exit_when_done
    with pytest.raises(UserError, match="unknown service"):
        service_config("forklift", DeployConfig())


def test_an_external_session_runs_the_clock_at_speed_1_and_the_gateway_on_the_broker():
    """FLEET_DISPATCH=external: the dispatcher runs no mission, on the real-time clock at
    the forklifts' own speed unless told otherwise; the gateway speaks on the broker service
    under the topics' names the settings give."""
    config = config_from_env({"FLEET_DISPATCH": "external", "FLEET_MANUFACTURER": "acme",
                              "FLEET_INTERFACE": "agv"})
    parser = build_parser()
    dispatcher = parser.parse_args(service_config("dispatcher", config).argv())
    assert (dispatcher.dispatch, dispatcher.clock, dispatcher.speed) == (
        "external", "realtime", 1.0)
    gateway = parser.parse_args(service_config("gateway", config).argv())
    assert (gateway.mqtt, gateway.manufacturer, gateway.interface) == (
        "mqtt://broker:1883", "acme", "agv")
    assert config_from_env({"FLEET_DISPATCH": "external", "FLEET_SPEED": "5"}).speed == 5.0


def test_the_roster_hands_out_the_lowest_free_id_and_the_same_one_again():
    roster = Roster(limit=3)
    assert [roster.claim(n) for n in ("a", "b", "a", "c")] == [1, 2, 1, 3]
    assert "complete" in roster.claim("d")  # no fourth forklift
    assert roster.claim("") == "a claim must name the claimant"


def test_a_closed_roster_answers_only_names_it_knows():
    roster = Roster(limit=4, ids={"a": 1, "b": 2}, closed=True)
    assert roster.claim("b") == 2  # a restarted container gets its forklift back
    assert "has started with 2 forklifts" in roster.claim("z")


def test_a_fleet_that_claims_its_ids_runs_the_reference_mission_and_every_process_exits(
        tmp_path):
    """What each container runs, as processes on loopback: agents with no id claim one
    (two of three names; the third arrives after the fleet is closed and is refused), every
    process exits by itself when the mission ends, the router last, and the mission is the
    in-process reference."""
    mission = Mission("small", MissionKind.FILL, Strategy.GREEDY, vehicles=2)
    layout = load_layout("small")
    reference = run_mission(mission, engine_options(mission, layout, None), layout)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    common = ["--connect", endpoint]
    logs = tmp_path / "logs"
    logs.mkdir()

    def start(name: str, *args: str) -> subprocess.Popen:
        with open(logs / f"{name}.log", "wb") as log:
            return subprocess.Popen([sys.executable, "-m", "fleet", *args], cwd=ROOT,
                                    stdout=log, stderr=subprocess.STDOUT)

    router = start("router", "router", "--listen", endpoint, "--exit-when-idle", "1")
    recorder = start("recorder", "recorder", *common, "--out-dir",
                     str(tmp_path / "recordings"), "--exit-when-done")
    session = open_session(BusConfig("client", (endpoint,)))
    keys = Keys()
    # The recorder first, as compose orders it (depends_on): it hears everything from the start.
    assert wait_alive(session, keys.recorder_alive, 60)
    services = [
        recorder,
        start("reservation", "reservation", *common, "--journal",
              str(tmp_path / "journal" / "r-{host}.journal"), "--exit-when-done"),
        *[start(f"agent-{name}", "agent", *common, "--id", "auto", "--claim-as", name,
                "--layout", "small", "--id-file", str(tmp_path / f"{name}.id"),
                "--exit-when-done") for name in ("crane", "hoist")],
        start("dispatcher", "dispatcher", *common, "--layout", "small", "--strategy",
              "greedy", "--claims", "--vehicles", "2", "--recorded", "--exit-when-done",
              "--restart-marker", str(tmp_path / "dispatcher.started"))]
    try:
        for v in (1, 2):  # a forklift's token comes once it has its id
            assert wait_alive(session, keys.vehicle_alive(v), 120)
        with pytest.raises(UserError, match=r"no forklift id for late: the (fleet is complete|"
                                            r"mission has started)"):
            claim(session, keys, "late", 10.0)
        crane = claim(session, keys, "crane", 10.0)  # a restarted container, its forklift
    finally:
        session.close()
    codes = [p.wait(timeout=180) for p in services]
    assert router.wait(timeout=60) == 0, (logs / "router.log").read_text()
    assert codes == [0] * len(services), [(p.args[3], c) for p, c in
                                          zip(services, codes, strict=True)]
    assert (tmp_path / "crane.id").read_text() == f"{crane}\n"
    assert sorted((tmp_path / n).read_text() for n in ("crane.id", "hoist.id")) == \
        ["1\n", "2\n"]
    assert len(list((tmp_path / "journal").glob("r-*.journal"))) == 1
    (run_dir,) = (tmp_path / "recordings").iterdir()
    recording = read_recording(run_dir)
    (done,) = [m for _, m in recording.of(MissionDone)]
    assert done.digest == digest(reference)
    report = analyze(recording)
    assert report.passed and report.complete and report.stacks_done == 24
    roster = json.loads((tmp_path / "dispatcher.started").read_text())  # for a restart
    assert sorted(roster.items()) == sorted(
        (name, int((tmp_path / f"{name}.id").read_text())) for name in ("crane", "hoist"))


def test_a_secure_deployment_logs_every_service_in_with_its_own_secret():
    parser = build_parser()
    config = DeployConfig(secure=True)
    router = parser.parse_args(service_config("router", config).argv())
    assert str(router.users) == "/run/secrets/fleet_users" and router.acl is not None
    for service, login in (("reservation", "reservation"), ("dispatcher", "dispatcher"),
                           ("recorder", "recorder"), ("gateway", "vda5050")):
        args = parser.parse_args(service_config(service, config).argv())
        assert (args.user, str(args.password_file)) == \
            (login, f"/run/secrets/fleet_{login}_password")
    vehicle = parser.parse_args(service_config("vehicle", config).argv())
    assert str(vehicle.logins) == "/run/secrets/fleet_vehicle_logins" and not vehicle.user


@pytest.mark.parametrize("layout,lifting", [
    ("paper004", True), ("paper", False),
    ("/nowhere/004.toml", False),  # a file only the dispatcher's container holds
])
def test_a_secure_router_writes_the_rules_of_its_layouts_vehicles(layout, lifting, tmp_path,
                                                                   monkeypatch, capsys):
    """A seed-004 floor's router grants the lifting AGVs and their dispatcher only what a
    seed-004 run uses (fleet/runtime/access.py); one that cannot read the layout, the
    forklifts' rules, saying so."""
    for var in ("FLEET_RUN", "FLEET_LAYOUT", "FLEET_SECURE"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("FLEET_SECURE", "1")
    monkeypatch.setenv("FLEET_LAYOUT", layout)
    monkeypatch.setattr(service_command, "ACL_FILE", str(tmp_path / "acl.json"))
    monkeypatch.setattr(service_command, "serve", lambda process: 0)  # no router started
    assert main(["service", "router"]) == 0
    written = json.loads((tmp_path / "acl.json").read_text())
    assert written == router_acl(Keys("default").root, MAX_VEHICLES, lifting)
    assert ("the vehicles get a forklift's grants" in capsys.readouterr().err) == \
        layout.endswith(".toml")


def test_the_secrets_give_the_router_every_login_and_the_forklifts_only_theirs(tmp_path):
    credentials = generate_credentials("compose", 3)
    files = secret_files(credentials)
    (tmp_path / "users").write_text(files["users"])
    (tmp_path / "vehicle_logins").write_text(files["vehicle_logins"])
    users = read_dictionary(tmp_path / "users")
    assert users == {name: login.password for name, login in credentials.logins.items()}
    assert read_dictionary(tmp_path / "vehicle_logins") == {
        f"vehicle-{v}": credentials.vehicle(v).password for v in (1, 2, 3)}
    assert files["dispatcher_password"].strip() == credentials["dispatcher"].password
    assert files["vda5050_password"].strip() == credentials["vda5050"].password
    (tmp_path / "bad").write_text("vehicle-1 no colon\n")
    with pytest.raises(UserError, match="bad:1: not a 'user:password' line"):
        read_dictionary(tmp_path / "bad")


def test_a_lane_layout_deploys_an_order_mission_with_its_journal():
    """FLEET_LAYOUT=paper002 runs an order mission (FLEET_ORDERS of them, 100 unless said),
    dispatched by the order book, as `fleet run --layout paper002` does; its dispatcher
    journals the book beside its restart marker, so a restart picks the mission up. A fill's
    dispatcher journals there too (where each forklift that goes down stops)."""
    parser = build_parser()
    config = config_from_env({"FLEET_LAYOUT": "paper002", "FLEET_ORDERS": "40",
                              "FLEET_VEHICLES": "6"})
    args = parser.parse_args(service_config("dispatcher", config).argv())
    assert (args.mission, args.orders, args.strategy, args.vehicles) == \
        ("orders", 40, "nearest", 6)
    assert str(args.journal) == "/tmp/fleet/dispatcher.journal" and args.claims
    default = parser.parse_args(service_config("dispatcher", DeployConfig(
        layout="paper002")).argv())
    assert (default.mission, default.orders) == ("orders", 100)
    paper = parser.parse_args(service_config("dispatcher", DeployConfig()).argv())
    assert (paper.mission, paper.strategy, str(paper.journal)) == \
        ("fill", "ann", "/tmp/fleet/dispatcher.journal")


@pytest.mark.parametrize("env, named", [
    ({"FLEET_ORDERS": "-3"}, "FLEET_ORDERS"), ({"FLEET_ORDERS": "many"}, "FLEET_ORDERS"),
    ({"FLEET_MISSION": "fill", "FLEET_ORDERS": "4"}, "FLEET_ORDERS"),
    ({"FLEET_LAYOUT": "paper002", "FLEET_STRATEGY": "ann"}, "FLEET_STRATEGY=ann"),
    ({"FLEET_LAYOUT": "paper", "FLEET_STRATEGY": "nearest"}, "FLEET_STRATEGY=nearest")])
def test_an_order_setting_that_does_not_fit_names_the_variable(env, named):
    with pytest.raises(UserError, match=named):
        service_config("dispatcher", config_from_env(env))
