"""The distribution installs under the one name ``walkstream``."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _setuptools() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]


def test_every_package_folder_is_installed() -> None:
    """A folder with an ``__init__.py`` that pyproject.toml does not list would not ship."""
    config = _setuptools()
    roots = {name: ROOT / folder for name, folder in config["package-dir"].items()}
    found = set()
    for name, folder in roots.items():
        for init in folder.rglob("__init__.py"):
            rel = init.parent.relative_to(folder).parts
            found.add(".".join((name, *rel)))
    assert found == set(config["packages"])


def test_no_top_level_name_but_walkstream() -> None:
    config = _setuptools()
    assert {p.split(".")[0] for p in config["packages"]} == {"walkstream"}


def test_old_top_level_names_are_gone(tmp_path: Path) -> None:
    """Outside the checkout, ``import server`` (or client, shared) must fail."""
    code = (
        "import importlib.util, sys\n"
        "names = ['server', 'client', 'shared', 'benchmarks']\n"
        "sys.exit(1 if any(importlib.util.find_spec(n) for n in names) else 0)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, check=False)
    assert done.returncode == 0


def test_grammar_file_found_through_the_package(tmp_path: Path) -> None:
    code = "from walkstream.shared.buildings import default_grammar; print(default_grammar().name)"
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, check=True, capture_output=True, text=True
    )
    assert done.stdout.strip() == "building"
