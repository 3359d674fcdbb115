"""How a command's process lives: it starts from its own command line (`python -m dispatcher`
as `fleet dispatcher`), logs to stderr, stops cleanly on a signal or when the `fleet run` that
started it is gone, and fails in one line that says why (a bug: with the traceback in a file).
The `fleet` command line and every process share this one error path."""

from __future__ import annotations

import contextlib
import faulthandler
import logging
import os
import signal
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from typing import NoReturn, TypeVar

import zenoh

from fleet import __version__
from fleet.errors import UserError, describe
from fleet.runtime.bus import RequestFailed, zenoh_message
from fleet.runtime.helptext import Parser
from fleet.runtime.process_configs import ProcessConfig

EX_SOFTWARE = 70  # sysexits.h: an internal error (a bug), not the user's
# What a command may fail with for reasons outside the program: bad input (every check of it
# raises a UserError), the network. Each reaches the user as one line; anything else is a bug
# (a ValueError too: a value the user gave is refused as a UserError).
EXPECTED: tuple[type[BaseException], ...] = (UserError, zenoh.ZError, RequestFailed)
PARENT_ENV = "FLEET_PARENT_PID"  # set by fleet run for its children
# How long an orphan (its fleet run killed outright) may take to stop cleanly before it
# writes every thread's stack to its log and exits all the same: nobody is left to stop it.
ORPHAN_GRACE_S = 20.0

C = TypeVar("C", bound=ProcessConfig)


def process_main(kind: type[C], serve: Callable[[C], int], prog: str,
                 argv: Sequence[str] | None = None) -> int:
    """A process started on its own (`python -m dispatcher`): its parser is the one `fleet
    dispatcher` has, its config is built once from the flags and handed to `serve`."""
    parser = Parser(prog=prog, description=kind.DESCRIPTION, epilog=kind.EPILOG)
    kind.add_arguments(parser)
    args = parser.parse_args(argv)
    setup_logging()
    watch_parent()
    return exit_status(prog, [prog, *(sys.argv[1:] if argv is None else argv)],
                       lambda: serve(kind.from_args(args)))


def leave(code: int) -> NoReturn:
    """End a process of a run once its command has returned `code`, without the
    interpreter's teardown: that frees every object one by one, and a planner's caches hold
    millions (0.5 s for an agent, 1 s for a dispatcher, most of a run's stop;
    docs/benchmarks.md). Nothing is lost: each process closes its session, recording and
    journal on the way out, and writes its journals through at every record (a fault's
    SIGKILL loses nothing either); the logs and standard streams are flushed here."""
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):  # a reader gone, or a stream closed
            stream.flush()
    os._exit(code)


def exit_status(prog: str, command: Sequence[str], body: Callable[[], int | None],
                expected_errors: tuple[type[BaseException], ...] = EXPECTED) -> int:
    """Run a command's body and return its exit status. A failure reaches the user as one
    line naming `prog`: an expected one (2) as its message, a bug (EX_SOFTWARE) with its
    traceback in a crash report that names the `command` line."""
    try:
        code = int(body() or 0)
        sys.stdout.flush()  # a reader that left shows here, not in a message at exit
        return code
    except KeyboardInterrupt:
        print(f"\n{prog}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader left (`fleet faults list | head`): nothing to say
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no flush error
        return 141
    except Exception as exc:
        if expected(exc, expected_errors):
            text = zenoh_message(exc) if isinstance(exc, zenoh.ZError) else describe(exc)
            print(f"{prog}: error: {text}", file=sys.stderr)
            return 2
        path = crash_report(exc, command)
        print(f"{prog}: internal error (a bug, please report it): "
              f"{type(exc).__name__}: {describe(exc)}; the traceback is in {path}",
              file=sys.stderr)
        return EX_SOFTWARE


def expected(exc: BaseException,
             expected_errors: tuple[type[BaseException], ...] = EXPECTED) -> bool:
    """Whether `exc` is a failure outside the program. An OS error is one when it names its
    file (a path the user gave that cannot be read or written, a full disk): the line says
    which; one about no file is a bug's."""
    if isinstance(exc, OSError):
        return exc.filename is not None
    return isinstance(exc, expected_errors)


def crash_report(exc: BaseException, command: Sequence[str]) -> str:
    """Write the command line and the traceback to a file in the temporary directory."""
    fd, path = tempfile.mkstemp(prefix=f"fleet-crash-{time.strftime('%Y%m%d-%H%M%S')}-",
                                suffix=".txt")
    with os.fdopen(fd, "w") as out:
        out.write(f"fleet {__version__}: {' '.join(command)}\n\n")
        out.write("".join(traceback.format_exception(exc)))
    return path


class Stopped(Exception):
    """SIGTERM or SIGINT: the process leaves whatever it was doing (its handler raises this
    where the main thread is)."""


def setup_logging() -> None:
    """Processes log to stderr with a wall-clock timestamp (fleet run keeps one file each);
    SIGUSR1 writes every thread's stack there (what a stuck process is doing)."""
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(asctime)s %(name)s %(levelname)s: %(message)s")
    faulthandler.register(signal.SIGUSR1, file=sys.__stderr__, all_threads=True)


def stop_on_signals(stop: Callable[[], None]) -> None:
    """SIGTERM and SIGINT ask the process to stop cleanly (and so close its session)."""
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop())


def watch_parent() -> None:
    """A child of `fleet run` stops when that parent is gone (killed outright, it could not
    stop its children), so no orphan keeps running: it sends itself SIGTERM (a clean stop
    once `stop_on_signals` is set up, before that the end), and one that has not stopped
    ORPHAN_GRACE_S later (a wait that a stop does not cut short) exits with every thread's
    stack in its log."""
    parent = os.environ.get(PARENT_ENV)
    if not (parent and parent.isdigit()):
        return

    def watch() -> None:
        while os.getppid() == int(parent):
            time.sleep(1.0)  # polling the parent: there is no event to wait on
        logging.getLogger("fleet.runtime").warning(
            "fleet run (pid %s) is gone: stopping (at the latest in %g s)", parent,
            ORPHAN_GRACE_S)
        # faulthandler's own thread: it needs no GIL, so even a stuck call is cut short
        faulthandler.dump_traceback_later(ORPHAN_GRACE_S, exit=True, file=sys.__stderr__)
        os.kill(os.getpid(), signal.SIGTERM)  # the handler runs in the main thread

    threading.Thread(target=watch, daemon=True, name="parent-watch").start()
