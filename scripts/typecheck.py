"""Run mypy on the installed layout (``walkstream.server`` ...) of the checkout's folders.

The folders ``server/``, ``client/``, ``shared/`` and ``benchmarks/`` install as
``walkstream.server`` and so on (``[tool.setuptools.package-dir]`` in pyproject.toml).
At run time setuptools' editable finder does that mapping; mypy cannot follow import
hooks, so this script lays the same mapping out as a tree of symbolic links under
``build/typecheck/`` and checks that tree, printing paths as they are in the checkout.

Why not setuptools' strict editable mode (``pip install -e . --config-settings
editable_mode=strict``), which builds the same tree of links under
``build/__editable__.walkstream-*``: measured, it serves mypy as well (185 files, the
same errors, about the same time), but the installed package then sees only the files
that existed at install time, so a new module is an ImportError until the next
``pip install -e`` (which ``make`` does not redo), and tracebacks and mypy's messages
point into ``build/`` instead of the checkout.  The lenient editable install keeps new
modules importable at once; this script rebuilds its tree on every run.  Ruff needs
neither: it reads files, and ``known-first-party`` names ``walkstream``.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TREE = ROOT / "build" / "typecheck"


def package_dirs() -> dict[str, str]:
    """The ``package-dir`` table of pyproject.toml: import name -> folder."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    return dict(config["tool"]["setuptools"]["package-dir"])


def build_tree(mapping: dict[str, str]) -> dict[Path, Path]:
    """Link every mapped folder into ``TREE`` at its import path; tree path -> real path."""
    if TREE.exists():
        shutil.rmtree(TREE)
    shown: dict[Path, Path] = {}
    # parents first, so that a child folder's link lands inside its parent's real folder copy
    for name in sorted(mapping, key=lambda n: n.count(".")):
        src = ROOT / mapping[name]
        dst = TREE.joinpath(*name.split("."))
        dst.mkdir(parents=True, exist_ok=True)
        for entry in src.iterdir():
            if entry.name == "__pycache__" or (dst / entry.name).exists():
                continue
            (dst / entry.name).symlink_to(entry)
        shown[dst] = src
    return shown


def main() -> int:
    shown = build_tree(package_dirs())
    proc = subprocess.run(
        [sys.executable, "-m", "mypy", str(TREE / "walkstream"), *sys.argv[1:]],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=False,
    )
    # longest tree paths first, so walkstream/server/... is not read as walkstream/...
    pairs = sorted(
        ((os.path.relpath(t, ROOT) + os.sep, os.path.relpath(r, ROOT) + os.sep) for t, r in shown.items()),
        key=lambda p: -len(p[0]),
    )
    pattern = re.compile("|".join(re.escape(t) for t, _ in pairs))
    table = dict(pairs)
    out = pattern.sub(lambda m: table[m.group(0)], proc.stdout + proc.stderr)
    sys.stdout.write(out)
    return proc.returncode


if __name__ == "__main__":
    raise SystemExit(main())
