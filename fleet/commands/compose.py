"""`fleet compose`: the compose deployment's chores, so nobody types docker's long forms
(docs/deployment.md). `up` runs a mission and analyses it, `collect` copies recordings out
of the volume, `analyze` looks at the latest one, `secrets` makes the logins that
compose.secure.yaml hands the containers."""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

from fleet.commands.analyze import print_analysis
from fleet.errors import UserError
from fleet.recording.rundir import run_id_of
from fleet.runtime.argtypes import positive_int, writable_dir
from fleet.runtime.deploy import MAX_VEHICLES
from fleet.wire.topics import GATEWAY

DEFAULT_PROJECT = "forklift-fleet"  # also in .env, which both compose tools read
SECRETS = Path("deploy/secrets")  # compose.secure.yaml reads them here ($FLEET_SECRETS)
CONTAINER_UID = 1000  # the image's user (the Dockerfile's UID argument)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compose", help="run and inspect the docker compose deployment",
                       description=__doc__)
    p.add_argument("--project", default=os.environ.get("COMPOSE_PROJECT_NAME", DEFAULT_PROJECT),
                   help=f"compose project name (default $COMPOSE_PROJECT_NAME or "
                   f"{DEFAULT_PROJECT})")
    p.add_argument("--file", type=Path, default=Path("compose.yaml"), metavar="FILE",
                   help="the compose file (default compose.yaml here)")
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    up = actions.add_parser("up", help="run a mission with N forklifts, then analyse it",
                            description="Run `docker compose up` with N forklift containers "
                            "in the foreground until the mission ends, then analyse its "
                            "recording.")
    up.add_argument("--vehicles", type=positive_int, default=4,
                    help="forklift (or AGV) containers, and the fleet the mission waits for "
                    "(default 4)")
    up.add_argument("--layout", type=shipped_layout,
                    help="FLEET_LAYOUT: a layout shipped in the image (paper002 runs order "
                    "missions; default: $FLEET_LAYOUT, else paper)")
    up.add_argument("--orders", type=positive_int, metavar="N",
                    help="FLEET_ORDERS: an order mission of N orders (default: $FLEET_ORDERS, "
                    "else 100)")
    up.add_argument("--dispatch", choices=("internal", "external"), default="internal",
                    help="external: no mission of ours, the forklifts take a VDA 5050 "
                    "master's orders on the broker at mqtt://127.0.0.1:1883 (profile vda5050, "
                    "FLEET_DISPATCH=external) until Ctrl-C (default internal)")
    up.add_argument("--build", action="store_true", help="build the image first")
    up.add_argument("--secure", action="store_true", help="behind the router's access "
                    "control (compose.secure.yaml), with the logins of `fleet compose secrets` "
                    "(made if there are none)")
    up.set_defaults(handler=run_up)
    collect = actions.add_parser("collect", help="copy recordings out of the volume (a "
                                 "run collected before is brought up to date; another "
                                 "run's directory is never written over)",
                                 description="Copy the latest recording (or all of them) out "
                                 "of the deployment's recordings volume. A run collected before "
                                 "is brought up to date; another run's directory is never "
                                 "written over.")
    collect.add_argument("dest", type=writable_dir, nargs="?", default=Path("runs/compose"),
                         help="where the copies go (default runs/compose)")
    collect.add_argument("--all", action="store_true", help="every recording, not the latest")
    collect.set_defaults(handler=run_collect)
    analyze = actions.add_parser("analyze", help="analyse the latest recording in the volume",
                                 description="Copy the latest recording out of the volume "
                                 "and run fleet analyze on it.")
    analyze.add_argument("--json", action="store_true", help="print one JSON object")
    analyze.add_argument("--dest", type=writable_dir, default=Path("runs/compose"),
                         metavar="DIR",
                         help="where its copy goes (default runs/compose)")
    analyze.set_defaults(handler=run_analyze)
    secrets = actions.add_parser("secrets", help="make the logins compose.secure.yaml uses",
                                 description="Make random logins for the router, the "
                                 "services and the forklifts, in files only their owner reads "
                                 "(compose.secure.yaml hands them to the containers).")
    secrets.add_argument("--out", type=writable_dir, default=None, metavar="DIR",
                         help=f"where (default $FLEET_SECRETS or {SECRETS})")
    secrets.add_argument("--force", action="store_true", help="replace existing logins")
    secrets.set_defaults(handler=run_secrets)


