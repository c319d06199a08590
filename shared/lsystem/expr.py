"""Safe, vectorised arithmetic expressions for the parametric L-system.

An expression is a small piece of Python syntax (numbers, names, ``+ - * / // % **``,
comparisons, ``and``/``or``/``not``, ``a if c else b`` and a few whitelisted
functions).  It is parsed once, checked against a whitelist, rewritten so that it
works element-wise on numpy arrays (``and`` becomes ``logical_and`` and so on) and
compiled.  Evaluating it on a batch of modules then costs one numpy call per
operator, whatever the number of modules.
"""

from __future__ import annotations

import ast
from collections.abc import Mapping
from types import CodeType
from typing import Any

import numpy as np

from walkstream.shared.errors import GrammarError

__all__ = ["Expr", "compile_expr", "FUNCTIONS", "hash01"]


def hash01(seed: Any, k: Any) -> Any:
    """Deterministic pseudo-random number in [0, 1) from integers ``seed`` and ``k``.

    Integer arithmetic only, so the value is the same on every machine.  Works on
    scalars and arrays alike.
    """
    if isinstance(seed, int | float) and isinstance(k, int | float):
        return _hash01_scalar(int(seed), int(k))
    s = np.asarray(seed, dtype=np.float64).astype(np.int64).astype(np.uint64)
    kk = np.asarray(k, dtype=np.float64).astype(np.int64).astype(np.uint64)
    with np.errstate(over="ignore"):
        x = (s * np.uint64(2654435761) + kk * np.uint64(40503) + np.uint64(0x9E3779B9)) & np.uint64(
            0xFFFFFFFF
        )
        x ^= x >> np.uint64(15)
        x = (x * np.uint64(0x2C1B3C6D)) & np.uint64(0xFFFFFFFF)
        x ^= x >> np.uint64(12)
        x = (x * np.uint64(0x297A2D39)) & np.uint64(0xFFFFFFFF)
        x ^= x >> np.uint64(15)
    out = x.astype(np.float64) / 4294967296.0
    return float(out) if out.ndim == 0 else out


def _hash01_scalar(seed: int, k: int) -> float:
    """The same hash as :func:`hash01` in plain Python integers (no numpy call overhead)."""
    m = 0xFFFFFFFF
    x = ((seed % (1 << 64)) * 2654435761 + (k % (1 << 64)) * 40503 + 0x9E3779B9) & m
    x ^= x >> 15
    x = (x * 0x2C1B3C6D) & m
    x ^= x >> 12
    x = (x * 0x297A2D39) & m
    x ^= x >> 15
    return x / 4294967296.0


def _clamp(x: Any, lo: Any, hi: Any) -> Any:
    return np.minimum(np.maximum(x, lo), hi)


#: Functions an expression may call, by name.
FUNCTIONS: dict[str, Any] = {
    "floor": np.floor,
    "ceil": np.ceil,
    "round": np.round,
    "abs": np.abs,
    "sqrt": np.sqrt,
    "min": np.minimum,
    "max": np.maximum,
    "clamp": _clamp,
    "hash01": hash01,
}

_ALLOWED = (
    ast.Expression,
    ast.BinOp,
    ast.UnaryOp,
    ast.BoolOp,
    ast.Compare,
    ast.IfExp,
    ast.Call,
    ast.Name,
    ast.Load,
    ast.Constant,
    ast.Add,
    ast.Sub,
    ast.Mult,
    ast.Div,
    ast.FloorDiv,
    ast.Mod,
    ast.Pow,
    ast.USub,
    ast.UAdd,
    ast.Not,
    ast.And,
    ast.Or,
    ast.Eq,
    ast.NotEq,
    ast.Lt,
    ast.LtE,
    ast.Gt,
    ast.GtE,
)


def _call(name: str, args: list[ast.expr], like: ast.AST) -> ast.Call:
    node = ast.Call(func=ast.Name(id=name, ctx=ast.Load()), args=args, keywords=[])
    return ast.copy_location(node, like)


