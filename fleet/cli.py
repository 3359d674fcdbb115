"""`fleet` command line: argument parsing only; the work lives in fleet.commands.*."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

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
    run,
    runs,
    service,
    services,
    train,
)
from fleet.errors import UserError


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fleet", description="Emulator for fleets of autonomous warehouse forklifts.")
    parser.add_argument("--version", action="version", version=f"fleet {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in (run, runs, analyze, plot, compare, faults, plan, layout, train, bench,
                   services, service, compose):
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = int(args.handler(args) or 0)
        sys.stdout.flush()  # a reader that left shows here, not in a message at exit
        return code
    except (UserError, ValueError, FileNotFoundError) as exc:
        print(f"fleet {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"\nfleet {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader left (`fleet faults list | head`): nothing to say
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no flush error
        return 141


if __name__ == "__main__":
    sys.exit(main())
