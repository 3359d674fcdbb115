"""Progress as people expect it (fleet/progress.py): on a terminal a bar that fits its width
and redraws in place; without one a plain line every few seconds, never a carriage return;
neither runs backwards. The README's main command shows it both ways."""

import fcntl
import io
import os
import re
import struct
import subprocess
import sys
import termios
import threading
from pathlib import Path

from fleet.progress import MissionProgress, ProgressBar

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
    return ProgressBar(total, "fill ann", stream, unit="stacks", every_s=5.0,
                       clock=clock), stream


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


def test_on_a_terminal_the_bar_fits_its_width_and_redraws_in_place(monkeypatch):
    monkeypatch.delenv("COLUMNS", raising=False)
    master, slave = terminal(80)
    out: list[bytes] = []
    reader = threading.Thread(target=lambda: out.append(read_all(master)))
    reader.start()
    with open(slave, "w", encoding="utf-8") as stream:
        bar = ProgressBar(136, "fill ann", stream, unit="stacks", redraw_s=0)  # draw each
        for done in range(1, 137, 15):
            bar.update(done, f"t={done * 14} s, {done // 3} decision failures")
        bar.update(136, "t=1972 s, 50 decision failures")
        bar.close()
    reader.join(timeout=10)
    os.close(master)
    text = out[0].decode()
    _, frames = bar_frames(text)
    assert text.endswith("\n") and text.count("\n") == 1  # one line, redrawn in place
    assert len(frames) >= 10 and text.count("\r") >= 10
    assert all(len(frame) <= 80 for frame in frames), max(frames, key=len)
    assert "136/136 stacks, t=1972 s, 50 decision failures" in frames[-1]


def run_main_command(stderr: int | None, env: dict, tmp: Path) -> subprocess.Popen:
    """The README's main command, `fleet run`, on the small layout to be quick."""
    return subprocess.Popen([sys.executable, "-m", "fleet", "run", "--layout", "small",
                             "--out", str(tmp)], cwd=ROOT, env=env, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=stderr or subprocess.PIPE)


def test_the_main_command_shows_progress_with_and_without_a_terminal(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "80"}
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

    # Without a terminal: plain progress lines, the first and the last at least.
    err = err_pipe.decode()
    assert "\r" not in err
    plain = [PLAIN.match(line) for line in err.splitlines() if PLAIN.match(line)]
    assert len(plain) >= 2 and plain[-1].group(1) == "24"
    done = [int(m.group(1)) for m in plain]
    times = [int(m.group(2)) for m in plain]
    assert done == sorted(done) and times == sorted(times)

    # On a terminal 80 columns wide: no line wider, the bar redrawn in place on one line.
    lines, frames = bar_frames(drawn)
    assert all(len(frame) <= 80 for frame in frames), max(frames, key=len)
    on_bar = [line for line in lines if "fill ann" in line]
    assert len(on_bar) == 1 and on_bar[0].count("\r") >= 2
    assert "24/24 stacks" in on_bar[0].split("\r")[-1]
