"""Argument types of the command line: each checks one kind of value where it enters, so
every command refuses it the same way, in one line that names the value and why (argparse
prints `fleet CMD: error: argument --X: <that line>`)."""

from __future__ import annotations

import argparse
import codecs
import errno
import math
import os
import re
import socket
from pathlib import Path

from fleet.mission.battery import parse_battery

# The zenoh link protocols whose address is HOST:PORT, and the one whose address is a path.
HOST_PORT_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")
PATH_PROTOCOLS = ("unixsock-stream",)
_ENDPOINT = re.compile(r"(?P<protocol>[^/]*)/(?P<address>[^?#]*)(?P<options>[?#].*)?")


def _refuse(text: str, why: str) -> argparse.ArgumentTypeError:
    return argparse.ArgumentTypeError(f"{text!r} {why}")


def finite_float(text: str) -> float:
    """A number, never NaN or infinite (a NaN speed stalls a clock, an infinite one breaks
    the dispatcher's arithmetic)."""
    try:
        value = float(text)
    except ValueError:
        raise _refuse(text, "is not a number") from None
    if not math.isfinite(value):
        raise _refuse(text, "is not a finite number")
    return value


def positive_float(text: str) -> float:
    value = finite_float(text)
    if value <= 0:
        raise _refuse(text, "must be a positive number")
    return value


def non_negative_float(text: str) -> float:
    value = finite_float(text)
    if value < 0:
        raise _refuse(text, "must be 0 or a positive number")
    return value


def lookahead_arg(text: str) -> float:
    """Seconds from 0 up, or "none" (no bound: infinity)."""
    if text.strip().lower() == "none":
        return math.inf
    try:
        return non_negative_float(text)
    except argparse.ArgumentTypeError:
        raise _refuse(text, "must be 0 or a positive number of seconds, or none") from None


def lookahead_text(value: float) -> str:
    """The flag's text for `value` (lookahead_arg's inverse)."""
    return "none" if math.isinf(value) else repr(value)


def key_expr(text: str) -> str:
    """A concrete zenoh key: chunks of anything but `*`, `$`, `?`, `#` and spaces,
    separated by single slashes."""
    chunks = text.split("/")
    if not text or any(not c or re.search(r"[*$?#\s]", c) for c in chunks):
        raise _refuse(text, "is no concrete zenoh key (e.g. fleet/RUN/router/b/linked)")
    return text


MAX_SIM_SECONDS = 1e6  # days of simulated time: beyond any mission (as fault scenarios say)


def sim_seconds(text: str) -> float:
    """A simulated time in seconds: from 0 to MAX_SIM_SECONDS."""
    value = finite_float(text)
    if not 0 <= value <= MAX_SIM_SECONDS:
        raise _refuse(text, f"must be a time from 0 to {MAX_SIM_SECONDS:.0f} seconds")
    return value


def integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise _refuse(text, "is not a whole number") from None


def positive_int(text: str) -> int:
    value = integer(text)
    if value < 1:
        raise _refuse(text, "must be at least 1")
    return value


def non_negative_int(text: str) -> int:
    value = integer(text)
    if value < 0:
        raise _refuse(text, "must not be negative")
    return value


def positive_ints(text: str) -> list[int]:
    """Whole numbers of at least 1, comma-separated: 25,50,100."""
    try:
        values = [int(part) for part in text.split(",")]
    except ValueError:
        raise _refuse(text, "is not a comma-separated list of whole numbers, e.g. "
                      "25,50,100") from None
    if any(v < 1 for v in values):
        raise _refuse(text, "must list numbers of at least 1, e.g. 25,50,100")
    return values


def positive_floats(text: str) -> list[float]:
    """Positive numbers, comma-separated: 1,2,4."""
    values = []
    for part in text.split(","):
        try:
            values.append(positive_float(part))
        except argparse.ArgumentTypeError:
            raise _refuse(text, "must list positive numbers, comma-separated, e.g. "
                          "1,2,4") from None
    return values


