"""The parametric L-system: expressions -> grammar -> derivation -> interpretation into meshes
(one derivation at a time, or a batch of them at once: :mod:`.batch`)."""

from walkstream.shared.lsystem.batch import FrameBatch, derive_batch, interpret_batch
from walkstream.shared.lsystem.derive import derive, evaluate_lets
from walkstream.shared.lsystem.expr import Expr, compile_expr, hash01
from walkstream.shared.lsystem.grammar import (
    Grammar,
    Production,
    Successor,
    load_grammar,
    parse_grammar,
)
from walkstream.shared.lsystem.interpret import EdgeFrames, count_triangles, interpret

__all__ = [
    "Expr",
    "compile_expr",
    "hash01",
    "Grammar",
    "Production",
    "Successor",
    "parse_grammar",
    "load_grammar",
    "derive",
    "evaluate_lets",
    "EdgeFrames",
    "interpret",
    "count_triangles",
    "FrameBatch",
    "derive_batch",
    "interpret_batch",
]
