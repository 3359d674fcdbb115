"""Bad input at every command: refused with a non-zero exit and one line that names it, never
a traceback; connects that cannot succeed fail in bounded time, naming what they waited for;
`fleet run` hears of a child's death at once; every option's help says what it does and its
default. In process through fleet.cli.main, and a few as real `python -m fleet` processes."""

import argparse
import contextlib
import io
import math
import os
import re
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from zenoh_helpers import client

from fleet.cli import build_parser, main, subcommands
from fleet.dispatching.decision import Strategy
from fleet.errors import describe
from fleet.mission.spec import Mission, MissionKind
from fleet.runtime.argtypes import endpoint, finite_float, port, positive_float, sim_seconds
from fleet.runtime.bus import free_port
from fleet.runtime.helptext import STRATEGIES, HelpFormatter, shows_default
from fleet.runtime.lifecycle import EX_SOFTWARE
from fleet.runtime.local_run import ROUTER_TIMEOUT_MS, RunSpec, run_processes
from fleet.world.layout_file import layout_source
from fleet.world.reachability import NO_STARTS

ROOT = Path(__file__).resolve().parent.parent
FUZZ = settings(max_examples=200, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.fixture
def busy_port():
    """A loopback port something listens on for the whole test."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        yield s.getsockname()[1]


@pytest.fixture
def paths(tmp_path, busy_port):
    """What the table's {PLACEHOLDERS} stand for."""
    a_file = tmp_path / "a_file.txt"
    a_file.write_text("hello\n")
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"name = \"x\"\n\xff\xfe not text")
    no_starts = tmp_path / "no_starts.toml"
    no_starts.write_text(layout_source("small").replace('starts = ["4,6,S", "5,6,S"]',
                                                        "starts = []"))
    return {"FILE": str(a_file), "DIR": str(tmp_path), "MISSING": str(tmp_path / "missing"),
            "UNDER_FILE": str(a_file / "x"), "BINARY": str(binary),
            "NO_STARTS": str(no_starts), "BUSY": str(busy_port)}


def cli(argv: list[str], capsys) -> tuple[int, str, str]:
    """Exit status, stdout and stderr of `fleet ARGV` run in this process."""
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse refuses by exiting
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


