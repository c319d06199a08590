"""The documentation stays true to the checkout.

README.md is the front door and docs/ holds one page per stage; these tests keep them
honest as the code moves: every repository path they name exists, every relative link
(and its anchor) resolves, no page or docstring carries a round number (a changelog
word, meaningless to a reader of the code), and the README stays short.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
PAGES = [README, *sorted(DOCS.glob("*.md"))]
#: Pages whose links are checked; the changelog names files that no longer exist on purpose.
LINKED = [*PAGES, ROOT / "CHANGELOG.md"]
PACKAGES = ("shared", "server", "client", "benchmarks", "walkstream")

#: Where a path named in the docs may start: the repository's folders and top-level files.
TOP_FOLDERS = (*(f"{p}/" for p in PACKAGES), "tests/", "scripts/", "docs/", ".ci/")
TOP_FILES = {"Makefile", "Dockerfile", "docker-compose.yml", "pyproject.toml", "README.md", "CHANGELOG.md"}

README_MAX_BYTES = 12_000

_CODE = re.compile(r"`([^`\n]+)`")
_LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
_ROUND = re.compile(r"\bround[- ](one|two|three|four|five|six|seven|eight|nine|ten)\b|\bthis round\b", re.I)
_FILE_NAME = re.compile(r"^[\w.-]+(/[\w.-]+)*(\.(py|lsys|sh|md|toml|yml)|/)$")


def _code_spans(text: str) -> list[str]:
    """Every inline code span of a Markdown text, fenced blocks left out."""
    prose = re.sub(r"```.*?```", "", text, flags=re.S)
    return [m.group(1).strip() for m in _CODE.finditer(prose)]


def _repo_path(token: str) -> str | None:
    """The repository path a code span names, or None when it names none."""
    token = token.split("::", 1)[0].rstrip(".,;:")
    if any(c in token for c in " *{}<>|$()"):
        return None
    if token.startswith(TOP_FOLDERS) or token in TOP_FILES:
        return token
    return None


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens."""
    text = heading.strip().lower().replace("`", "")
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    return {_slug(m.group(1)) for m in re.finditer(r"^#+\s+(.*)$", text, flags=re.M)}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_path_a_page_names_exists(page: Path) -> None:
    missing = sorted(
        {p for p in map(_repo_path, _code_spans(page.read_text(encoding="utf-8"))) if p and not (ROOT / p).exists()}
    )
    assert not missing, f"{page.name} names paths that do not exist: {missing}"


def test_the_layout_table_names_only_files_that_exist() -> None:
    """In docs/architecture.md's layout table, the bare names of a row are files of its folder."""
    text = (DOCS / "architecture.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| `([\w/.]+/)` \|(.*)$", text, flags=re.M)
    assert len(rows) >= 15, "the layout table is gone"
    missing = []
    for name, rest in rows:
        folder = ROOT / name
        assert folder.is_dir(), folder
        for token in _code_spans(rest):
            if _repo_path(token) or not _FILE_NAME.match(token):
                continue
            if not (folder / token).exists():
                missing.append(f"{folder.relative_to(ROOT)}/{token}")
    assert not missing, f"docs/architecture.md names files that do not exist: {missing}"


def test_every_package_folder_is_in_the_layout_table() -> None:
    text = (DOCS / "architecture.md").read_text(encoding="utf-8")
    listed = set(re.findall(r"^\| `([\w/.]+)/` \|", text, flags=re.M))
    folders = {  # the folders that hold modules (server/ holds only its sub-packages)
        str(p.parent.relative_to(ROOT))
        for pkg in PACKAGES
        for p in (ROOT / pkg).rglob("*.py")
        if p.name != "__init__.py"
    }
    # a sub-package may be described in its parent's row, as server/service/routers is
    unlisted = sorted(f for f in folders if f not in listed and not any(f.startswith(f"{d}/") for d in listed))
    assert not unlisted, f"folders missing from the layout table of docs/architecture.md: {unlisted}"


@pytest.mark.parametrize("page", LINKED, ids=lambda p: p.name)
def test_every_relative_link_resolves(page: Path) -> None:
    bad = []
    for target in _LINK.findall(page.read_text(encoding="utf-8")):
        if re.match(r"^[a-z]+:", target):
            continue  # http:, https:, mailto:
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            bad.append(target)
        elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
            bad.append(f"{target} (no such heading)")
    assert not bad, f"{page.name} links to what is not there: {bad}"


def test_every_docs_page_is_linked_from_the_readme() -> None:
    links = set(_LINK.findall(README.read_text(encoding="utf-8")))
    unlinked = [p.name for p in DOCS.glob("*.md") if f"docs/{p.name}" not in links]
    assert not unlinked, f"README.md does not link {unlinked}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_no_page_carries_a_round_number(page: Path) -> None:
    hits = [m.group(0) for m in _ROUND.finditer(page.read_text(encoding="utf-8"))]
    assert not hits, f"{page.name}: {hits} (history goes into CHANGELOG.md)"


def test_no_docstring_carries_a_round_number() -> None:
    hits = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
                    doc = ast.get_docstring(node, clean=False) or ""
                    hits += [f"{path.relative_to(ROOT)}: {m.group(0)}" for m in _ROUND.finditer(doc)]
    assert not hits, hits


def test_readme_stays_short() -> None:
    size = len(README.read_bytes())
    assert size < README_MAX_BYTES, f"README.md is {size} bytes; move detail into docs/"


def test_readme_keeps_the_two_commands() -> None:
    text = README.read_text(encoding="utf-8")
    assert "make demo" in text and "make test" in text
