"""`fleet` command line: argument parsing and the one error path; the work lives in
fleet.commands.*."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import NoReturn

from fleet import __version__
from fleet.commands import processes
from fleet.errors import UserError
from fleet.runtime import lifecycle
from fleet.runtime.helptext import Parser


def build_parser() -> argparse.ArgumentParser:
    # Here, not at the top: a process of a run (`fleet agent`) needs none of them.
    from fleet.commands import (
        analyze,
        bench,
        compare,
        compose,
        faults,
        layout,
        plan,
        plot,
        run,
        runs,
        service,
        train,
        vda5050,
    )

    parser = Parser(
        prog="fleet", description="Emulator for fleets of autonomous warehouse forklifts: "
        "run a mission as processes on zenoh, record it, and look at the recording.",
        epilog="`fleet help COMMAND [ACTION]` (or `fleet COMMAND --help`) says what a "
        "command's options do and their defaults. Start with `fleet run`; README.md and "
        "docs/ tell the rest.")
    parser.add_argument("--version", action="version", version=f"fleet {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")
    for module in (run, runs, analyze, plot, compare, faults, plan, layout, train, bench,
                   processes, service, compose, vda5050):
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
    words = list(sys.argv[1:] if argv is None else argv)
    process = processes.alone(words)
    if process is not None:  # `fleet agent ...` as fleet run and compose start one
        return process()
    from fleet.runtime.local_run import RunFailed

    parser = build_parser()
    args = parser.parse_args(words)
    if args.command is None:  # plain `fleet`: what there is to do
        parser.print_help()
        return 0
    # Besides what every process may fail with: a run's processes (`fleet run`).
    expected = (*lifecycle.EXPECTED, RunFailed)
    return lifecycle.exit_status(args.prog, ["fleet", *words], lambda: args.handler(args),
                                 expected)


def entry() -> NoReturn:
    """The `fleet` command and `python -m fleet`: main's exit status. A process of a run (as
    fleet run and compose start each: `fleet agent ...`) ends without the interpreter's
    teardown (`lifecycle.leave`)."""
    process = processes.alone(sys.argv[1:])
    if process is not None:
        lifecycle.leave(process())
    sys.exit(main())


if __name__ == "__main__":
    entry()