# Each row: the command line ({NAME}: a path or port of the `paths` fixture), the text its
# error must hold (naming the input), and the exit status (2 unless said).
BAD = [
    # fleet run
    ("run --speed nan", "argument --speed: 'nan' is not a finite number"),
    ("run --speed inf", "argument --speed: 'inf' is not a finite number"),
    ("run --speed=-1", "argument --speed: '-1' must be a positive number"),
    ("run --speed fast", "argument --speed: 'fast' is not a number"),
    ("run --vehicles 0", "argument --vehicles: '0' must be at least 1"),
    ("run --layout small --vehicles 99",
     "--vehicles 99: layout small has start poses for 1 to 2 forklifts"),
    ("run --seed 1.5", "argument --seed: '1.5' is not a whole number"),
    ("run --port 0", "argument --port: '0' is not a TCP port (1 to 65535)"),
    ("run --port 65536", "argument --port: '65536' is not a TCP port"),
    ("run --layout small --port {BUSY}", "--port {BUSY}: port {BUSY} on 127.0.0.1 is busy"),
    ("run --layout small --foxglove {BUSY}", "--foxglove {BUSY}: port {BUSY} on 127.0.0.1 is busy"),
    ("run --out {FILE}", "argument --out: '{FILE}' is a file, not a directory"),
    ("run --out {UNDER_FILE}", "cannot be written: {FILE} is a file, not a directory"),
    ("run --weights {MISSING}", "argument --weights: '{MISSING}' does not exist"),
    ("run --weights {DIR}", "argument --weights: '{DIR}' is a directory, not a file"),
    ("run --weights {BINARY}", "argument --weights: '{BINARY}' is not UTF-8 text"),
    ("run --layout {BINARY}", "argument --layout: '{BINARY}' is not UTF-8 text"),
    ("run --layout nosuch", "layout 'nosuch' is neither a built-in layout"),
    ("run --layout {NO_STARTS}", f"layout small: {NO_STARTS}"),
    ("run --strategy fastest", "argument --strategy: invalid choice: 'fastest'"),
    ("run --faults nosuch", "scenario 'nosuch' is neither a shipped scenario"),
    ("run --faults {BINARY}", "argument --faults: '{BINARY}' is not UTF-8 text"),
    ("run --inprocess --clock realtime", "--inprocess runs the fast clock"),
    ("run --inprocess --port 7447", "without a router, a live view or logins: it takes no "
     "--port"),
    ("run --inprocess --foxglove --secure", "it takes no --foxglove and no --secure"),
    # looking at recordings
    ("analyze {MISSING}", "{MISSING}"),
    ("analyze {FILE}", "{FILE}: not an MCAP recording"),
    ("plot {MISSING}", "{MISSING}"),
    ("plot {FILE} --at nan", "argument --at: 'nan' is not a finite number"),
    ("plot {FILE} --at=-1", "argument --at: '-1' must be a time from 0 to 1000000 seconds"),
    ("plot {FILE} --at 1e300", "argument --at: '1e300' must be a time from 0"),
    ("plot {FILE} --frames 0", "argument --frames: '0' must be at least 1"),
    ("plot {FILE} --fps x", "argument --fps: 'x' is not a whole number"),
    ("plot {FILE} --out {FILE}", "argument --out: '{FILE}' is a file, not a directory"),
    ("compare {MISSING} {FILE}", "{MISSING}"),
    # fault scenarios
    ("faults check mixed --vehicles 0", "argument --vehicles: '0' must be at least 1"),
    ("faults check mixed --vehicles 99",
     "--vehicles 99: layout paper has start poses for 1 to 4 forklifts"),
    ("faults check kill_vehicle --layout {NO_STARTS}", f"layout small: {NO_STARTS}"),
    ("faults check {BINARY}", "argument scenario: '{BINARY}' is not UTF-8 text"),
    ("faults check nosuch", "scenario 'nosuch' is neither a shipped scenario"),
    ("faults show nosuch", "argument scenario: invalid choice: 'nosuch'"),
    # one planning query
    ("plan --from p1 --to s1#1 --at nan", "argument --at: 'nan' is not a finite number"),
    ("plan --from p1 --to s1#1 --at=-1", "argument --at: '-1' must be a time from 0"),
    ("plan --from p1 --to s1#1 --vehicle 0", "argument --vehicle: '0' must be at least 1"),
    ("plan --from p1 --to s1#1 --png {FILE}", "argument --png: '{FILE}' must end in .png"),
    ("plan --from p1 --to s1#1 --png {DIR}", "argument --png: '{DIR}' is a directory"),
    ("plan --from p1 --to s1#1 --png {MISSING}/plan.png",
     "cannot be written: directory {MISSING} does not exist"),
    ("plan --from p1 --to s1#1 --png {UNDER_FILE}.png",
     "cannot be written: {FILE} is a file, not a directory"),
    ("plan --from p1 --to s1#1 --reserved {MISSING}", "argument --reserved: '{MISSING}'"),
    ("plan --from p1 --to s1#1 --reserved {BINARY}", "'{BINARY}' is not UTF-8 text"),
    ("plan --from p9 --to s1#1", "place 'p9' is not a pose"),
    ("plan --layout small --from 4,6,S --to a#1 --vehicle 9",
     "--vehicle 9: layout small has forklifts 1 to 2"),
    # layouts
    ("layout show nosuch", "layout 'nosuch' is neither a built-in layout"),
    ("layout check {MISSING}", "layout '{MISSING}' is neither a built-in layout"),
    ("layout check {NO_STARTS}", f"{{NO_STARTS}}: {NO_STARTS}", 1),
    ("layout generate --aisles 0", "argument --aisles: '0' must be at least 1"),
    ("layout generate --depth 1", "--depth must be at least 4, not 1"),
    ("layout generate --aisles 1 --depth 2",
     "--depth must be at least 4, not 2: with fewer lanes per side an aisle has no parking"),
    ("layout generate --out {DIR}", "argument --out: '{DIR}' is a directory; give a file name"),
    ("layout generate --out {MISSING}/x.toml", "directory {MISSING} does not exist"),
    ("layout generate --out /dev/full", "--out /dev/full: No space left on device"),
    ("layout generate --aisles 1000 --depth 1000", "more than a layout may have"),
    # training and benchmarks
    ("train --cycles 0", "argument --cycles: '0' must be at least 1"),
    ("train --lm-steps x", "argument --lm-steps: 'x' is not a whole number"),
    ("train --out {DIR}", "argument --out: '{DIR}' is a directory; give a file name"),
    ("train --layout nosuch", "layout 'nosuch' is neither a built-in layout"),
    ("bench planner --queries 0", "argument --queries: '0' must be at least 1"),
    ("bench seed004 --heat-weights 1,-2",
     "argument --heat-weights: '1,-2' must list positive numbers, comma-separated"),
    ("bench seed004 --heat-weights 2,many",
     "argument --heat-weights: '2,many' must list positive numbers, comma-separated"),
    ("bench planner --layout small --queries 2", "layout small has 2 stations and 2 clusters; "
     "the planner benchmark needs at least 4 of each"),
    ("bench runtime --agents 3,2", "argument --agents: '3,2' must be in ascending order"),
    ("bench runtime --agents many", "argument --agents: 'many' is not a comma-separated list"),
    ("bench runtime --window inf", "argument --window: 'inf' is not a finite number"),
    ("bench recorder --seconds nan", "argument --seconds: 'nan' is not a finite number"),
    ("bench recorder --rates 0,5", "argument --rates: '0,5' must list numbers of at least 1"),
    ("bench faults --speed nan", "argument --speed: 'nan' is not a finite number"),
    ("bench faults --scenarios nosuch", "--scenarios: 'nosuch' is not a shipped scenario"),
    ("bench strategies --weights {BINARY}", "'{BINARY}' is not UTF-8 text"),
    ("bench strategies --layout paper002 --ann-seeds 0", "layout paper002 has no stacks or no "
     "forklift starts: the Table 4 experiment fills and empties stacks"),
    ("bench strategies --ann-seeds -1", "argument --ann-seeds: '-1' must not be negative"),
    ("train --layout small --plot weights.txt", "'weights.txt' must end in .png"),
    ("bench campaign --runs 0", "argument --runs: '0' must be at least 1"),
    ("bench campaign --seed -1", "argument --seed: '-1' must not be negative"),
    ("bench campaign --kind sideways", "argument --kind: invalid choice: 'sideways'"),
    ("bench campaign --out {FILE}", "argument --out: '{FILE}' is a file, not a directory"),
    ("bench campaign --layout nosuch", "layout 'nosuch' is neither a built-in layout"),
    # the processes of a run
    ("router --listen garbage", "argument --listen: 'garbage' is not a zenoh endpoint"),
    ("router --listen tcp/127.0.0.1", "the address must be HOST:PORT"),
    ("router --connect tcp/router:0", "port '0' is not 1 to 65535"),
    ("router --exit-when-idle nan", "argument --exit-when-idle: 'nan' is not a finite number"),
    ("reservation --connect udp/", "the address must be HOST:PORT"),
    ("reservation --connect-timeout 0", "argument --connect-timeout: '0' must be a positive"),
    ("agent --id 0", "argument --id: forklift ids start at 1, not 0"),
    ("agent --id one", "argument --id: 'one' is neither a number nor 'auto'"),
    ("agent --id 1 --start 1,2", "argument --start: pose '1,2' must look like 'col,row,H'"),
    ("agent --id 1 --claim-timeout nan", "argument --claim-timeout: 'nan' is not a finite"),
    ("agent --id 1 --layout {BINARY}", "argument --layout: '{BINARY}' is not UTF-8 text"),
    ("dispatcher --speed inf", "argument --speed: 'inf' is not a finite number"),
    ("dispatcher --gather=-1", "argument --gather: '-1' must be a positive number"),
    ("dispatcher --startup-timeout 0", "argument --startup-timeout: '0' must be a positive"),
    ("dispatcher --vehicles 0", "argument --vehicles: '0' must be at least 1"),
    ("recorder --out {DIR}", "argument --out: '{DIR}' is a directory; give a file name"),
    ("recorder --out-dir {FILE}", "argument --out-dir: '{FILE}' is a file, not a directory"),
    ("recorder --foxglove 70000", "argument --foxglove: '70000' is not a TCP port"),
    ("recorder --out {DIR}/r.mcap --foxglove {BUSY}",
     "--foxglove {BUSY}: port {BUSY} on 127.0.0.1 is busy"),
    ("table --connect garbage", "argument --connect: 'garbage' is not a zenoh endpoint"),
    ("table --connect tcp/:7447", "the address must be HOST:PORT"),
    ("table --connect quack/host:7447", "the protocol must be one of tcp, udp"),
    ("table --connect-timeout nan", "argument --connect-timeout: 'nan' is not a finite"),
    ("service nosuch", "argument name: invalid choice: 'nosuch'"),
    # VDA 5050: the external session and the gateway
    ("run --mqtt tcp://host:1883", "argument --mqtt: 'tcp://host:1883' is not an MQTT broker"),
    ("run --dispatch external --layout paper004", "--dispatch external: layout paper004 is "
     "a seed-004 floor"),
    ("run --dispatch external --inprocess", "--dispatch external takes no --inprocess"),
    ("run --mqtt mqtt://127.0.0.1:1883", "--mqtt is the broker of --dispatch vda5050 or "
     "external"),
    ("run --dispatch vda5050 --faults kill_vehicle", "--dispatch vda5050 takes no --faults"),
    ("run --dispatch external --layout paper002 --mission fill", "--dispatch external "
     "--mission fill: the AGVs of lane layout paper002 park on their piles"),
    ("run --dispatch vda5050 --clock fast", "--dispatch vda5050 takes no --clock fast"),
    ("run --dispatch vda5050 --layout paper002", "layout paper002 is a lane layout, whose "
     "order missions do not go through it yet"),
    ("vda5050 gateway --state-interval 31",
     "argument --state-interval: '31' is more than 30 s"),
    ("vda5050 gateway --interface a/b",
     "argument --interface: 'a/b' is not one MQTT topic level"),
    ("bench vda5050 --vehicles 0", "argument --vehicles: '0' must be at least 1"),
    # the compose deployment (refused before docker is asked anything)
    ("compose secrets --out {FILE}", "argument --out: '{FILE}' is a file, not a directory"),
    ("compose up --vehicles 0", "argument --vehicles: '0' must be at least 1"),
    ("compose up --dispatch external --orders 3", "--dispatch external takes no --orders"),
    ("compose collect {FILE}", "argument dest: '{FILE}' is a file, not a directory"),
    # commands that are not there
    ("nosuch", "argument COMMAND: invalid choice: 'nosuch'"),
    ("help nosuch", "fleet has no command 'nosuch'"),
    ("help layout nosuch", "fleet layout has no command 'nosuch'"),
]


