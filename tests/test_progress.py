"""Progress as people expect it (fleet/commands/progress.py): on a terminal a bar that fits its
width
and redraws in place; without one a plain line every few seconds, never a carriage return;
neither runs backwards. The README's main command shows it both ways."""

import fcntl
import io
import logging
import os
import re
import signal
import struct
import subprocess
import sys
import termios
import threading
from pathlib import Path

from fleet.commands.progress import MissionProgress, ProgressBar

ROOT = Path(__file__).resolve().parent.parent
PLAIN = re.compile(r"^fill ann: (\d+)/24 stacks, t=(\d+) s, (\d+) decision failures \[\d+ s\]$")


class Clock:
    """Wall seconds set by the test."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def plain_bar(clock: Clock, total: int = 10) -> tuple[ProgressBar, io.StringIO]:
    stream = io.StringIO()  # no terminal
    return ProgressBar(total, "fill ann", stream, unit="stacks", every_s=5.0, clock=clock,
                       tick_s=None), stream  # the test ticks


def test_without_a_terminal_a_plain_line_comes_first_then_every_few_seconds_and_last():
    clock = Clock()
    bar, stream = plain_bar(clock)
    for now, done in [(0.0, 1), (1.0, 2), (4.9, 3), (5.0, 4), (7.0, 5), (9.9, 6), (10.0, 7),
                      (11.0, 8)]:
        clock.now = now
        bar.update(done, f"t={done * 10} s")
    clock.now = 12.0
    bar.close()
    text = stream.getvalue()
    assert "\r" not in text
    assert text.splitlines() == [
        "fill ann: 1/10 stacks, t=10 s [0 s]",
        "fill ann: 4/10 stacks, t=40 s [5 s]",
        "fill ann: 7/10 stacks, t=70 s [10 s]",
        "fill ann: 8/10 stacks, t=80 s [12 s]",  # the last state, at the close
    ]


def test_without_reports_the_state_is_said_again_every_few_seconds():
    """The ticker's looks at the clock: while nothing is reported (processes starting, a long
    real-time stretch without commits), the last state again every 5 s with the time gone."""
    clock = Clock()
    bar, stream = plain_bar(clock, total=24)
    progress = MissionProgress(bar)
    bar.tick()  # before the first update: nothing to say yet
    progress.status("starting the router")
    for k in range(1, 25):
        clock.now = k / 2
        bar.tick()
        if clock.now == 6.0:
            progress.status("all started; waiting for the first subtask")
        if clock.now == 11.0:
            progress(1, 0.0, 0)
    clock.now = 13.0
    bar.close()
    clock.now = 20.0
    bar.tick()  # closed: says nothing
    assert stream.getvalue().splitlines() == [
        "fill ann: 0/24 stacks, starting the router [0 s]",
        "fill ann: 0/24 stacks, starting the router [5 s]",
        "fill ann: 0/24 stacks, all started; waiting for the first subtask [10 s]",
        "fill ann: 1/24 stacks, t=0 s, 0 decision failures [13 s]",  # the last, at the close
    ]


def test_the_ticker_runs_from_the_first_update_until_the_close():
    stream = io.StringIO()
    bar = ProgressBar(10, "fill ann", stream, tick_s=3600.0)  # it would tick in an hour

    def tickers() -> int:
        return sum(t.name == "progress ticker" for t in threading.enumerate())

    before = tickers()
    bar.update(1)
    assert tickers() == before + 1
    bar.close()
    assert tickers() == before
    assert stream.getvalue() == "fill ann: 1/10 [0 s]\n"


def test_the_last_plain_line_is_not_repeated_and_a_silent_bar_writes_nothing():
    clock = Clock()
    bar, stream = plain_bar(clock)
    bar.update(10)
    clock.now = 30.0
    bar.close()
    assert stream.getvalue() == "fill ann: 10/10 stacks [0 s]\n"
    quiet = io.StringIO()
    silent = ProgressBar(10, "fill ann", quiet, enabled=False)
    silent.update(3)
    silent.close()
    assert quiet.getvalue() == ""


def test_reports_out_of_order_never_run_backwards():
    clock = Clock()
    bar, stream = plain_bar(clock, total=24)
    progress = MissionProgress(bar)
    reports = [(1, 30.0, 0), (3, 95.0, 2), (2, 60.0, 1), (4, 80.0, 1)]
    for k, (done, t, failures) in enumerate(reports):
        clock.now = 5.0 * k  # each report is due to be shown
        progress(done, t, failures)
    shown = [tuple(int(x) for x in PLAIN.match(line).groups())
             for line in stream.getvalue().splitlines()]
    assert shown == [(1, 30, 0), (3, 95, 2), (3, 95, 2), (4, 95, 2)]


def terminal(columns: int) -> tuple[int, int]:
    """A pseudo-terminal `columns` wide that passes bytes as written (no CR added)."""
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, columns, 0, 0))
    attrs = termios.tcgetattr(slave)
    attrs[1] &= ~termios.OPOST  # no output processing: "\n" stays "\n"
    termios.tcsetattr(slave, termios.TCSANOW, attrs)
    return master, slave


def read_all(fd: int) -> bytes:
    """Everything written to the terminal until every writer closed it."""
    chunks = []
    while True:
        try:
            data = os.read(fd, 65536)
        except OSError:  # EIO: no writer left
            break
        if not data:
            break
        chunks.append(data)
    return b"".join(chunks)


def bar_frames(text: str) -> tuple[list[str], list[str]]:
    """The lines, and every frame drawn on them (a carriage return starts a frame)."""
    lines = text.split("\n")
    return lines, [frame for line in lines for frame in line.split("\r") if frame]


def drawn_on_terminal(columns: int, draw) -> str:
    """What `draw(stream)` writes to a terminal `columns` wide."""
    master, slave = terminal(columns)
    out: list[bytes] = []
    reader = threading.Thread(target=lambda: out.append(read_all(master)))
    reader.start()
    with open(slave, "w", encoding="utf-8") as stream:
        draw(stream)
    reader.join(timeout=10)
    os.close(master)
    return out[0].decode()


def test_on_a_terminal_the_bar_fits_its_width_and_redraws_in_place(monkeypatch):
    monkeypatch.delenv("COLUMNS", raising=False)

    def draw(stream) -> None:
        bar = ProgressBar(136, "fill ann", stream, unit="stacks", redraw_s=0,  # draw each
                          tick_s=None)
        for done in range(1, 137, 15):
            bar.update(done, f"t={done * 14} s, {done // 3} decision failures")
        bar.update(136, "t=1972 s, 50 decision failures")
        bar.close()

    text = drawn_on_terminal(80, draw)
    _, frames = bar_frames(text)
    assert text.endswith("\n") and text.count("\n") == 1  # one line, redrawn in place
    assert len(frames) >= 10 and text.count("\r") >= 10
    assert all(len(frame) <= 80 for frame in frames), max(frames, key=len)
    assert "136/136 stacks [" in frames[-1]
    assert frames[-1].endswith(", t=1972 s, 50 decision failures]")


def test_on_a_terminal_a_long_text_loses_its_end_never_the_elapsed_time(monkeypatch):
    monkeypatch.delenv("COLUMNS", raising=False)

    def draw(stream) -> None:
        bar = ProgressBar(24, "fill ann", stream, unit="stacks", redraw_s=0, tick_s=None)
        bar.update(0, "starting the router, recorder, reservation service, 2 forklift "
                   "agents and dispatcher")
        bar.close()

    _, frames = bar_frames(drawn_on_terminal(80, draw))
    assert all(len(frame) <= 79 for frame in frames), max(frames, key=len)
    assert re.search(r"0/24 stacks \[00:00<\?, starting the router", frames[-1]), frames[-1]


def test_on_a_terminal_ticks_redraw_the_bar_and_log_records_go_above_it(monkeypatch):
    """Between reports the ticker redraws the bar (tqdm's elapsed time goes on); a log record
    said meanwhile gets a line of its own above the bar instead of breaking it."""
    monkeypatch.delenv("COLUMNS", raising=False)

    def draw(stream) -> None:
        monkeypatch.setattr(sys, "stderr", stream)  # where log records go
        bar = ProgressBar(24, "fill ann", stream, unit="stacks", redraw_s=3600, tick_s=None)
        bar.update(3, "t=90 s")  # drawn: the first frame
        bar.update(4, "t=95 s")  # within redraw_s: not drawn
        bar.tick()
        bar.tick()
        logging.getLogger("fleet.run").warning("t=95.00: kill the recorder")
        bar.close()
        bar.tick()  # closed: nothing

    text = drawn_on_terminal(80, draw)
    lines, frames = bar_frames(text)
    assert lines[-1] == "" and len(lines) == 3, lines
    assert lines[0].split("\r")[-1] == "t=95.00: kill the recorder"  # the bar cleared first
    bars = [frame for frame in frames if "fill ann" in frame]
    assert [re.search(r"(\d+)/24 stacks", b).group(1) for b in bars] == \
        ["3", "4", "4", "4", "4"], bars  # first, two ticks, redrawn after the record, closed
    assert all(b.endswith(", t=95 s]") for b in bars[1:])


def run_main_command(stderr: int | None, env: dict, tmp: Path) -> subprocess.Popen:
    """The README's main command, `fleet run`, on the small layout to be quick."""
    return subprocess.Popen([sys.executable, "-m", "fleet", "run", "--layout", "small",
                             "--out", str(tmp)], cwd=ROOT, env=env, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=stderr or subprocess.PIPE)


# A log line: with a timestamp where a process set up logging, the bare sentence where
# `fleet run` itself says it (Python's last-resort handler); never a bar's frame.
LOG_LINE = re.compile(r"(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d+ fleet\S* (INFO|WARNING|ERROR): )?"
                      r"[a-z][^|\r\n]*$")


def env_for_runs() -> dict:
    """A child's environment: this worktree's code, 80 columns, and a bar redrawn at every
    report (tqdm's TQDM_MININTERVAL), so that what it draws does not depend on timing."""
    return {**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "80", "TQDM_MININTERVAL": "0"}


def test_the_main_command_shows_progress_with_and_without_a_terminal(tmp_path):
    env = env_for_runs()
    master, slave = terminal(0)  # a terminal that does not say its size: COLUMNS does
    on_terminal = run_main_command(slave, env, tmp_path / "tty")
    os.close(slave)
    piped = run_main_command(None, env, tmp_path / "pipe")
    drawn = read_all(master).decode()
    os.close(master)
    out_tty, _ = on_terminal.communicate(timeout=300)
    out_pipe, err_pipe = piped.communicate(timeout=300)
    assert on_terminal.returncode == 0 and piped.returncode == 0, err_pipe
    assert b"mission fill on small" in out_tty and b"mission fill on small" in out_pipe

    # Without a terminal: plain progress lines, first what is being started, the last at 24.
    err = err_pipe.decode()
    assert "\r" not in err
    said = [line for line in err.splitlines() if line.startswith("fill ann: ")]
    assert re.fullmatch(r"fill ann: 0/24 stacks, starting the router, recorder, reservation "
                        r"service, 2 forklift agents and dispatcher \[\d+ s\]", said[0]), said
    plain = [PLAIN.match(line) for line in said if PLAIN.match(line)]
    assert plain and plain[-1].group(1) == "24" and said[-1] == plain[-1].group(0)
    done = [int(m.group(1)) for m in plain]
    times = [int(m.group(2)) for m in plain]
    assert done == sorted(done) and times == sorted(times)

    # On a terminal 80 columns wide: no line wider, the bar redrawn in place on one line, at
    # every report (TQDM_MININTERVAL=0): each count of stacks from 0 to 24, in order.
    lines, frames = bar_frames(drawn)
    assert all(len(frame) <= 80 for frame in frames), max(frames, key=len)
    # A log line said while the bar is shown (a slow machine: "waiting for the router ...")
    # replaces the bar's frame, ends that line and the bar goes on below: one line more.
    on_bar = [line for line in lines if "fill ann" in line]
    bar = [frame for line in on_bar for frame in line.split("\r") if frame.strip()]
    said_above = [frame for frame in bar if not frame.startswith("fill ann")]
    assert all(LOG_LINE.match(frame) for frame in said_above), said_above
    assert len(on_bar) == 1 + len(said_above), on_bar
    counts = [int(m.group(1)) for frame in bar
              if (m := re.search(r"\| (\d+)/24 stacks", frame))]
    assert counts == sorted(counts) and sorted(set(counts)) == list(range(25)), counts
    assert "24/24 stacks" in bar[-1]


def read_until(fd: int, marker: bytes) -> bytes:
    """What is written to the terminal up to (and a little past) `marker`."""
    seen = b""
    while marker not in seen:
        try:
            data = os.read(fd, 65536)
        except OSError:  # EIO: no writer left
            data = b""
        assert data, f"the terminal closed before {marker!r}: {seen!r}"
        seen += data
    return seen


def children_of(pid: int) -> dict[int, str]:
    """The processes `pid` started, with their command lines (from /proc: a process's stat
    names its parent after its command's name in parentheses). A child that has only just
    been started may not show its command line yet."""
    children = {}
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and \
                    int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                children[int(entry.name)] = \
                    (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:  # gone meanwhile
            continue
    return children


def test_when_a_child_dies_the_bar_ends_before_the_failure_is_said(tmp_path):
    master, slave = terminal(80)
    run = run_main_command(slave, env_for_runs(), tmp_path)
    os.close(slave)
    drawn = read_until(master, b"all started")  # every child started, the recorder long since
    recorder = next(k for k, line in children_of(run.pid).items() if " fleet recorder " in line)
    os.kill(recorder, signal.SIGKILL)
    drawn += read_all(master)
    os.close(master)
    run.communicate(timeout=120)
    assert run.returncode == 1
    lines = drawn.decode().split("\n")
    failed = next((i for i, line in enumerate(lines)
                   if line.startswith("fleet run: the mission did not finish: ")), None)
    assert failed is not None, lines
    assert "recorder exited with status -9 (killed by SIGKILL)" in lines[failed]
    assert "fill ann" in lines[failed - 1]  # the bar, ended on its own line
    # Then the summary of what the torn recording holds, if it holds the mission's start.
    assert lines[-2:] == [f"fleet run: logs and what was recorded are in {tmp_path}", ""]
