"""What each forklift's agent was told, in order: the engine keeps this log so that an
in-process run can drive the forklifts' states exactly as their agents would have
(fleet/recording/inprocess.py follows it with a `Drive`)."""

from __future__ import annotations

from dataclasses import dataclass

from fleet.planning.trajectory import Trajectory


@dataclass(frozen=True)
class AddLeg:
    """Drive this committed trajectory after what was added before."""

    trajectory: Trajectory
    loaded: bool  # carrying goods on it
    after: bool | None = None  # carrying goods once arrived (None: as on it; Task.after)


@dataclass(frozen=True)
class AmendLeg:
    """The last leg added is postponed (seed 002's collision rules): drive this instead."""

    trajectory: Trajectory


@dataclass(frozen=True)
class CutAt:
    """Stop after the maneuver in progress at t: the plan beyond is cancelled."""

    t: float


@dataclass(frozen=True)
class StopAt:
    """Down at t: stand where it is (and say nothing) until resumed."""

    t: float


@dataclass(frozen=True)
class ResumeAt:
    """Up again at t: complete the maneuver that was interrupted."""

    t: float


DriveOrder = AddLeg | AmendLeg | CutAt | StopAt | ResumeAt
DriveLog = dict[int, list[DriveOrder]]  # vehicle -> what it was told, in order