@pytest.mark.parametrize("row", BAD, ids=[row[0] for row in BAD])
def test_bad_input_is_refused_in_one_line_naming_it(row, paths, capsys):
    command, named, *status = row
    argv = [part.format(**paths) for part in command.split()]
    code, out, err = cli(argv, capsys)
    assert code == (status[0] if status else 2), err
    assert "Traceback" not in out + err
    lines = err.strip().splitlines()
    if status:  # a check that found problems: one line each, then their count
        assert named.format(**paths) in lines, err
    else:
        assert named.format(**paths) in lines[-1], err
        assert lines[-1].startswith("fleet") and ": error: " in lines[-1]


BAD_SCENES = [  # a --reserved file of fleet plan (on paper) -> what its refusal says
    ("extra = 1", "unknown key 'extra' (it takes filled, reservation, vehicle)"),
    ("filled = 3", "filled must be a table of cluster = stacks filled"),
    ("[filled]\ns1 = 'x'", "filled.s1: must be a whole number, not 'x'"),
    ("vehicle = 3", "vehicle entries must be [[vehicle]] tables"),
    ("[[vehicle]]\nfrom = 'p2'", "vehicle[0]: needs an integer 'id' and a 'from' place"),
    ("[[vehicle]]\nid = 9\nfrom = 'p2'", "vehicle[0].id: layout paper has forklifts 1 to 4, not 9"),
    ("[[vehicle]]\nid = 2\nfrom = 5", "vehicle[0].from: a place is a string, not 5"),
    ("[[vehicle]]\nid = 2\nfrom = 'p2'\nto = 's2#1'\nat = 'x'",
     "vehicle[0].at: must be a time in seconds, not 'x'"),
    ("[[vehicle]]\nid = 2\nfrom = 'p2'\nto = 's2#1'\nat = nan",
     "vehicle[0].at: must be a time from 0 to 1000000 seconds, not nan"),
    ("[[reservation]]\ncell = 'ab'\nt0 = 1\nvehicle = 2",
     "reservation[0].cell: a cell is [column, row], not 'ab'"),
    ("[[reservation]]\ncell = [100, 2]\nt0 = 1\nvehicle = 2",
     "reservation[0].cell: [100, 2] is off the 18 x 12 map"),
    ("[[reservation]]\ncell = [1, 2]\nt0 = 5\nt1 = 1\nvehicle = 2",
     "reservation[0]: t1 1 must be after t0 5"),
    ("[[reservation]]\ncell = [1, 2]\nt0 = 1\nt1 = inf\nvehicle = 0",
     "reservation[0].vehicle: layout paper has forklifts 1 to 4, not 0"),
]


