"""One fleet across several hosts (`fleet run --hosts FILE`, fleet/runtime/hosts.py): the
hosts file and the faults that cut a host, checked without a network; then real runs whose
hosts are network namespaces made here (tests/netns.py), a zenoh router on each, the
routers linked: the fast-clock record equals the one-host record, and a host cut off from
the others is lived as the cut links of its forklifts, bit for bit."""

from __future__ import annotations

import functools
import json
import subprocess
import sys
from pathlib import Path

import pytest
from cryptography import x509
from netns import cut_off, hosts_toml, namespace_hosts, require_netns

from fleet.analysis.analyze import analyze
from fleet.cli import main
from fleet.dispatching.decision import Strategy
from fleet.errors import UserError
from fleet.mission.engine import Engine, engine_options
from fleet.mission.faults import FaultKind, ScenarioError, parse_scenario, scenario_toml
from fleet.mission.freeze import ScheduledPacer
from fleet.mission.record import digest
from fleet.mission.spec import Mission, MissionKind
from fleet.recording.reader import read_recording
from fleet.runtime.deploy import config_from_env, service_config
from fleet.runtime.hosts import HostsError, cut_links, hosts_for, load_hosts
from fleet.wire.protocol import Halt, Resume
from fleet.world.layout_file import load_layout

MISSION = Mission("paper", MissionKind.FILL, Strategy.ANN, 4, 0)
TWO_HOSTS = """
[[host]]
name = "a"
address = "10.0.0.1"
services = ["reservation"]
vehicles = [1, 2]

[[host]]
name = "b"
address = "10.0.0.2"
port = 7448
exec = ["ip", "netns", "exec", "b"]
services = ["recorder"]
vehicles = [3, 4]
"""
B_DRIVES_ONLY = TWO_HOSTS.replace('services = ["recorder"]', 'services = []')
CUT_B = """
name = "cut b"
[[fault]]
kind = "cut_host"
at = 300.3
host = "b"
duration = 40.0
"""


