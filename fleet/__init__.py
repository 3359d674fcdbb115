"""The forklift fleet emulator: the planner and its reservation table, the warehouse
layouts, the wire protocol, the dispatching, the run of a mission (in one process or as
processes on zenoh), its MCAP recording, the views and analysis of a run, and the command
line, each in a sub-package of its own. docs/architecture.md maps them and what each may
import."""

__version__ = "0.1.0"
