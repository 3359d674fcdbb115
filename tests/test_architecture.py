"""The import graph keeps the house's shape (docs/architecture.md), read from every module's
imports with ast, lazy imports inside functions included:

- the core (fleet/ but the command line) imports no process package;
- no process package imports the command line: each starts itself with its own main(argv);
- each wing of fleet/ imports only wings below it, so there are no circles;
- zenoh, matplotlib, foxglove, torch and mcap are each imported only in the wing meant for them.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PROCESSES = ("dispatcher", "vehicle_agent", "reservation", "recorder", "vda5050")
COMMAND_LINE = ("fleet.cli", "fleet.__main__", "fleet.commands")

# Floors of fleet/, lowest first: a module may import its own wing and any wing on a lower floor.
FLOORS: tuple[tuple[str, ...], ...] = (
    ("fleet", "fleet.errors", "fleet.params"),
    ("fleet.planning",),
    ("fleet.vehicles",),
    ("fleet.world", "fleet.wire"),
    ("fleet.dispatching", "fleet.vda5050"),
    ("fleet.mission",),
    ("fleet.views",),
    ("fleet.recording",),
    ("fleet.runtime", "fleet.analysis"),
    ("fleet.commands", "fleet.cli", "fleet.__main__"),
)

# Third-party packages with one home each (a prefix of the importing module's name).
HOMES = {
    "zenoh": ("fleet.runtime", "fleet.cli", *PROCESSES, "bench"),
    "matplotlib": ("fleet.views",),
    "foxglove": ("fleet.views", "recorder"),
    "torch": ("fleet.dispatching",),
    "mcap": ("fleet.recording",),
}


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def sources() -> dict[str, Path]:
    found = {}
    for package in ("fleet", *PROCESSES, "bench"):
        for path in sorted((ROOT / package).rglob("*.py")):
            found[module_name(path)] = path
    return found


MODULES = sources()


def imports_of(name: str, path: Path) -> set[str]:
    """Every module `name` imports, as dotted names: `from a import b` counts as a.b when a.b is
    a module of the project, else as a."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                found.add(sub if sub in MODULES else base)
    return found


GRAPH = {name: imports_of(name, path) for name, path in MODULES.items()}


def within(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def floor_of(name: str) -> int | None:
    """The floor of a module of fleet/: the floor of the longest wing holding it."""
    best = None
    for level, wings in enumerate(FLOORS):
        for wing in wings:
            if within(name, (wing,)) and (best is None or len(wing) > len(best[1])):
                best = (level, wing)
    return None if best is None else best[0]


def project(targets: set[str]) -> set[str]:
    return {t for t in targets if within(t, ("fleet", *PROCESSES, "bench"))}


def test_the_graph_is_read():
    """The reader sees real edges (a broken reader would make every rule pass)."""
    assert "fleet.mission.engine" in MODULES
    assert "fleet.planning.reservations" in GRAPH["fleet.planning.planner"]
    assert "fleet.vehicles.registry" in GRAPH["fleet.world.layout"]
    assert any(t.startswith("fleet.runtime") for t in GRAPH["dispatcher.process"])


def test_the_core_imports_no_process_package():
    wrong = sorted(f"{name} imports {target}"
                   for name, targets in GRAPH.items()
                   if name.startswith("fleet") and not within(name, COMMAND_LINE)
                   for target in targets if within(target, PROCESSES))
    assert wrong == []


def test_processes_start_themselves():
    wrong = sorted(f"{name} imports {target}"
                   for name, targets in GRAPH.items() if within(name, PROCESSES)
                   for target in targets if within(target, COMMAND_LINE))
    assert wrong == []
    for package in PROCESSES:
        main = (ROOT / package / "__main__.py").read_text()
        assert "fleet.cli" not in main and "main(" in main, package


def test_each_wing_imports_only_wings_below_it():
    wrong = []
    for name, targets in GRAPH.items():
        own = floor_of(name)
        if own is None:
            continue
        for target in project(targets):
            floor = floor_of(target)
            if floor is not None and floor > own:
                wrong.append(f"{name} (floor {own}) imports {target} (floor {floor})")
    assert sorted(wrong) == []


def test_every_module_of_fleet_has_a_floor():
    assert sorted(n for n in MODULES if n.startswith("fleet") and floor_of(n) is None) == []


def test_no_import_circles():
    """Tarjan's strongly connected components over the project's modules."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    circles = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in project(GRAPH.get(node, set())):
            if target not in MODULES:
                continue
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                top = stack.pop()
                on_stack.discard(top)
                component.append(top)
                if top == node:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for name in MODULES:
        if name not in index:
            visit(name)
    assert circles == []


@pytest.mark.parametrize("package", sorted(HOMES))
def test_third_party_packages_stay_in_their_wing(package):
    wrong = sorted(name for name, targets in GRAPH.items()
                   if any(within(t, (package,)) for t in targets)
                   and not within(name, HOMES[package]))
    assert wrong == []
