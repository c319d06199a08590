"""The distribution installs under the one name ``walkstream``."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
import zipfile
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


def test_a_skip_fails_under_ci(tmp_path: Path) -> None:
    """CI=true turns a skipped test (no GL context, missing data) into a failure."""
    (tmp_path / "test_skips.py").write_text(
        "import pytest\n\n\ndef test_needs_gl():\n    pytest.skip('no GL context')\n"
    )
    argv = [sys.executable, "-m", "pytest", "-q", "-p", "ci_skips", "-p", "no:cacheprovider", str(tmp_path)]
    # no plugin but the ones named: each of the three runs starts in a second, not in ten
    env = {**os.environ, "PYTHONPATH": str(ROOT / "tests"), "PYTEST_DISABLE_PLUGIN_AUTOLOAD": "1"}
    local = subprocess.run(argv, env={**env, "CI": ""}, capture_output=True, text=True, check=False)
    assert local.returncode == 0 and "1 skipped" in local.stdout
    ci = subprocess.run(argv, env={**env, "CI": "true"}, capture_output=True, text=True, check=False)
    assert ci.returncode == 1 and "skipped under CI" in ci.stdout and "no GL context" in ci.stdout
    # and so it does in a pytest-xdist worker, as `make test` runs the suite
    xdist = [*argv[:4], "-p", "xdist", "-n", "1", *argv[4:]]
    ci = subprocess.run(xdist, env={**env, "CI": "true"}, capture_output=True, text=True, check=False)
    assert ci.returncode == 1 and "skipped under CI" in ci.stdout and "no GL context" in ci.stdout
    assert ci.stdout.rstrip().splitlines()[-1].startswith("1 failed")


def test_the_wheel_holds_one_top_level_name_and_the_grammar(tmp_path: Path) -> None:
    """A real (non-editable) build: package-dir renames, package data, nothing else on top."""
    out = tmp_path / "wheel"
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-q", "-w", str(out)],
        check=True,
        capture_output=True,
        cwd=tmp_path,
    )
    (wheel,) = out.glob("walkstream-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert {n.split("/")[0] for n in names} == {"walkstream", f"{wheel.name.split('-py')[0]}.dist-info"}
    assert "walkstream/shared/grammars/building.lsys" in names
    config = _setuptools()
    for name, folder in config["package-dir"].items():
        for f in (ROOT / folder).rglob("*.py") if name != "walkstream" else (ROOT / folder).glob("*.py"):
            rel = f.relative_to(ROOT / folder).as_posix()
            assert f"{name.replace('.', '/')}/{rel}" in names, rel


def test_the_dockerfile_copies_every_package_folder() -> None:
    text = (ROOT / "Dockerfile").read_text(encoding="utf-8")
    for folder in _setuptools()["package-dir"].values():
        assert f"COPY {folder} ./{folder}" in text
