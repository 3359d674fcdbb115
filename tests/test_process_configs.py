"""Each process kind's command line: a config written as flags (how `fleet run` and the
compose deployment start processes) parses back into the very same config, as `fleet KIND`
and `python -m PACKAGE` parse it; and a process started on its own needs no command line of
the `fleet` CLI, yet fails the same way: in one line."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from fleet.cli import build_parser, main
from fleet.dispatching.decision import Strategy
from fleet.mission.spec import ClockMode, Mission, MissionKind
from fleet.planning.trajectory import Pose
from fleet.runtime.access import TlsFiles
from fleet.runtime.args import BusFlags
from fleet.runtime.bus import free_port
from fleet.runtime.process_configs import (
    KINDS,
    AgentConfig,
    DispatcherConfig,
    RecorderConfig,
    ReservationConfig,
    RouterConfig,
)

ROOT = Path(__file__).resolve().parent.parent


def configs(tmp_path: Path) -> list:
    weights = tmp_path / "weights.json"
    weights.write_text("{}")
    plain = BusFlags(connect=("tcp/127.0.0.1:7447",))
    secure = BusFlags("r", "peer", ("tcp/router:7447",), ("tcp/0.0.0.0:7448",), 5.0,
                      "dispatcher", tmp_path / "secret")
    return [
        RouterConfig(), RouterConfig(("tcp/0.0.0.0:1",), ("tcp/other:2",), tmp_path / "acl",
                                     tmp_path / "users", 5.0),
        RouterConfig(("tcp/0.0.0.0:1",), ("tls/other:3",), tmp_path / "acl", tmp_path / "users",
                     None, "router-b", tmp_path / "router-b.password",
                     TlsFiles(tmp_path / "ca.pem", tmp_path / "b.pem", tmp_path / "b.key")),
        ReservationConfig(plain), ReservationConfig(secure, tmp_path / "{host}.journal", True),
        AgentConfig(plain, 3), AgentConfig(secure, None, "crane", 30.0, "small",
                                           Pose.parse("3,4,E"), tmp_path / "logins",
                                           tmp_path / "id", True),
        DispatcherConfig(plain, Mission()),
        DispatcherConfig(secure, Mission("small", MissionKind.EMPTY, Strategy.GREEDY, 2, 7),
                         weights, ClockMode.REALTIME, 20.0, 30.0, "fleet run", "kill_vehicle",
                         True, True, True, True, 1.5, tmp_path / "marker"),
        RecorderConfig(plain), RecorderConfig(secure, tmp_path / "a.mcap", None, True, 8765,
                                              "0.0.0.0"),
        RecorderConfig(plain, out_dir=tmp_path / "recordings"),
    ]


def test_every_config_parses_back_from_its_command_line(tmp_path):
    parser = build_parser()
    cases = configs(tmp_path)
    assert {type(c) for c in cases} == set(KINDS)
    for config in cases:
        args = parser.parse_args(config.argv())
        assert type(config).from_args(args) == config, config.argv()


def test_a_config_built_in_code_runs_as_its_flags_left_out():
    parser = build_parser()
    for kind, required in ((RouterConfig, []), (ReservationConfig, []),
                           (AgentConfig, ["--id", "auto"]), (DispatcherConfig, []),
                           (RecorderConfig, [])):
        parsed = kind.from_args(parser.parse_args([kind.COMMAND, *required]))
        built = kind() if kind is RouterConfig else \
            kind(BusFlags(), Mission()) if kind is DispatcherConfig else kind(BusFlags())
        assert parsed == built


def test_processes_start_without_the_fleet_command_line():
    code = ("import sys, dispatcher.process, vehicle_agent.process, reservation.service, "
            "recorder.process; print(sorted(m for m in sys.modules if m == 'fleet.cli' or "
            "m.startswith('fleet.commands')))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, env={**os.environ, "PYTHONPATH": str(ROOT)}, check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize("package", ["dispatcher", "vehicle_agent", "reservation", "recorder"])
def test_a_process_alone_fails_in_one_line(package, tmp_path):
    dead = f"tcp/127.0.0.1:{free_port()}"
    extra = {"vehicle_agent": ["--id", "1"], "recorder": ["--out", str(tmp_path / "r.mcap")]}
    proc = subprocess.run([sys.executable, "-m", package, "--connect", dead,
                           "--connect-timeout", "1", *extra.get(package, [])],
                          cwd=tmp_path, capture_output=True, text=True, timeout=60,
                          env={**os.environ, "PYTHONPATH": str(ROOT), "TMPDIR": str(tmp_path)})
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == \
        f"python -m {package}: error: no zenoh router answers at {dead} (waited 1 s)"
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no crash report, no file


IMPORTED = """
import contextlib, io, json, sys
from fleet.cli import main
words = sys.argv[1:]
help_text = io.StringIO()
with contextlib.redirect_stdout(help_text), contextlib.suppress(SystemExit):
    main([*words, "--help"])
print(json.dumps({"help": help_text.getvalue(), "modules": sorted(sys.modules)}))
"""


@pytest.mark.parametrize("words", [(kind.COMMAND,) for kind in KINDS] + [("vda5050", "gateway")])
def test_a_process_of_a_run_starts_without_the_other_commands(words, capsys):
    """`fleet KIND ...`, as fleet run and compose start each process of a run, is parsed by
    the kind's own parser (the help `fleet help KIND` gives) and imports none of the other
    commands (runs, analysis, plots, benchmarks) nor torch: they were half of its start-up."""
    done = subprocess.run([sys.executable, "-c", IMPORTED, *words], capture_output=True,
                          text=True, cwd=ROOT, check=True)
    started = json.loads(done.stdout)
    assert main(["help", *words]) == 0
    assert started["help"] == capsys.readouterr().out
    commands = {m for m in started["modules"] if m.startswith("fleet.commands.")}
    assert commands == {"fleet.commands.processes"}
    assert not {"torch", "mcap", "fleet.analysis.analyze", "fleet.runtime.local_run"} & \
        set(started["modules"])
