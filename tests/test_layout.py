"""The house rules: one-way arrows between packages, a public face per package, one home per idea."""

from __future__ import annotations

import ast
import doctest
import importlib
import tomllib
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MAX_LINES = 800


def _modules() -> dict[str, Path]:
    """Every installed module: dotted name -> file, from pyproject.toml's package-dir."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    mods: dict[str, Path] = {}
    for name, folder in config["tool"]["setuptools"]["package-dir"].items():
        base = ROOT / folder
        for f in sorted(base.glob("*.py")) if name == "walkstream" else sorted(base.rglob("*.py")):
            rel = f.relative_to(base).with_suffix("").parts
            if rel[-1] == "__init__":
                rel = rel[:-1]
            mods[".".join((name, *rel))] = f
    return mods


MODULES = _modules()
CLI = {m for m in MODULES if m.startswith("walkstream.") and m.count(".") == 1} | {"walkstream"}
CLI -= {"walkstream.shared", "walkstream.server", "walkstream.client", "walkstream.benchmarks"}


def _imports(path: Path) -> set[str]:
    """Every walkstream module a file imports (at any depth of the file)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
            out.update(f"{node.module}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return {m for m in out if m.startswith("walkstream")}


def _in(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


# (importer, forbidden): the arrows run walkstream (CLI) > benchmarks > server, client > shared
FORBIDDEN = [
    ("walkstream.shared", "walkstream.server"),
    ("walkstream.shared", "walkstream.client"),
    ("walkstream.shared", "walkstream.benchmarks"),
    ("walkstream.client", "walkstream.server"),
    ("walkstream.client", "walkstream.benchmarks"),
    ("walkstream.server", "walkstream.client"),
    ("walkstream.server", "walkstream.benchmarks"),
    ("walkstream.server.service", "walkstream.server.bake"),
    ("walkstream.server.sources", "walkstream.server.bake"),
    ("walkstream.server.sources", "walkstream.server.store"),
    ("walkstream.server.sources", "walkstream.server.service"),
    ("walkstream.server.store", "walkstream.server.bake"),
    ("walkstream.server.store", "walkstream.server.service"),
    ("walkstream.server.bake", "walkstream.server.service"),
]


@pytest.mark.parametrize(("importer", "forbidden"), FORBIDDEN)
def test_arrows_run_one_way(importer: str, forbidden: str) -> None:
    bad = [
        f"{m} imports {i}"
        for m, f in MODULES.items()
        if _in(m, importer)
        for i in _imports(f)
        if _in(i, forbidden)
    ]
    assert not bad


def test_nothing_but_the_cli_imports_the_cli() -> None:
    bad = [
        f"{m} imports {i}"
        for m, f in MODULES.items()
        if m not in CLI
        for i in _imports(f)
        if any(_in(i, c) for c in CLI if c != "walkstream")
        or i == "walkstream.cli"
    ]
    assert not bad


def test_every_package_has_a_public_face() -> None:
    """Every ``__init__.py`` says what its package offers, and every name it lists exists."""
    missing = []
    for name, path in MODULES.items():
        if path.name != "__init__.py":
            continue
        pkg = importlib.import_module(name)
        if not getattr(pkg, "__all__", None):
            missing.append(f"{name}: no __all__")
            continue
        missing += [f"{name}.{n}" for n in pkg.__all__ if not hasattr(pkg, n)]
    assert not missing


def _top_level_names(tree: ast.Module) -> set[str]:
    names = set()
    for node in tree.body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return names


def test_a_module_lists_only_what_it_defines() -> None:
    """Outside ``__init__.py``, ``__all__`` names the module's own definitions (one home)."""
    bad = []
    for name, path in MODULES.items():
        if path.name == "__init__.py":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        own = _top_level_names(tree)
        for node in tree.body:
            if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
            ):
                listed = ast.literal_eval(node.value)
                bad += [f"{name}.{n}" for n in listed if n not in own]
    assert not bad


def _bindings(package: str) -> dict[str, str]:
    """What a package ``__init__`` re-exports: name -> the module it comes from.

    Both eager re-exports (``from walkstream.x.y import name``) and lazy ones (the
    ``_EXPORTS`` table that :func:`~walkstream.shared.exports.lazy_exports` serves).
    """
    path = MODULES.get(package)
    if path is None or path.name != "__init__.py":
        return {}
    out: dict[str, str] = {}
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.update({a.asname or a.name: node.module for a in node.names})
        elif isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "_EXPORTS" for t in node.targets
        ):
            out.update(ast.literal_eval(node.value))
    return out