def pose(text: str):
    """A pose 'col,row,H' (fleet.planning.trajectory.Pose)."""
    from fleet.planning.trajectory import Pose

    try:
        return Pose.parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def port(text: str) -> int:
    value = integer(text)
    if not 1 <= value <= 65535:
        raise _refuse(text, "is not a TCP port (1 to 65535)")
    return value


def endpoint(text: str) -> str:
    """A zenoh endpoint: PROTOCOL/HOST:PORT (tcp/127.0.0.1:7447, tcp/router:7447,
    tcp/[::1]:7447) or unixsock-stream/PATH, optionally with zenoh's ?metadata or #config."""
    form = "is not a zenoh endpoint such as tcp/127.0.0.1:7447"
    match = _ENDPOINT.fullmatch(text)
    if match is None:
        raise _refuse(text, form)
    protocol, address = match["protocol"], match["address"]
    if protocol in PATH_PROTOCOLS:
        if not address:
            raise _refuse(text, f"{form}: {protocol}/ needs a socket path")
        return text
    if protocol not in HOST_PORT_PROTOCOLS:
        known = ", ".join((*HOST_PORT_PROTOCOLS, *PATH_PROTOCOLS))
        raise _refuse(text, f"{form}: the protocol must be one of {known}")
    host, colon, port_text = address.rpartition(":")
    if not colon or not host or host in ("[", "[]"):
        raise _refuse(text, f"{form}: the address must be HOST:PORT")
    if not port_text.isdigit() or not 1 <= int(port_text) <= 65535:
        raise _refuse(text, f"{form}: port {port_text!r} is not 1 to 65535")
    return text


_MQTT_URL = re.compile(r"mqtt://(?P<host>[^:/\s]+|\[[0-9a-fA-F:.]+\])(?::(?P<port>\d+))?/?")
MQTT_PORT = 1883


def mqtt_url(text: str) -> str:
    """An MQTT broker: mqtt://HOST[:PORT] (port 1883 if none)."""
    match = _MQTT_URL.fullmatch(text)
    if match is None:
        raise _refuse(text, "is not an MQTT broker URL such as mqtt://127.0.0.1:1883")
    if match["port"] is not None and not 1 <= int(match["port"]) <= 65535:
        raise _refuse(text, f"names port {match['port']}, not 1 to 65535")
    return text


def mqtt_host_port(url: str) -> tuple[str, int]:
    """The host and port of an URL `mqtt_url` took."""
    match = _MQTT_URL.fullmatch(url)
    assert match is not None, url
    return match["host"].strip("[]"), int(match["port"] or MQTT_PORT)


def topic_level(text: str) -> str:
    """One level of an MQTT topic: not empty, no '/', '+', '#' (VDA 5050 6.1)."""
    if not text or any(c in text for c in "/+#") or text != text.strip():
        raise _refuse(text, "is not one MQTT topic level (no '/', '+', '#' or spaces)")
    return text


def state_interval(text: str) -> float:
    """Seconds between states: VDA 5050 2.0.0 (6.10) wants one at least every 30 s."""
    value = positive_float(text)
    if value > 30:
        raise _refuse(text, "is more than 30 s: a state is due at least every 30 s "
                      "(VDA 5050 2.0.0, 6.10)")
    return value


def _path(text: str) -> Path:
    if "\0" in text:  # the OS refuses it; say so rather than fail inside pathlib
        raise _refuse(text, "is not a path (it holds a NUL character)")
    return Path(text)


def _writable_dir_problem(folder: Path) -> str | None:
    """Why files cannot be made in `folder`, or what is in the way of making it."""
    ancestor = folder
    while not ancestor.exists():  # the nearest part that is there decides
        if ancestor.parent == ancestor:
            break
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        return f"{ancestor} is a file, not a directory"
    if not os.access(ancestor, os.W_OK | os.X_OK):
        return f"directory {ancestor} is not writable"
    return None


def writable_file(text: str) -> Path:
    """A file to write: not a directory, in a directory that exists and may be written."""
    path = _path(text)
    if path.is_dir():
        raise _refuse(text, "is a directory; give a file name")
    folder = path.parent
    if not folder.exists():
        raise _refuse(text, f"cannot be written: directory {folder} does not exist")
    problem = _writable_dir_problem(folder)
    if problem is None and path.exists() and not os.access(path, os.W_OK):
        problem = "it is not writable"
    if problem is not None:
        raise _refuse(text, f"cannot be written: {problem}")
    return path


