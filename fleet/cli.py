"""`fleet` command line: argument parsing and the one error path; the work lives in
fleet.commands.*."""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
import traceback
from collections.abc import Sequence

import zenoh

from fleet import __version__
from fleet.commands import (
    analyze,
    bench,
    compare,
    compose,
    faults,
    layout,
    plan,
    plot,
    processes,
    run,
    runs,
    service,
    train,
)
from fleet.commands.helptext import Parser
from fleet.errors import UserError, describe
from fleet.runtime.bus import RequestFailed, zenoh_message
from fleet.runtime.local_run import RunFailed

EX_SOFTWARE = 70  # sysexits.h: an internal error (a bug), not the user's
# What a command may fail with for reasons outside the program: bad input (every check of it
# raises a UserError), the network, a run's processes. Each reaches the user as one line;
# anything else is a bug (a ValueError too: a value the user gave is refused as a UserError).
EXPECTED = (UserError, zenoh.ZError, RequestFailed, RunFailed)


def expected(exc: BaseException) -> bool:
    """Whether `exc` is a failure outside the program. An OS error is one when it names its
    file (a path the user gave that cannot be read or written, a full disk): the line says
    which; one about no file is a bug's."""
    if isinstance(exc, OSError):
        return exc.filename is not None
    return isinstance(exc, EXPECTED)


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="fleet", description="Emulator for fleets of autonomous warehouse forklifts: "
        "run a mission as processes on zenoh, record it, and look at the recording.",
        epilog="`fleet help COMMAND [ACTION]` (or `fleet COMMAND --help`) says what a "
        "command's options do and their defaults. Start with `fleet run`; README.md and "
        "docs/ tell the rest.")
    parser.add_argument("--version", action="version", version=f"fleet {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")
    for module in (run, runs, analyze, plot, compare, faults, plan, layout, train, bench,
                   processes, service, compose):
        module.register(sub)
    helper = sub.add_parser("help", help="say what a command does and its options (as "
                            "COMMAND --help)",
                            description="Print the help of a command (or of an action of "
                            "one, e.g. `fleet help layout check`); without one, the list of "
                            "commands.")
    helper.add_argument("topic", nargs="*", metavar="COMMAND",
                        help="the command, and its action if it has some")
    helper.set_defaults(handler=lambda args: print_help(parser, args.topic))
    _name_commands(parser)
    return parser


def _name_commands(parser: argparse.ArgumentParser) -> None:
    """Each parser sets `prog` to its command line (`fleet faults check`): the deepest one
    parsed wins, so an error names the very command that failed."""
    parser.set_defaults(prog=parser.prog)
    for child in subcommands(parser).values():
        _name_commands(child)


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """A parser's subcommands by name (empty: it has none)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def print_help(parser: argparse.ArgumentParser, topic: Sequence[str]) -> int:
    """`fleet help CMD [ACTION]`: the same text as `fleet CMD [ACTION] --help`."""
    for i, word in enumerate(topic):
        choices = subcommands(parser)
        if word not in choices:
            where = " ".join(["fleet", *topic[:i]])
            known = ", ".join(choices) if choices else "none"
            raise UserError(f"{where} has no command {word!r} (its commands: {known})")
        parser = choices[word]
    print(parser.format_help(), end="")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:  # plain `fleet`: what there is to do
        parser.print_help()
        return 0
    try:
        code = int(args.handler(args) or 0)
        sys.stdout.flush()  # a reader that left shows here, not in a message at exit
        return code
    except KeyboardInterrupt:
        print(f"\n{args.prog}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader left (`fleet faults list | head`): nothing to say
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no flush error
        return 141
    except Exception as exc:
        if expected(exc):
            text = zenoh_message(exc) if isinstance(exc, zenoh.ZError) else describe(exc)
            print(f"{args.prog}: error: {text}", file=sys.stderr)
            return 2
        # a bug: one line here, the traceback in a file for the report
        path = crash_report(exc, sys.argv[1:] if argv is None else argv)
        print(f"{args.prog}: internal error (a bug, please report it): "
              f"{type(exc).__name__}: {describe(exc)}; the traceback is in {path}",
              file=sys.stderr)
        return EX_SOFTWARE


def crash_report(exc: BaseException, argv: Sequence[str]) -> str:
    """Write the command line and the traceback to a file in the temporary directory."""
    fd, path = tempfile.mkstemp(prefix=f"fleet-crash-{time.strftime('%Y%m%d-%H%M%S')}-",
                                suffix=".txt")
    with os.fdopen(fd, "w") as out:
        out.write(f"fleet {__version__}: fleet {' '.join(argv)}\n\n")
        out.write("".join(traceback.format_exception(exc)))
    return path


if __name__ == "__main__":
    sys.exit(main())
