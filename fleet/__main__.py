"""`python -m fleet`, as `fleet`; a process of a run (as fleet run starts each: `python -m fleet
agent ...`) ends without the interpreter's teardown (`leave`)."""

import sys

from fleet.cli import main
from fleet.commands.processes import alone
from fleet.runtime.lifecycle import leave

code = main()
if alone(sys.argv[1:]) is not None:
    leave(code)
sys.exit(code)