def shipped_layout(text: str) -> str:
    """A layout the image ships (a file here is not in the dispatcher's container)."""
    from fleet.world.layout_file import builtin_names

    if text not in builtin_names():
        raise argparse.ArgumentTypeError(
            f"{text!r} is no layout shipped in the image (one of {', '.join(builtin_names())}; "
            f"for your own, mount its TOML into the dispatcher's container and set "
            f"FLEET_LAYOUT to its path there)")
    return text


def compose_command() -> list[str]:
    """`docker compose` (the plugin) where it exists, else Debian's `docker-compose`."""
    if shutil.which("docker") and subprocess.run(
            ["docker", "compose", "version"], capture_output=True).returncode == 0:
        return ["docker", "compose"]
    if shutil.which("docker-compose"):
        return ["docker-compose"]
    raise UserError("neither `docker compose` nor `docker-compose` is installed")


def run_up(args: argparse.Namespace) -> int:
    files = ["-f", str(args.file)]
    if args.secure:
        folder = secrets_folder(None)
        if not (folder / "users").exists():
            write_secrets(folder, force=False)
        elif args.dispatch == "external" and not (folder / f"{GATEWAY}_password").exists():
            # made before the gateway had a login
            raise UserError(f"{folder} holds no login for the VDA 5050 gateway: `fleet compose "
                            "secrets --force` writes this deployment's logins anew")
        files += ["-f", str(args.file.with_name("compose.secure.yaml"))]
    if args.dispatch == "external":
        if args.orders:
            raise UserError("--dispatch external takes no --orders (docs/vda5050.md)")
        files += ["--profile", "vda5050"]
    up = [*compose_command(), "-p", args.project, *files, "up", "--scale",
          f"vehicle={args.vehicles}", *(["--build"] if args.build else [])]
    settings = {"FLEET_VEHICLES": str(args.vehicles)}  # start once all of them claimed
    if args.layout:
        settings["FLEET_LAYOUT"] = args.layout
    if args.orders:
        settings["FLEET_ORDERS"] = str(args.orders)
    if args.dispatch == "external":
        settings["FLEET_DISPATCH"] = "external"
    print("$ " + " ".join([*(f"{k}={v}" for k, v in settings.items()), *up]), file=sys.stderr)
    # In the foreground: every container's log shows how far it is; the mission's processes
    # exit when it ends, the router last, and `up` returns then.
    if subprocess.run(up, env={**os.environ, **settings}).returncode not in (0, 130):
        raise UserError("docker compose up failed (its output is above)")
    return analyze_latest(args.project, Path("runs/compose"))


def volume(project: str) -> str:
    return f"{project}_recordings"


def image() -> str:
    return os.environ.get("FLEET_IMAGE", "forklift-fleet:latest")


def in_volume(project: str, *command: str) -> list[str]:
    """A docker command line: `command` in a throwaway container of the image with the
    recordings mounted (read only)."""
    if subprocess.run(["docker", "volume", "inspect", volume(project)],
                      capture_output=True).returncode != 0:
        raise UserError(f"no volume {volume(project)}: has project {project!r} run yet?")
    return ["docker", "run", "--rm", "-v", f"{volume(project)}:/recordings:ro",
            "--entrypoint", command[0], image(), *command[1:]]


def recordings(project: str) -> list[str]:
    """The run directories in the volume, oldest first (they are named by date-time)."""
    listing = subprocess.run(in_volume(project, "ls", "-1", "/recordings"),
                             capture_output=True, text=True)
    if listing.returncode != 0:
        raise UserError(f"cannot list {volume(project)}: {listing.stderr.strip()}")
    return sorted(line for line in listing.stdout.split() if line)


