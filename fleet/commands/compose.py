"""`fleet compose`: the compose deployment's chores, so nobody types docker's long forms
(docs/deployment.md). `up` runs a mission and analyses it, `collect` copies recordings out
of the volume, `analyze` looks at the latest one."""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

from fleet.errors import UserError

DEFAULT_PROJECT = "forklift-fleet"  # also in .env, which both compose tools read


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compose", help="run and inspect the docker compose deployment",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--project", default=os.environ.get("COMPOSE_PROJECT_NAME", DEFAULT_PROJECT),
                   help=f"compose project name (default $COMPOSE_PROJECT_NAME or "
                   f"{DEFAULT_PROJECT})")
    p.add_argument("--file", type=Path, default=Path("compose.yaml"),
                   help="the compose file (default compose.yaml here)")
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    up = actions.add_parser("up", help="run a mission with N forklifts, then analyse it")
    up.add_argument("--vehicles", type=int, default=4, help="forklift containers (default 4)")
    up.add_argument("--build", action="store_true", help="build the image first")
    up.set_defaults(handler=run_up)
    collect = actions.add_parser("collect", help="copy recordings out of the volume")
    collect.add_argument("dest", type=Path, nargs="?", default=Path("runs/compose"))
    collect.add_argument("--all", action="store_true", help="every recording, not the latest")
    collect.set_defaults(handler=run_collect)
    analyze = actions.add_parser("analyze", help="analyse the latest recording in the volume")
    analyze.add_argument("--json", action="store_true")
    analyze.add_argument("--dest", type=Path, default=Path("runs/compose"),
                         help="where its copy goes (default runs/compose)")
    analyze.set_defaults(handler=run_analyze)


def compose_command() -> list[str]:
    """`docker compose` (the plugin) where it exists, else Debian's `docker-compose`."""
    if shutil.which("docker") and subprocess.run(
            ["docker", "compose", "version"], capture_output=True).returncode == 0:
        return ["docker", "compose"]
    if shutil.which("docker-compose"):
        return ["docker-compose"]
    raise UserError("neither `docker compose` nor `docker-compose` is installed")


def run_up(args: argparse.Namespace) -> int:
    up = [*compose_command(), "-p", args.project, "-f", str(args.file), "up", "--scale",
          f"vehicle={args.vehicles}", *(["--build"] if args.build else [])]
    print("$ " + " ".join(up), file=sys.stderr)
    # In the foreground: every container's log shows how far it is; the mission's processes
    # exit when it ends, the router last, and `up` returns then.
    if subprocess.run(up).returncode not in (0, 130):
        raise UserError("docker compose up failed (its output is above)")
    return run_analyze(argparse.Namespace(project=args.project, json=False,
                                          dest=Path("runs/compose")))


def volume(project: str) -> str:
    return f"{project}_recordings"


def image() -> str:
    return os.environ.get("FLEET_IMAGE", "forklift-fleet:latest")


def in_volume(project: str, *command: str, **kwargs) -> subprocess.CompletedProcess:
    """Run a command in a throwaway container of the image with the recordings mounted."""
    if subprocess.run(["docker", "volume", "inspect", volume(project)],
                      capture_output=True).returncode != 0:
        raise UserError(f"no volume {volume(project)}: has project {project!r} run yet?")
    return subprocess.run(["docker", "run", "--rm", "-v", f"{volume(project)}:/recordings:ro",
                           "--entrypoint", command[0], image(), *command[1:]], **kwargs)


def recordings(project: str) -> list[str]:
    """The run directories in the volume, oldest first (they are named by date-time)."""
    listing = in_volume(project, "ls", "-1", "/recordings", capture_output=True, text=True)
    if listing.returncode != 0:
        raise UserError(f"cannot list {volume(project)}: {listing.stderr.strip()}")
    return sorted(line for line in listing.stdout.split() if line)


def collect(project: str, dest: Path, every: bool) -> list[Path]:
    names = recordings(project)
    if not names:
        raise UserError(f"{volume(project)} holds no recording yet")
    chosen = names if every else names[-1:]
    dest.mkdir(parents=True, exist_ok=True)
    proc = subprocess.Popen(["docker", "run", "--rm", "-v", f"{volume(project)}:/recordings:ro",
                             "--entrypoint", "tar", image(), "-C", "/recordings", "-cf", "-",
                             *chosen], stdout=subprocess.PIPE)
    assert proc.stdout is not None
    with tarfile.open(fileobj=proc.stdout, mode="r|") as archive:
        archive.extractall(dest, filter="data")
    if proc.wait() != 0:
        raise UserError(f"copying out of {volume(project)} failed")
    return [dest / name for name in chosen]


def run_collect(args: argparse.Namespace) -> int:
    for path in collect(args.project, args.dest, args.all):
        print(path)
    return 0


def run_analyze(args: argparse.Namespace) -> int:
    (latest,) = collect(args.project, args.dest, every=False)
    print(f"the latest recording, copied to {latest}", file=sys.stderr)
    from fleet.cli import main

    return main(["analyze", str(latest), *(["--json"] if args.json else [])])