@pytest.mark.parametrize(("text", "named"), BAD_SCENES, ids=[row[1] for row in BAD_SCENES])
def test_a_bad_reserved_file_is_refused_naming_the_entry(text, named, tmp_path, capsys):
    scene = tmp_path / "scene.toml"
    scene.write_text(text + "\n")
    code, _, err = cli(["plan", "--from", "p1", "--to", "s1#1", "--reserved", str(scene)],
                       capsys)
    assert (code, err) == (2, f"fleet plan: error: {scene}: {named}\n")


def test_an_os_error_in_a_command_is_one_line_naming_the_path(tmp_path, capsys):
    (tmp_path / "users").mkdir()  # where a login file goes
    code, _, err = cli(["compose", "secrets", "--out", str(tmp_path), "--force"], capsys)
    assert code == 2
    assert err == f"fleet compose secrets: error: {tmp_path / 'users'}: Is a directory\n"
    with pytest.raises(OSError) as raised:
        tmp_path.read_text()
    assert describe(raised.value) == f"{tmp_path}: Is a directory"


BUGS = [  # what a command's code may raise that is no fault of the user's, as the line says it
    (KeyError("no such key"), "KeyError: 'no such key'"),
    (ValueError("Sample larger than population"), "ValueError: Sample larger than population"),
    (OSError(9, "Bad file descriptor"), "OSError: Bad file descriptor"),
]