def collect(project: str, dest: Path, every: bool) -> list[Path]:
    """Copy run directories out of the volume into dest/NAME: extracted beside it first,
    then each put in place (`place_copy`)."""
    names = recordings(project)
    if not names:
        raise UserError(f"{volume(project)} holds no recording yet")
    chosen = names if every else names[-1:]
    try:
        dest.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=".collect-", dir=dest))
    except OSError as exc:
        raise UserError(f"cannot write in {dest}: {exc.strerror}") from None
    try:
        proc = subprocess.Popen(in_volume(project, "tar", "-C", "/recordings", "-cf", "-",
                                          *chosen), stdout=subprocess.PIPE)
        assert proc.stdout is not None
        with tarfile.open(fileobj=proc.stdout, mode="r|") as archive:
            archive.extractall(staging, filter="data")
        if proc.wait() != 0:
            raise UserError(f"copying out of {volume(project)} failed")
        return [place_copy(staging / name, dest / name) for name in chosen]
    finally:
        shutil.rmtree(staging, ignore_errors=True)  # ours: what is left of the copies


def place_copy(copy: Path, target: Path) -> Path:
    """Put a run directory copied out of the volume at `target`. A copy collected before
    of the same run (the same run id) is brought up to date: the volume's files replace
    theirs (a recording only grows) and nothing else there is touched (plots stay). Another
    run's directory there is refused by name: collect elsewhere."""
    if not target.exists():
        os.rename(copy, target)
        return target
    ours, theirs = run_id_of(copy), run_id_of(target) if target.is_dir() else None
    if not target.is_dir() or ours != theirs:
        what = "a file" if not target.is_dir() else \
            f"run {theirs or 'without a run id'}, not the volume's {ours or 'without one'}"
        raise UserError(f"{target} exists and holds {what}: nothing was copied over it; "
                        f"collect into another directory (fleet compose collect DEST)")
    for path in sorted(copy.rglob("*")):
        if path.is_file():
            there = target / path.relative_to(copy)
            there.parent.mkdir(parents=True, exist_ok=True)
            os.replace(path, there)
    return target


def run_collect(args: argparse.Namespace) -> int:
    for path in collect(args.project, args.dest, args.all):
        print(path)
    return 0


def run_analyze(args: argparse.Namespace) -> int:
    return analyze_latest(args.project, args.dest, args.json)


def analyze_latest(project: str, dest: Path, as_json: bool = False) -> int:
    """Copy the latest recording out of the volume into dest and analyse it."""
    (latest,) = collect(project, dest, every=False)
    print(f"the latest recording, copied to {latest}", file=sys.stderr)
    return print_analysis(latest, as_json)


def secrets_folder(out: Path | None) -> Path:
    return out or Path(os.environ.get("FLEET_SECRETS", SECRETS))


def run_secrets(args: argparse.Namespace) -> int:
    folder = secrets_folder(args.out)
    write_secrets(folder, args.force)
    print(f"logins for the router, the services and {MAX_VEHICLES} forklifts in {folder}")
    return 0


def write_secrets(folder: Path, force: bool) -> None:
    """Random logins for one deployment, readable by the containers' user only (compose
    mounts a secret file with its owner and mode)."""
    from fleet.runtime.access import generate_credentials, write_private
    from fleet.runtime.deploy import secret_files

    if (folder / "users").exists() and not force:
        raise UserError(f"{folder} holds logins already (--force replaces them)")
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    for name, text in secret_files(generate_credentials("compose", MAX_VEHICLES)).items():
        path = write_private(folder / name, text)
        if os.getuid() == 0:
            os.chown(path, CONTAINER_UID, CONTAINER_UID)
    if os.getuid() not in (0, CONTAINER_UID):
        print(f"note: the containers run as uid {CONTAINER_UID} and read these files only if "
              f"it owns them: build the image with --build-arg UID={os.getuid()}",
              file=sys.stderr)