def hosts_file(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "hosts.toml"
    path.write_text(text)
    return path


def test_a_hosts_file_places_each_process_and_the_rest_on_the_first_host(tmp_path):
    hosts = load_hosts(hosts_file(tmp_path, TWO_HOSTS), 5)
    a, b = hosts.hosts
    assert (a.endpoint, b.endpoint, b.exec) == (
        "tcp/10.0.0.1:7447", "tcp/10.0.0.2:7448", ("ip", "netns", "exec", "b"))
    placed = {kind: hosts.of_process(kind).name for kind in (
        "reservation", "recorder", "dispatcher", "agent-1", "agent-3", "agent-4", "agent-5")}
    assert placed == {"reservation": "a", "recorder": "b", "dispatcher": "a", "agent-1": "a",
                      "agent-3": "b", "agent-4": "b", "agent-5": "a"}
    assert [hosts.router_name(h) for h in hosts.hosts] == ["router", "router-b"]


@pytest.mark.parametrize("change, named", [
    (('vehicles = [3, 4]', 'vehicles = [2, 3]'), "forklift 2 is on host a and on host b"),
    (('services = ["recorder"]', 'services = ["reservation"]'), "service reservation is on"),
    (('services = ["recorder"]', 'services = ["router"]'), "services must be a list of"),
    (('vehicles = [3, 4]', 'vehicles = [3, 9]'), "vehicle 9: the run has forklifts 1 to 5"),
    (('port = 7448', 'port = 0'), "port must be a TCP port"),
    (('port = 7448', 'colour = "red"'), "unknown field 'colour'"),
    (('address = "10.0.0.2"', 'address = "10.0.0.2:7448"'), "neither an IP address nor"),
    (('name = "b"', 'name = "a"'), "name 'a' is on host a and on host a"),
    (('name = "b"', 'name = "B b"'), "must be 1 to 16 lower-case"),
    (('exec = ["ip", "netns", "exec", "b"]', 'exec = "ssh b"'), "exec must be a list"),
    (('name = "a"\naddress = "10.0.0.1"', 'name = "a"\naddress = "10.0.0.1"\nexec = ["x"]'),
     "the first host is the one fleet run runs on"),
])
def test_a_bad_hosts_file_is_refused_naming_the_host_and_field(tmp_path, change, named):
    old, new = change
    assert old in TWO_HOSTS
    with pytest.raises(HostsError, match=named):
        load_hosts(hosts_file(tmp_path, TWO_HOSTS.replace(old, new, 1)), 5)


def test_a_hosts_file_that_is_no_toml_or_missing_is_refused(tmp_path):
    with pytest.raises(HostsError, match="not valid TOML"):
        load_hosts(hosts_file(tmp_path, "[[host]\n"), 4)
    with pytest.raises(HostsError, match="expected \\[\\[host\\]\\] tables"):
        load_hosts(hosts_file(tmp_path, 'host = "a"\n'), 4)
    with pytest.raises(HostsError, match="No such file"):
        load_hosts(tmp_path / "none.toml", 4)


def test_a_secure_runs_first_host_needs_the_port_after_its_routers(tmp_path):
    assert hosts_for(None, 4, secure=True) is None
    assert len(hosts_for(hosts_file(tmp_path, TWO_HOSTS), 4, secure=True).hosts) == 2
    last = TWO_HOSTS.replace('address = "10.0.0.1"', 'address = "10.0.0.1"\nport = 65535')
    with pytest.raises(HostsError, match=r"port after its own \(65535 \+ 1\), which is no port"):
        hosts_for(hosts_file(tmp_path, last), 4, secure=True)
    same = TWO_HOSTS.replace('address = "10.0.0.2"', 'address = "10.0.0.1"')
    with pytest.raises(HostsError, match=r"\(7447 \+ 1\), which is taken"):
        hosts_for(hosts_file(tmp_path, same), 4, secure=True)
    assert hosts_for(hosts_file(tmp_path, same), 4, secure=False) is not None


def test_a_host_cut_is_lived_as_the_cut_links_of_its_forklifts(tmp_path):
    hosts = load_hosts(hosts_file(tmp_path, B_DRIVES_ONLY), 4)
    scenario = parse_scenario(CUT_B, "cut")
    assert parse_scenario(scenario_toml(scenario), "again") == scenario  # written, read back
    lived = cut_links(scenario, hosts)
    assert [(f.kind, f.at, f.vehicle, f.duration) for f in lived.faults] == [
        (FaultKind.CUT_LINK, 300.3, 3, 40.0), (FaultKind.CUT_LINK, 300.3, 4, 40.0)]


@pytest.mark.parametrize("host_text, scenario_text, named", [
    (None, CUT_B, "only a run spread over several hosts"),
    (TWO_HOSTS, CUT_B.replace('host = "b"', 'host = "c"'), "no host is named 'c'"),
    (TWO_HOSTS, CUT_B.replace('host = "b"', 'host = "a"'), "a is the first host"),
    (TWO_HOSTS, CUT_B, "host b runs recorder: only a host of forklift agents"),
    (B_DRIVES_ONLY.replace("vehicles = [3, 4]", "vehicles = []"), CUT_B,
     "host b runs no forklift"),
    (B_DRIVES_ONLY,
     CUT_B + '[[fault]]\nkind = "cut_link"\nat = 320.0\nvehicle = 3\nduration = 5.0\n',
     "starts before fault 1 .cut_link of forklift 3"),
])
def test_a_host_that_cannot_be_cut_is_refused_naming_the_fault(tmp_path, host_text,
                                                                scenario_text, named):
    hosts = load_hosts(hosts_file(tmp_path, host_text), 4) if host_text else None
    with pytest.raises(ScenarioError, match=named):
        cut_links(parse_scenario(scenario_text, "cut"), hosts)


def test_fleet_run_refuses_hosts_with_what_runs_on_one_host_alone(tmp_path, capsys):
    path = hosts_file(tmp_path, TWO_HOSTS)
    for extra, said in ((["--inprocess"], "takes no --hosts"),
                        (["--port", "7999"], "gives each host's router its port"),
                        (["--vehicles", "2"], "vehicle 3: the run has forklifts 1 to 2")):
        assert main(["run", "--layout", "paper", "--vehicles", "4", "--hosts", str(path), "--out",
                     str(tmp_path / "out"), *extra]) == 2
        assert said in capsys.readouterr().err
    (tmp_path / "cut.toml").write_text(CUT_B)
    assert main(["run", "--layout", "small", "--vehicles", "2", "--faults",
                 str(tmp_path / "cut.toml"), "--out", str(tmp_path / "out")]) == 2
    assert "only a run spread over several hosts" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()  # refused before anything was made


def test_a_compose_router_links_to_another_docker_hosts_router():
    config = config_from_env({"FLEET_ROUTER_LINK": "tcp/fleet-a.example:7447"})
    assert service_config("router", config).argv()[:5] == [
        "router", "--listen", "tcp/0.0.0.0:7447", "--connect", "tcp/fleet-a.example:7447"]
    with pytest.raises(UserError, match="FLEET_ROUTER_LINK"):
        config_from_env({"FLEET_ROUTER_LINK": "fleet-a:7447"})
    with pytest.raises(UserError, match="FLEET_ROUTER_LINK with FLEET_SECURE=1"):
        config_from_env({"FLEET_ROUTER_LINK": "tcp/a:7447", "FLEET_SECURE": "1"})


# -- real runs, each host a network namespace ------------------------------------------------

@functools.cache
def reference_digest(scenario_text: str | None) -> str:
    """The in-process run of MISSION (with this scenario's faults)."""
    layout = load_layout("paper")
    pacer = ScheduledPacer(parse_scenario(scenario_text, "reference")) \
        if scenario_text else None
    engine = Engine(MISSION, engine_options(MISSION, layout, None), layout, pacer=pacer)
    return digest(engine.run())


def run_on_hosts(tmp_path: Path, extra: list[str]) -> tuple[dict, Path]:
    """MISSION on three namespace hosts: a runs fleet run, the reservation service, the
    dispatcher and forklift 1; b the recorder and forklift 2; c forklifts 3 and 4."""
    require_netns()
    out = tmp_path / "run"
    with namespace_hosts(["a", "b", "c"]) as hosts:
        path = hosts_file(tmp_path, hosts_toml(
            hosts, {"a": ["reservation", "dispatcher"], "b": ["recorder"]},
            {"a": [1], "b": [2], "c": [3, 4]}))
        done = subprocess.run(
            [*hosts[0].exec, sys.executable, "-m", "fleet", "run", "--layout", "paper",
             "--vehicles", "4", "--hosts", str(path), "--out", str(out), "--json", *extra],
            capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    routers = {name: (out / "logs" / f"{name}.log").read_text()
               for name in ("router", "router-b", "router-c")}
    for (name, text), host in zip(routers.items(), hosts, strict=True):
        assert f"routing on tcp/{host.address}:7447" in text, name  # bound on its own host
    return json.loads(done.stdout), out


def test_a_host_whose_router_cannot_link_is_named_before_anything_runs_there(tmp_path):
    """Host b is unplugged: its router starts but never links to a's. fleet run waits for
    the link (the router's token, which reaches a's router once linked) and says which
    router did not link, where to, and what to check, before it starts any process of the
    run."""
    require_netns()
    out = tmp_path / "run"
    with namespace_hosts(["a", "b"]) as hosts:
        cut_off(hosts[1])
        path = hosts_file(tmp_path, hosts_toml(
            hosts, {"a": ["reservation", "dispatcher", "recorder"]}, {"a": [1, 2], "b": [3, 4]}))
        done = subprocess.run(
            [*hosts[0].exec, sys.executable, "-m", "fleet", "run", "--layout", "paper",
             "--vehicles", "4", "--hosts", str(path), "--out", str(out)],
            capture_output=True, text=True, timeout=300)
    assert done.returncode == 1
    assert (f"router-b did not link to the first host's router (at tcp/{hosts[0].address}:7447) "
            f"within 30 s: are the hosts file's addresses and ports right") in done.stderr
    assert "Traceback" not in done.stderr
    started = {p.stem for p in (out / "logs").glob("*.log")}
    assert started == {"router", "router-b"}  # no service or agent


def test_a_fleet_on_three_hosts_records_what_one_host_records(tmp_path):
    summary, out = run_on_hosts(tmp_path, [])
    assert summary["verdicts"]["passed"] and summary["stacks_done"] == 136
    assert summary["digest"] == reference_digest(None)
    assert {p.name for p in (out / "logs").iterdir()} >= {
        "recorder.log", "reservation.log", "dispatcher.log", "agent-3.log", "agent-4.log"}


def test_a_host_cut_off_is_survived_like_the_cut_links_of_its_forklifts(tmp_path):
    (tmp_path / "cut.toml").write_text(CUT_B.replace('host = "b"', 'host = "c"'))
    summary, out = run_on_hosts(tmp_path, ["--faults", str(tmp_path / "cut.toml")])
    lived = (out / "faults.toml").read_text()
    assert lived.count('kind = "cut_link"') == 2
    assert summary["digest"] == reference_digest(lived)
    recording = read_recording(out)
    report = analyze(recording)
    assert report.passed and report.stacks_done == 136, report.verdict_lines()
    assert {m.vehicle for _, m in recording.of(Halt)} >= {3, 4}
    assert {m.vehicle for _, m in recording.of(Resume)} == {3, 4}


def test_a_secure_fleet_on_three_hosts_survives_a_host_cut_off_as_on_one_host(tmp_path):
    """Every host's router checks its own clients' logins and rules; the routers link over
    TLS with the run's certificates, and the first host's takes the others' logins too
    (tests/test_secure_hosts.py proves the links' rules). Host c, cut off and back, links
    again through its forwarder."""
    (tmp_path / "cut.toml").write_text(CUT_B.replace('host = "b"', 'host = "c"'))
    summary, out = run_on_hosts(tmp_path, ["--secure", "--faults", str(tmp_path / "cut.toml")])
    assert summary["verdicts"]["passed"] and summary["stacks_done"] == 136
    assert summary["digest"] == reference_digest((out / "faults.toml").read_text())
    # A bundle per host, each with what that host needs and no more.
    secrets = out / "secrets"
    assert {p.name for p in secrets.iterdir()} == {"a", "b", "c"}

    def linked(host: str) -> list[tuple[list[str], list[str]]]:
        """Whom the host's router takes links from: by certificate, and by login."""
        return [(s["cert_common_names"], s.get("usernames", []))
                for s in json.loads((secrets / host / "acl.json").read_text())["subjects"]
                if "cert_common_names" in s]

    assert linked("a") == [(["router-b"], ["router-b"]), (["router-c"], ["router-c"])]
    assert linked("b") == linked("c") == [(["router"], [])]
    ca_pem = (secrets / "a" / "ca.pem").read_bytes()
    ca = x509.load_pem_x509_certificate(ca_pem)
    # (the VDA 5050 gateway's login too, on the first host, where it runs when it does)
    runs = {"a": ({"operator", "dispatcher", "reservation", "vda5050", "vehicle-1"}, "router"),
            "b": ({"recorder", "vehicle-2"}, "router-b"),
            "c": ({"vehicle-3", "vehicle-4"}, "router-c")}
    for host, (processes, router) in runs.items():
        bundle = secrets / host
        assert (bundle / "ca.pem").read_bytes() == ca_pem
        assert (bundle / f"{router}.key").stat().st_mode & 0o777 == 0o600
        x509.load_pem_x509_certificate((bundle / f"{router}.pem").read_bytes(
            )).verify_directly_issued_by(ca)  # signed by the run's own CA
        # Its own router's key alone: the CA's is nowhere, no one signs another.
        assert {p.name for p in bundle.iterdir() if p.suffix in (".key", ".pem")} == {
            "ca.pem", f"{router}.key", f"{router}.pem"}
        logs_in = processes | ({router} if host != "a" else set())
        assert {p.stem for p in bundle.glob("*.password")} == logs_in
        checked = {line.split(":")[0] for line in (bundle / "users.txt").read_text().split()}
        assert checked == processes | ({"router-b", "router-c"} if host == "a" else set())