@pytest.mark.parametrize(("bug", "said"), BUGS, ids=[type(b).__name__ for b, _ in BUGS])
def test_a_bug_is_one_line_with_the_traceback_in_a_file(bug, said, tmp_path, capsys,
                                                         monkeypatch):
    """A ValueError or an OSError about no file is a bug's, never shown as bad input."""
    from fleet.commands import layout

    def broken(args):
        raise bug

    monkeypatch.setattr(layout, "run_list", broken)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    code, _, err = cli(["layout", "list"], capsys)
    assert code == EX_SOFTWARE
    [line] = err.splitlines()
    assert line.startswith(f"fleet layout list: internal error (a bug, please report it): "
                           f"{said}; the traceback is in ")
    report = Path(line.rsplit(" ", 1)[1])
    assert report.parent == tmp_path
    text = report.read_text()
    assert "fleet layout list" in text and "Traceback" in text and "broken" in text


def test_an_os_error_naming_a_file_is_the_users(tmp_path, capsys, monkeypatch):
    from fleet.commands import layout

    def full(args):
        raise OSError(28, "No space left on device", str(tmp_path / "x.toml"))

    monkeypatch.setattr(layout, "run_list", full)
    code, _, err = cli(["layout", "list"], capsys)
    assert (code, err) == (2, f"fleet layout list: error: {tmp_path / 'x.toml'}: No space "
                              f"left on device\n")


# -- properties --------------------------------------------------------------------------------

def every_parser(parser=None, path=()):
    """(command path, parser) for `fleet` and every command and action under it."""
    parser = parser or build_parser()
    yield path, parser
    for name, child in subcommands(parser).items():
        yield from every_parser(child, (*path, name))


def options():
    """(command path, action) for every argument of every command."""
    for path, parser in every_parser():
        for action in parser._actions:
            if not isinstance(action, argparse._HelpAction | argparse._VersionAction |
                              argparse._SubParsersAction):
                yield path, parser, action


def test_no_option_takes_a_bare_number_or_an_unchecked_output_path():
    """Numbers go through fleet.runtime.argtypes (finite, in range); so do files written to."""
    for path, _, action in options():
        name = " ".join(["fleet", *path, *action.option_strings[:1]])
        assert action.type not in (float, int), f"{name} takes a bare {action.type.__name__}"
        if action.dest in ("out", "png", "out_dir", "dest"):
            assert action.type is not Path, f"{name} writes where it is not checked"