def png_file(text: str) -> Path:
    """A PNG file to write (matplotlib would add .png to another name and write there)."""
    path = writable_file(text)
    if path.suffix.lower() != ".png":
        raise _refuse(text, "must end in .png")
    return path


def writable_dir(text: str) -> Path:
    """A directory to write into: there, or to be made (with its parents)."""
    path = _path(text)
    if path.exists() and not path.is_dir():
        raise _refuse(text, "is a file, not a directory")
    problem = _writable_dir_problem(path)
    if problem is not None:
        raise _refuse(text, f"cannot be written: {problem}")
    return path


def text_file(text: str) -> Path:
    """A file to read, of UTF-8 text (every file the commands read is TOML, JSON or lines,
    and a decoding error deep in a loader would not say which file it was)."""
    path = _path(text)
    if not path.exists():
        raise _refuse(text, "does not exist")
    if path.is_dir():
        raise _refuse(text, "is a directory, not a file")
    problem = _not_text(path)
    if problem is not None:
        raise _refuse(text, problem)
    return path


def orders_arg(text: str) -> int | tuple[str, ...]:
    """`--orders`: a number of orders (drawn with the seed), a file of shelf names (one a
    line, `#` starts a comment), or the shelf names themselves, comma-separated; the shelves
    are checked against the layout later, each order named."""
    stripped = text.strip()
    if stripped.isdigit():
        return positive_int(stripped)
    path = Path(text)
    if "," not in text and path.suffix and not path.is_file():
        raise _refuse(text, "is no number of orders, no file and no list of shelves")
    if path.is_file():
        try:
            lines = path.read_text(encoding="utf-8").splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            raise _refuse(text, f"cannot be read: {exc}") from None
        shelves = tuple(line.split("#", 1)[0].strip() for line in lines)
        where = f"file {text}"
    else:
        shelves = tuple(part.strip() for part in text.split(","))
        where = "the list"
    shelves = tuple(s for s in shelves if s) if path.is_file() else shelves
    if not shelves:
        raise _refuse(text, "names no shelf")
    if "" in shelves:
        raise _refuse(text, f"has an empty shelf name in {where}")
    return shelves


def battery_arg(text: str) -> str:
    """A `--battery` text (fleet.mission.battery.parse_battery), checked, kept as given."""
    try:
        parse_battery(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def layout_arg(text: str) -> str:
    """A built-in layout's name or a text file (what fleet.world.layout_file.load_layout takes)."""
    from fleet.world.layout_file import builtin_names

    return _name_or_text_file(text, builtin_names())


def scenario_arg(text: str) -> str:
    """A shipped fault scenario's name or a text file (fleet.mission.faults.load_scenario)."""
    from fleet.mission.faults import builtin_scenarios

    return _name_or_text_file(text, builtin_scenarios())


def _name_or_text_file(text: str, names: list[str]) -> str:
    """A name the loader knows (it says what else it takes), or a file of text."""
    if text not in names and "\0" not in text and Path(text).is_file():
        problem = _not_text(Path(text))
        if problem is not None:
            raise _refuse(text, problem)
    return text


def _not_text(path: Path) -> str | None:
    decoder = codecs.getincrementaldecoder("utf-8")()
    offset = 0
    try:
        with open(path, "rb") as f:
            while chunk := f.read(1 << 20):
                decoder.decode(chunk)
                offset += len(chunk)
            decoder.decode(b"", final=True)
    except OSError as exc:
        return f"cannot be read: {exc.strerror}"
    except UnicodeDecodeError as exc:
        return f"is not UTF-8 text (near byte {offset + exc.start})"
    return None


def port_problem(number: int, host: str = "127.0.0.1") -> str | None:
    """Why nothing could listen on host:number now (busy, not allowed), or None."""
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as zenoh: TIME_WAIT is free
        try:
            s.bind((host, number))
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                return f"port {number} on {host} is busy (another process listens there)"
            return f"cannot listen on {host}:{number}: {exc.strerror}"
    return None
