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