NUMBERISH = st.one_of(
    st.text(),
    st.sampled_from(["nan", "NaN", "-nan", "inf", "+inf", "-inf", "Infinity", "1e999", "-1e999",
                     "0", "-0", "1e-320", "1_000", " 7 ", "0x10", "1e6", "1000000.5"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr))


@FUZZ
@given(NUMBERISH)
def test_any_text_for_a_number_is_a_finite_number_or_refused_naming_it(text):
    for check, holds in ((finite_float, lambda v: True), (positive_float, lambda v: v > 0),
                         (sim_seconds, lambda v: 0 <= v <= 1e6)):
        try:
            value = check(text)
        except argparse.ArgumentTypeError as exc:
            assert repr(text) in str(exc)
        else:
            assert math.isfinite(value) and holds(value) and value == float(text)


@FUZZ
@given(NUMBERISH)
def test_any_speed_on_the_command_line_runs_or_is_refused_naming_it(text):
    """Through the whole command line (a valid speed meets an unknown layout: no run)."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(["run", f"--speed={text}", "--layout", "no-such-layout"])
        except SystemExit as exc:
            code = exc.code
    assert code == 2 and "Traceback" not in err.getvalue()
    try:
        valid = math.isfinite(float(text)) and float(text) > 0
    except ValueError:
        valid = False
    assert ("layout 'no-such-layout'" if valid else repr(text)) in err.getvalue()


@FUZZ
@given(st.one_of(st.text(), st.builds(lambda p, h, n: f"{p}/{h}:{n}",
                                      st.sampled_from(["tcp", "udp", "tls", "quic", "ws", "x"]),
                                      st.text(max_size=8), st.integers(-5, 70000))))
def test_any_text_for_an_endpoint_is_one_or_refused_naming_it(text):
    try:
        accepted = endpoint(text)
    except argparse.ArgumentTypeError as exc:
        assert repr(text) in str(exc)
    else:
        protocol, address = accepted.split("/", 1)
        if protocol != "unixsock-stream":
            host, number = address.split("?")[0].split("#")[0].rsplit(":", 1)
            assert host and 1 <= int(number) <= 65535


@FUZZ
@given(st.integers(-10**6, 10**6))
def test_a_port_is_1_to_65535(number):
    if 1 <= number <= 65535:
        assert port(str(number)) == number
    else:
        with pytest.raises(argparse.ArgumentTypeError, match=f"'{number}' is not a TCP port"):
            port(str(number))


# -- waits that end ----------------------------------------------------------------------------

def test_a_table_at_a_dead_endpoint_fails_in_bounded_time_naming_it(capsys):
    dead = f"tcp/127.0.0.1:{free_port()}"
    start = time.monotonic()
    code, _, err = cli(["table", "--connect", dead, "--connect-timeout", "1"], capsys)
    assert time.monotonic() - start < 20  # it used to wait for ever: bounded, by its 1 s
    assert code == 2
    assert err.splitlines()[-1] == \
        f"fleet table: error: no zenoh router answers at {dead} (waited 1 s)"


def test_a_recorder_that_cannot_connect_leaves_nothing_behind(tmp_path, capsys):
    """It connects before it makes its file (or, with --out-dir, its run directory), so the
    same command can simply be tried again."""
    dead = f"tcp/127.0.0.1:{free_port()}"
    common = ["recorder", "--connect", dead, "--connect-timeout", "0.5"]
    for where in (["--out", str(tmp_path / "rec.mcap")], ["--out-dir", str(tmp_path / "runs")]):
        for _ in range(2):  # and again: the same refusal, not "rec.mcap exists"
            code, _, err = cli([*common, *where], capsys)
            assert code == 2
            assert err.splitlines()[-1] == \
                f"fleet recorder: error: no zenoh router answers at {dead} (waited 0.5 s)"
    assert list(tmp_path.iterdir()) == []


def test_waiting_for_the_router_says_the_whole_wait(tmp_path, caplog, monkeypatch):
    """fleet run tries its connect in short attempts, to notice a dead router: what it says
    it waits for is the router's whole timeout, not one attempt's."""
    from fleet.runtime import local_run as distributed
    from fleet.runtime.bus import BusConfig
    from fleet.runtime.launcher import Child

    monkeypatch.setattr(distributed, "ROUTER_TIMEOUT_MS", 2000)
    dead = f"tcp/127.0.0.1:{free_port()}"
    alive = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        with pytest.raises(distributed.RunFailed, match="the router took no connection within "
                           "2 s: no zenoh router answers at"):
            distributed._open_when_up(BusConfig("client", (dead,)),
                                      Child("router", alive, tmp_path / "router.log"))
    finally:
        alive.kill()
        alive.wait()
    said = [r.getMessage() for r in caplog.records if "waiting" in r.getMessage()]
    assert said == [f"waiting for the router at {dead} to take connections (up to 2 s)"]


def test_a_table_of_an_unknown_run_names_the_runs_there(service, capsys):
    client(service).close()  # the service is up
    common = ["table", "--mode", "peer", "--connect", service.endpoint]
    code, out, err = cli([*common, "--run", "nosuch"], capsys)
    assert code == 2, out
    assert err.splitlines()[-1] == (
        f"fleet table: error: no reservation service answers for run 'nosuch' at "
        f"{service.endpoint} (runs with one there: {service.keys.run})")
    code, out, _ = cli([*common, "--run", service.keys.run], capsys)
    assert code == 0 and out.startswith(f"{service.keys.root}: revision 0, 0 reserved")


def test_fleet_run_refuses_a_busy_port_before_starting_anything(busy_port, tmp_path, capsys):
    out = tmp_path / "run"
    code, _, err = cli(["run", "--layout", "small", "--port", str(busy_port), "--out",
                        str(out)], capsys)
    assert code == 2
    assert err == (f"fleet run: error: --port {busy_port}: port {busy_port} on 127.0.0.1 is "
                   f"busy (another process listens there)\n")
    assert not out.exists()  # nothing started, nothing written


def since_last_written(log: Path) -> float:
    """Seconds since a child last wrote its log: for one that died, since its death (so a
    bound on it holds however slowly the run's other processes started)."""
    return time.time() - log.stat().st_mtime


def test_a_router_that_dies_at_start_ends_the_run_at_once_saying_why(busy_port, tmp_path):
    """Past the command line's check (the port taken in between): the router refuses the
    port and exits; the run says so within moments, not after the connect timeout."""
    outcome = run_processes(RunSpec(Mission("small", MissionKind.FILL, Strategy.TRAFFIC), 2,
                                    tmp_path, port=busy_port))
    assert since_last_written(tmp_path / "logs" / "router.log") < 20 < ROUTER_TIMEOUT_MS / 1000
    assert outcome.done is None
    assert outcome.error == (
        f"router exited with status 2 before the run started; the last line of its log "
        f"({tmp_path / 'logs' / 'router.log'}): fleet router: error: cannot listen on "
        f"tcp/127.0.0.1:{busy_port}: the address is in use (another process listens there)")


def test_a_forklift_that_dies_before_the_mission_ends_the_run_at_once(tmp_path):
    """An agent that refuses to start would keep the dispatcher waiting for it (two minutes
    by default): the run ends as soon as it exits, with its reason."""
    outcome = run_processes(RunSpec(Mission("small", MissionKind.FILL, Strategy.TRAFFIC), 2,
                                    tmp_path, extra={"agent": ["--claim-timeout", "nan"]}))
    assert outcome.done is None
    died = re.match(r"(agent-[12]) exited with status 2 before the mission ended; the last "
                    r"line of its log", outcome.error)
    assert died, outcome.error
    startup_timeout_s = 120  # the dispatcher's default --startup-timeout
    assert since_last_written(tmp_path / "logs" / f"{died[1]}.log") < 60 < startup_timeout_s
    assert outcome.error.endswith("fleet agent: error: argument --claim-timeout: 'nan' is "
                                  "not a finite number")


# -- help --------------------------------------------------------------------------------------

def expanded_help(parser, action) -> str:
    return HelpFormatter(parser.prog)._expand_help(action)


def test_every_option_says_what_it_does_and_its_default():
    for path, parser, action in options():
        name = " ".join(["fleet", *path, *(action.option_strings[:1] or [action.dest])])
        text = expanded_help(parser, action)
        assert text.strip(), f"{name} has no help"
        takes_value = action.option_strings and action.nargs != 0 and not action.required
        if takes_value:
            assert "default" in text, f"{name}: {text!r} shows no default"
        if shows_default(action) and "default" not in (action.help or ""):
            assert f"(default {action.default})" in text


def test_every_command_and_action_says_what_it_is():
    for path, parser in every_parser():
        assert (parser.description or "").strip(), f"fleet {' '.join(path)} has no description"


def test_run_help_gives_each_strategy_a_line_and_every_default(capsys):
    assert set(STRATEGIES) == {s.value for s in Strategy}
    code, out, _ = cli(["run", "--help"], capsys)
    assert code == 0
    text = " ".join(out.split())
    for name, line in STRATEGIES.items():
        assert f"{name} {' '.join(line.split())}" in text
    for option, default in (("--strategy", "default ann"), ("--mission", "else fill"),
                            ("--seed", "default 0"), ("--speed", "default 1"),
                            ("--layout", "default paper")):
        [entry] = [line for line in out.split("\n  -") if line.startswith(option[1:])]
        assert default in " ".join(entry.split()), entry


@pytest.mark.parametrize("name", ["router", "reservation", "agent", "dispatcher", "recorder"])
def test_process_commands_describe_themselves_not_their_design(name, capsys):
    import importlib

    module = importlib.import_module({"router": "fleet.runtime.router",
                                      "reservation": "reservation.service",
                                      "agent": "vehicle_agent.process",
                                      "dispatcher": "dispatcher.process",
                                      "recorder": "recorder.process"}[name])
    code, out, _ = cli([name, "--help"], capsys)
    assert code == 0
    description = " ".join(out.split("\n\n")[1].split())
    assert description.startswith(("Run ", "Record "))
    for paragraph in module.__doc__.split("\n\n"):
        assert " ".join(paragraph.split()) not in " ".join(out.split())


def test_plain_fleet_lists_every_command(capsys):
    code, out, err = cli([], capsys)
    assert code == 0 and err == ""
    for name in subcommands(build_parser()):
        assert f"    {name}" in out
    assert "fleet help COMMAND" in " ".join(out.split())


def test_fleet_help_prints_what_help_prints(capsys):
    for path, _ in every_parser():
        code, by_flag, _ = cli([*path, "--help"], capsys)
        assert code == 0
        assert cli(["help", *path], capsys) == (0, by_flag, ""), path


# -- as a user meets them: real processes ------------------------------------------------------

def test_real_processes_refuse_bad_input_without_a_traceback(busy_port, tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "TMPDIR": str(tmp_path)}
    dead = f"tcp/127.0.0.1:{free_port()}"
    cases = {  # command line -> what the last line of stderr must hold
        ("run", "--speed", "nan"): "fleet run: error: argument --speed: 'nan' is not a "
                                   "finite number",
        ("table", "--connect", dead): f"fleet table: error: no zenoh router answers at {dead} "
                                      f"(waited 5 s)",
        ("router", "--listen", f"tcp/127.0.0.1:{busy_port}"):
            f"fleet router: error: cannot listen on tcp/127.0.0.1:{busy_port}: the address "
            f"is in use",
        ("router", "--acl", str(tmp_path / "acl.json"), "--users", str(tmp_path / "users")):
            f"fleet router: error: --acl {tmp_path / 'acl.json'}",
        ("router", "--password-file", str(tmp_path / "users")):
            "fleet router: error: --password-file needs --user",
        ("plan", "--from", "p1", "--to", "s1#1", "--png", str(ROOT / "README.md" / "x.png")):
            "is a file, not a directory",
    }
    procs = {argv: subprocess.Popen([sys.executable, "-m", "fleet", *argv], cwd=tmp_path,
                                    env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                    text=True) for argv in cases}
    errors = {}
    for argv, proc in procs.items():  # the dead endpoint used to wait for ever: not now
        out, errors[argv] = proc.communicate(timeout=60)
        assert proc.returncode == 2, (argv, errors[argv])
        assert "Traceback" not in out + errors[argv], errors[argv]
        assert cases[argv] in errors[argv].strip().splitlines()[-1], errors[argv]
    assert errors[("table", "--connect", dead)].startswith(  # said while it waited
        f"fleet table: waiting for a zenoh router at {dead} (up to 5 s)\n")
    assert list(tmp_path.iterdir()) == []  # no crash report: every failure was expected
