"""Parse the text of a parametric L-system grammar.

The language (one statement per line; ``#`` starts a comment; a line that starts
with whitespace continues the statement above)::

    grammar NAME VERSION              # first statement: name and integer version
    limits depth 40 modules 200000    # bounds on the derivation (optional)
    seed Building()                   # modules the host seeds the derivation with,
    seed Edge(e, L, N)                #   and their parameter names (documentation + checks)
    global S F FH H LOD               # scalar names the host provides per derivation
    let NAME = EXPR                   # a per-derivation constant, evaluated in order
    Pred(a, b) : COND -> SUCCESSORS   # a production; ': COND' is optional
    Pred(a, b) -> *                   # '*' deletes the module

``SUCCESSORS`` is a list of modules ``Sym(expr, ...)``; a module may be prefixed by a
repeat count ``{EXPR}``, in which case it is produced ``floor(EXPR)`` times and its
argument expressions may use ``i`` (0, 1, ...).  Expressions see the predecessor's
parameters, the globals and the lets.  For one symbol the productions are tried in
the order written and the first whose condition holds applies; a module that no
production matches is kept unchanged (and never rewritten again, since nothing it
depends on changes).  Terminal symbols are the interpreter's generic operations,
whose arities are fixed (see :data:`TERMINALS`).
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, field
from pathlib import Path

from walkstream.shared.errors import GrammarError
from walkstream.shared.lsystem.expr import Expr, compile_expr

__all__ = [
    "Grammar",
    "Production",
    "Successor",
    "TERMINALS",
    "parse_grammar",
    "load_grammar",
]

#: The interpreter's generic geometric operations and their parameters.
TERMINALS: dict[str, tuple[str, ...]] = {
    # a rectangle on the vertical plane of footprint edge e, offset outward by `off`
    "Quad": ("e", "u0", "z0", "u1", "z1", "off", "mat"),
    # the same rectangle extruded outward by `depth` (front and four sides)
    "Box": ("e", "u0", "z0", "u1", "z1", "off", "depth", "mat"),
    # the footprint (holes included) as a horizontal polygon at height z, facing up (dir=1) or down
    "Cap": ("z", "dir", "mat"),
}

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_HEADER = re.compile(r"^grammar\s+([A-Za-z_][\w-]*)\s+(\d+)\s*$")
_LIMITS = re.compile(r"^limits(\s+(depth|modules)\s+(\d+))+\s*$")
_LET = re.compile(r"^let\s+([A-Za-z_]\w*)\s*=\s*(.+)$")
_PRED = re.compile(r"^([A-Za-z_]\w*)\s*(\(([^)]*)\))?\s*(:(.*?))?->(.*)$")
_RESERVED = {"i", "and", "or", "not", "if", "else"}


@dataclass(frozen=True, slots=True)
class Successor:
    """One module of a production's right-hand side."""

    symbol: str
    args: tuple[Expr, ...]
    repeat: Expr | None
    line: int


@dataclass(frozen=True, slots=True)
class Production:
    """``symbol(params) : condition -> successors``."""

    symbol: str
    params: tuple[str, ...]
    condition: Expr | None
    successors: tuple[Successor, ...]
    line: int


@dataclass(frozen=True, slots=True)
class Grammar:
    """A parsed grammar: what the derivation engine and interpreter need."""

    name: str
    version: int
    text: str
    globals: tuple[str, ...]
    seeds: dict[str, tuple[str, ...]]
    lets: tuple[tuple[str, Expr], ...]
    productions: dict[str, tuple[Production, ...]]
    arity: dict[str, int]
    max_depth: int = 64
    max_modules: int = 1_000_000
    digest: str = field(default="")

    @property
    def id(self) -> str:
        """``name@version+digest`` — what a client caches a grammar under."""
        return f"{self.name}@{self.version}+{self.digest[:12]}"