class _Vectorise(ast.NodeTransformer):
    """Rewrite boolean logic and conditionals into element-wise numpy calls."""

    def visit_BoolOp(self, node: ast.BoolOp) -> ast.AST:
        self.generic_visit(node)
        fn = "__and" if isinstance(node.op, ast.And) else "__or"
        out = node.values[0]
        for v in node.values[1:]:
            out = _call(fn, [out, v], node)
        return out

    def visit_UnaryOp(self, node: ast.UnaryOp) -> ast.AST:
        self.generic_visit(node)
        if isinstance(node.op, ast.Not):
            return _call("__not", [node.operand], node)
        return node

    def visit_Compare(self, node: ast.Compare) -> ast.AST:
        self.generic_visit(node)
        parts: list[ast.expr] = []
        left = node.left
        for op, right in zip(node.ops, node.comparators, strict=True):
            parts.append(ast.copy_location(ast.Compare(left=left, ops=[op], comparators=[right]), node))
            left = right
        out = parts[0]
        for p in parts[1:]:
            out = _call("__and", [out, p], node)
        return out

    def visit_IfExp(self, node: ast.IfExp) -> ast.AST:
        self.generic_visit(node)
        return _call("__where", [node.test, node.body, node.orelse], node)


_HIDDEN = {
    "__and": np.logical_and,
    "__or": np.logical_or,
    "__not": np.logical_not,
    "__where": np.where,
}


class Expr:
    """A compiled expression; call :meth:`eval` with a mapping of names to values."""

    __slots__ = ("text", "names", "_code", "constant")

    def __init__(self, text: str, names: frozenset[str], code: CodeType, constant: Any) -> None:
        self.text = text
        self.names = names
        self._code = code
        self.constant = constant

    def eval(self, env: Mapping[str, Any]) -> Any:
        """Evaluate on scalars or equally-shaped arrays given by ``env``."""
        if self.constant is not None:
            return self.constant
        return eval(self._code, _GLOBALS, env)  # noqa: S307 - whitelisted AST only

    def __repr__(self) -> str:
        return f"Expr({self.text!r})"


_GLOBALS: dict[str, Any] = {"__builtins__": {}, **FUNCTIONS, **_HIDDEN}


def compile_expr(text: str, known: set[str] | frozenset[str], line: int = 0) -> Expr:
    """Parse and check ``text``; every name must be in ``known`` or be a function.

    Raises
    ------
    GrammarError
        With ``line``, when the text is not a valid expression, uses syntax outside
        the whitelist, calls an unknown function or names an unknown variable.
    """
    src = text.strip()
    if not src:
        raise GrammarError("empty expression", line)
    try:
        tree = ast.parse(src, mode="eval")
    except SyntaxError as exc:
        raise GrammarError(f"cannot parse expression {src!r}: {exc.msg}", line) from exc
    names: set[str] = set()
    for node in ast.walk(tree):
        if not isinstance(node, _ALLOWED):
            raise GrammarError(f"{type(node).__name__} is not allowed in expression {src!r}", line)
        if isinstance(node, ast.Call):
            if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS or node.keywords:
                raise GrammarError(
                    f"unknown function in {src!r}; known: {', '.join(sorted(FUNCTIONS))}", line
                )
        elif isinstance(node, ast.Name):
            if node.id in FUNCTIONS:
                continue
            if node.id not in known:
                raise GrammarError(f"unknown name {node.id!r} in expression {src!r}", line)
            names.add(node.id)
        elif isinstance(node, ast.Constant) and not isinstance(node.value, int | float):
            raise GrammarError(f"only numbers may appear as constants in {src!r}", line)
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            names.discard(node.func.id)
    tree = ast.fix_missing_locations(_Vectorise().visit(tree))
    code = compile(tree, f"<grammar line {line}>", "eval")
    constant = None
    if not names:
        try:
            with np.errstate(all="ignore"):
                constant = eval(code, _GLOBALS, {})  # noqa: S307
        except Exception as exc:  # an error in a constant is a grammar error
            raise GrammarError(f"cannot evaluate {src!r}: {exc}", line) from exc
    return Expr(src, frozenset(names), code, constant)
