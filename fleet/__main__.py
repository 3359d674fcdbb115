"""`python -m fleet`, as `fleet`."""

from fleet.cli import entry

entry()