def _split_top(text: str, sep: str, line: int) -> list[str]:
    """Split on ``sep`` outside parentheses."""
    out: list[str] = []
    cur: list[str] = []
    depth = 0
    for ch in text:
        if ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
            if depth < 0:
                raise GrammarError(f"unbalanced ')' in {text.strip()!r}", line)
        if ch == sep and depth == 0:
            out.append("".join(cur))
            cur = []
        else:
            cur.append(ch)
    if depth:
        raise GrammarError(f"unbalanced '(' in {text.strip()!r}", line)
    out.append("".join(cur))
    return out


def _scan_successors(text: str, line: int) -> list[tuple[str, str | None, list[str]]]:
    """Tokenise ``{n} Sym(a, b) Sym2 ...`` into (symbol, repeat text, arg texts)."""
    out: list[tuple[str, str | None, list[str]]] = []
    pos, n = 0, len(text)
    while True:
        while pos < n and text[pos].isspace():
            pos += 1
        if pos >= n:
            return out
        repeat = None
        if text[pos] == "{":
            end = text.find("}", pos)
            if end < 0:
                raise GrammarError("'{' without a closing '}'", line)
            repeat = text[pos + 1 : end]
            pos = end + 1
            while pos < n and text[pos].isspace():
                pos += 1
        m = _IDENT.match(text, pos)
        if not m:
            raise GrammarError(f"expected a module name at {text[pos:pos + 20]!r}", line)
        sym = m.group(0)
        pos = m.end()
        args: list[str] = []
        if pos < n and text[pos] == "(":
            depth, start = 0, pos
            while pos < n:
                if text[pos] == "(":
                    depth += 1
                elif text[pos] == ")":
                    depth -= 1
                    if depth == 0:
                        break
                pos += 1
            if depth:
                raise GrammarError(f"unbalanced '(' after {sym}", line)
            inner = text[start + 1 : pos]
            pos += 1
            if inner.strip():
                args = _split_top(inner, ",", line)
        out.append((sym, repeat, args))


def _statements(text: str) -> list[tuple[int, str]]:
    """Join continuation lines, drop comments; return (first line number, statement)."""
    stmts: list[tuple[int, str]] = []
    for no, raw in enumerate(text.splitlines(), start=1):
        body = raw.split("#", 1)[0].rstrip()
        if not body.strip():
            continue
        if raw[:1].isspace() and stmts:
            first, prev = stmts[-1]
            stmts[-1] = (first, prev + " " + body.strip())
        else:
            stmts.append((no, body.strip()))
    return stmts