def _resolve(importer: str, package: str, name: str) -> str:
    """The module that ``from package import name`` in ``importer`` depends on.

    A submodule is that submodule.  A name a package re-exports is its home module,
    unless the importer lives in that package: the package's ``__init__`` imports its
    own modules, so one of them importing the ``__init__`` back is a real cycle.
    """
    if f"{package}.{name}" in MODULES:
        return f"{package}.{name}"
    home = _bindings(package).get(name)
    if home is None or _in(importer, package):
        return package
    return _resolve(importer, home, name)  # (a package may re-export another's re-export)


def _depends(module: str) -> set[str]:
    """The walkstream modules ``module`` imports, at any depth of its file.

    Imports inside functions and under ``TYPE_CHECKING`` count: a cycle that only a
    lazy import lets load is still two modules that need each other.  Importing
    ``walkstream.a.b`` also runs ``walkstream.a``'s ``__init__`` first, but that is
    not counted: Python always runs a package before its modules, so it never closes a
    cycle, and counting it would make every ``__init__`` that re-exports its modules
    one.  See :func:`_resolve` for ``from package import name``.
    """
    out = set()
    for node in ast.walk(ast.parse(MODULES[module].read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module.startswith("walkstream"):
                out.update(_resolve(module, node.module, a.name) for a in node.names)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return {m for m in out if m in MODULES and m != module}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            part = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                part.append(w)
                if w == v:
                    break
            if len(part) > 1:
                found.append(sorted(part))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_import_cycles() -> None:
    """No two walkstream modules import each other, directly or through others."""
    graph = {m: _depends(m) for m in MODULES}
    cycles = [
        " <-> ".join(f"{m} (imports {sorted(graph[m] & set(c))})" for m in c)
        for c in _cycles(graph)
    ]
    assert not cycles


def test_the_cycle_check_sees_a_cycle() -> None:
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []
    # a re-exported name is its home module (eager and lazy re-exports) ...
    store, client = "walkstream.server.store", "walkstream.client"
    assert _resolve("walkstream.server.bake.pipeline", store, "SceneWriter") == f"{store}.writer"
    assert _resolve("walkstream.cli", client, "Streamer") == f"{client}.stream.streamer"
    assert _resolve("walkstream.cli", client, "stream") == f"{client}.stream"
    # ... except from inside the package, whose __init__ imports the importer
    assert _resolve(f"{store}.edit", store, "SceneWriter") == store


def _private_uses(module: str) -> list[str]:
    """The ``_private`` names of other walkstream modules that ``module`` uses.

    Both ``from walkstream.x import _name`` and ``alias._name`` where ``alias`` is a
    walkstream module (``import walkstream.x as alias``, ``from walkstream import x``).
    """
    tree = ast.parse(MODULES[module].read_text(encoding="utf-8"))
    out: list[str] = []
    aliases: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if not node.module.startswith("walkstream"):
                continue
            for a in node.names:
                if f"{node.module}.{a.name}" in MODULES:
                    aliases[a.asname or a.name] = f"{node.module}.{a.name}"
                elif a.name.startswith("_") and not a.name.startswith("__"):
                    out.append(f"{node.module}.{a.name}")
        elif isinstance(node, ast.Import):
            aliases.update({a.asname: a.name for a in node.names if a.asname and a.name in MODULES})
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id in aliases
            and node.attr.startswith("_")
            and not node.attr.startswith("__")
        ):
            out.append(f"{aliases[node.value.id]}.{node.attr}")
    return out


def test_no_module_uses_another_modules_private_names() -> None:
    """A name another module needs is public in its home: listed in its ``__all__``,
    documented, and imported without an underscore."""
    bad = [f"{m} uses {name}" for m in MODULES for name in _private_uses(m)]
    assert not bad


# ideas that once had several homes (issue 10): each is defined exactly once now
ONE_HOME = [
    "signed_area",
    "recovery_frames",
    "displayed_fps",
    "within_target_mask",
    "Viewpoint",
    "ApiError",
    "StreamCut",
    "CELL_KINDS",
    "LOCATABLE_KINDS",
    "CellKind",
    "ContentKind",
    "CONTENT_KINDS",
    "CONTENTS_MEDIA",
    "CellLocator",
    "inside_convex",
    "outside_lonlat",
    "parse_crs_member",
    "format_headline",
    "find_party_walls",
    "F64",
    "MSGPACK",
    "Manifest",
    "CellRecord",
    "CellIndex",
    "TileGrid",
    "RoomRecord",
    "Topology",
    "read_source",
    "Releasable",
    "within",
    "manifest_task",
    # the bake (issue 23): one chunk runner (its pool's worker set-up and task), one
    # driver's plan, one navigation graph over one Dijkstra, one notion of a walk's place
    "run_chunks",
    "dask_client",
    "init_worker",
    "pool_task",
    "BakePlan",
    "SceneGraph",
    "shortest_paths",
    "Place",
    # the walk (issue 23): one frame loop's state and scene, one request scheduler, one
    # cache, one ground truth (its renderer and its recorder), one topology of a crossing
    "WalkState",
    "WalkScene",
    "RequestScheduler",
    "Cache",
    "TruthRenderer",
    "TruthRecorder",
    "crossing_topology",
    "fog_for_budget",
]


def test_each_idea_has_one_home() -> None:
    homes: dict[str, list[str]] = defaultdict(list)
    for name, path in MODULES.items():
        for defined in _top_level_names(ast.parse(path.read_text(encoding="utf-8"))):
            bare = defined.lstrip("_")
            if bare in ONE_HOME:
                homes[bare].append(name)
    # the service documents the manifest's shape for OpenAPI with a pydantic model of
    # the same name; tests/test_server.py checks it against the wire record
    homes["Manifest"] = [m for m in homes["Manifest"] if m != "walkstream.server.service.models"]
    several = {k: v for k, v in homes.items() if len(v) != 1}
    assert not several
    assert set(homes) == set(ONE_HOME)


def test_long_modules_say_why() -> None:
    """A module over 800 lines states at its top why it is not split."""
    long = []
    for name, path in MODULES.items():
        text = path.read_text(encoding="utf-8")
        if len(text.splitlines()) > MAX_LINES:
            doc = ast.get_docstring(ast.parse(text)) or ""
            if "over 800 lines" not in doc.lower():
                long.append(f"{name} ({len(text.splitlines())} lines)")
    assert not long


@pytest.mark.parametrize(
    "module",
    [
        "walkstream.shared.geometry",
        "walkstream.shared.cells",
        "walkstream.shared.scene.cellkinds",
        "walkstream.shared.content.registry",
        "walkstream.shared.exports",
        "walkstream.server.sources.crs",
        "walkstream.shared.codec.ints",
        "walkstream.server.service.http",
        "walkstream.client.stream.cellmap",
        "walkstream.client.stream.route",
        "walkstream.client.stream.plan",
        "walkstream.client.report.metrics",
        "walkstream.benchmarks.stream",
    ],
)
def test_doctests(module: str) -> None:
    result = doctest.testmod(importlib.import_module(module), raise_on_error=False)
    assert result.attempted > 0 and result.failed == 0