def parse_grammar(text: str) -> Grammar:
    """Parse grammar text.

    Raises
    ------
    GrammarError
        With the 1-based line number of the statement at fault.
    """
    stmts = _statements(text)
    if not stmts:
        raise GrammarError("the grammar text is empty", 1)
    first_line, first = stmts[0]
    m = _HEADER.match(first)
    if not m:
        raise GrammarError("expected 'grammar NAME VERSION' as the first statement", first_line)
    name, version = m.group(1), int(m.group(2))
    globals_: list[str] = []
    seeds: dict[str, tuple[str, ...]] = {}
    lets: list[tuple[str, Expr]] = []
    raw_prods: list[tuple[int, str, tuple[str, ...], str | None, str]] = []
    max_depth, max_modules = 64, 1_000_000
    for line, stmt in stmts[1:]:
        word = stmt.split(None, 1)[0]
        if word == "limits" and "->" not in stmt:
            if not _LIMITS.match(stmt):
                raise GrammarError("expected 'limits depth N modules M'", line)
            toks = stmt.split()[1:]
            for key, val in zip(toks[::2], toks[1::2], strict=True):
                if key == "depth":
                    max_depth = int(val)
                else:
                    max_modules = int(val)
        elif word == "global" and "->" not in stmt:
            for g in stmt.split()[1:]:
                if not _IDENT.fullmatch(g) or g in _RESERVED:
                    raise GrammarError(f"bad global name {g!r}", line)
                globals_.append(g)
        elif word == "seed" and "->" not in stmt:
            scanned = _scan_successors(stmt[4:], line)
            for sym, rep, args in scanned:
                if rep is not None:
                    raise GrammarError("a seed cannot have a repeat count", line)
                params = tuple(a.strip() for a in args)
                for p in params:
                    if not _IDENT.fullmatch(p):
                        raise GrammarError(f"seed {sym}: bad parameter name {p!r}", line)
                seeds[sym] = params
        elif word == "let" and "->" not in stmt:
            lm = _LET.match(stmt)
            if not lm:
                raise GrammarError("expected 'let NAME = EXPRESSION'", line)
            lname = lm.group(1)
            if lname in _RESERVED or lname in globals_:
                raise GrammarError(f"'{lname}' cannot be redefined", line)
            known = set(globals_) | {n for n, _ in lets}
            lets.append((lname, compile_expr(lm.group(2), known, line)))
        else:
            pm = _PRED.match(stmt)
            if not pm:
                raise GrammarError(
                    f"expected a production 'Pred(params) : condition -> successors', got {stmt[:40]!r}",
                    line,
                )
            sym = pm.group(1)
            params = tuple(p.strip() for p in pm.group(3).split(",")) if pm.group(3) and pm.group(3).strip() else ()
            for p in params:
                if not _IDENT.fullmatch(p) or p in _RESERVED:
                    raise GrammarError(f"{sym}: bad parameter name {p!r}", line)
            if len(set(params)) != len(params):
                raise GrammarError(f"{sym}: repeated parameter name", line)
            if sym in TERMINALS:
                raise GrammarError(f"{sym} is a terminal operation and cannot be rewritten", line)
            cond = pm.group(5).strip() if pm.group(4) else None
            if pm.group(4) and not cond:
                raise GrammarError(f"{sym}: empty condition after ':'", line)
            raw_prods.append((line, sym, params, cond, pm.group(6)))

    # arities: terminals fixed, seeds declared, then each predecessor's own list
    arity: dict[str, int] = {k: len(v) for k, v in TERMINALS.items()}
    for sym, params in seeds.items():
        arity[sym] = len(params)
    for line, sym, params, _, _ in raw_prods:
        if arity.setdefault(sym, len(params)) != len(params):
            raise GrammarError(f"{sym} has {len(params)} parameters here but {arity[sym]} elsewhere", line)

    let_names = {n for n, _ in lets}
    scalar_names = set(globals_) | let_names
    prods: dict[str, list[Production]] = {}
    for line, sym, params, cond_text, succ_text in raw_prods:
        clash = scalar_names.intersection(params)
        if clash:
            raise GrammarError(f"{sym}: parameter {sorted(clash)[0]!r} hides a global or let", line)
        known = scalar_names | set(params)
        cond = compile_expr(cond_text, known, line) if cond_text else None
        succs: list[Successor] = []
        body = succ_text.strip()
        if body not in ("*", "ε"):
            if not body:
                raise GrammarError(f"{sym}: empty right-hand side (write '*' to delete)", line)
            for s_sym, rep_text, arg_texts in _scan_successors(body, line):
                rep_expr = compile_expr(rep_text, known, line) if rep_text is not None else None
                arg_known = known | {"i"} if rep_expr is not None else known
                arg_exprs = tuple(compile_expr(a, arg_known, line) for a in arg_texts)
                want = arity.setdefault(s_sym, len(arg_exprs))
                if want != len(arg_exprs):
                    raise GrammarError(f"{s_sym} takes {want} parameters, got {len(arg_exprs)}", line)
                succs.append(Successor(s_sym, arg_exprs, rep_expr, line))
        prods.setdefault(sym, []).append(Production(sym, params, cond, tuple(succs), line))

    return Grammar(
        name=name,
        version=version,
        text=text,
        globals=tuple(globals_),
        seeds=seeds,
        lets=tuple(lets),
        productions={k: tuple(v) for k, v in prods.items()},
        arity=arity,
        max_depth=max_depth,
        max_modules=max_modules,
        digest=hashlib.sha256(text.encode("utf-8")).hexdigest(),
    )


def load_grammar(path: str | Path) -> Grammar:
    """Read and parse a grammar file (UTF-8)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise GrammarError(f"cannot read grammar file {p}: {exc.strerror}") from exc
    return parse_grammar(text)
