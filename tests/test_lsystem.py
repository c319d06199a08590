"""The parametric L-system engine: parsing, conditions, repeats, limits, errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from walkstream.shared.errors import DerivationLimitError, GrammarError
from walkstream.shared.lsystem.derive import derive
from walkstream.shared.lsystem.expr import compile_expr, hash01
from walkstream.shared.lsystem.grammar import parse_grammar


def _g(body: str) -> str:
    return "grammar t 1\nglobal X\n" + body


def test_conditions_pick_first_matching_production() -> None:
    g = parse_grammar(
        _g(
            """
A(n) : n > 2 -> B(n * 10)
A(n) : n > 0 -> C(n)
A(n) -> *
"""
        )
    )
    out = derive(g, {"A": np.array([[1.0], [3.0], [-1.0], [2.0]])}, {"X": 0})
    assert sorted(out["B"][:, 0]) == [30.0]
    assert sorted(out["C"][:, 0]) == [1.0, 2.0]
    assert "A" not in out


def test_repeat_index_and_recursion() -> None:
    g = parse_grammar(
        _g(
            """
let STEP = 2 * X
Row(n) -> {n} Cell(i * STEP)
Count(k) : k < 5 -> Mark(k) Count(k + 1)
"""
        )
    )
    out = derive(g, {"Row": np.array([[3.0], [2.0]]), "Count": np.array([[0.0]])}, {"X": 1.5})
    assert sorted(out["Cell"][:, 0]) == [0.0, 0.0, 3.0, 3.0, 6.0]
    assert sorted(out["Mark"][:, 0]) == [0, 1, 2, 3, 4]
    # Count(5) matches nothing and stays as it is
    assert out["Count"][:, 0].tolist() == [5.0]


def test_unbounded_growth_trips_module_limit() -> None:
    g = parse_grammar(_g("limits depth 1000 modules 5000\nA(x) -> A(x) A(x + 1)\n"))
    with pytest.raises(DerivationLimitError, match="more than 5000 modules"):
        derive(g, {"A": np.zeros((1, 1))}, {"X": 0})


def test_endless_rewriting_trips_depth_limit() -> None:
    g = parse_grammar(_g("limits depth 30\nA(x) -> A(x + 1)\n"))
    with pytest.raises(DerivationLimitError, match="depth 30.*A \\(1\\)"):
        derive(g, {"A": np.zeros((1, 1))}, {"X": 0})


def test_huge_repeat_is_refused_before_allocating() -> None:
    g = parse_grammar(_g("limits modules 1000\nA(x) -> {1e12} B(i)\n"))
    with pytest.raises(DerivationLimitError, match="more than 1000 modules"):
        derive(g, {"A": np.zeros((1, 1))}, {"X": 0})


@pytest.mark.parametrize(
    ("text", "line", "match"),
    [
        ("nonsense here\n", 1, "grammar NAME VERSION"),
        ("grammar t 1\n\n# c\nA(x) -> B(x\n", 4, "unbalanced"),
        ("grammar t 1\nA(x) -> B(y)\n", 2, "unknown name 'y'"),
        ("grammar t 1\nA(x) -> B(x)\nC(x) -> B(x, x)\n", 3, "B takes 1 parameters, got 2"),
        ("grammar t 1\nA(x) -> B(__import__('os'))\n", 2, "unknown function"),
        ("grammar t 1\nA(x) -> B(x.real)\n", 2, "Attribute is not allowed"),
        ("grammar t 1\nA(x) : -> B(x)\n", 2, "empty condition"),
        ("grammar t 1\nlet = 3\n", 2, "let NAME"),
        ("grammar t 1\nQuad(a) -> B(a)\n", 2, "terminal operation"),
        ("grammar t 1\nA(x) -> Quad(x)\n", 2, "Quad takes 7 parameters"),
        ("grammar t 1\nlimits depth many\n", 2, "limits depth"),
        ("grammar t 1\nA(x) ->\n", 2, "empty right-hand side"),
    ],
)
def test_malformed_grammar_names_its_line(text: str, line: int, match: str) -> None:
    with pytest.raises(GrammarError, match=match) as exc:
        parse_grammar(text)
    assert exc.value.line == line
    assert str(exc.value).startswith(f"grammar line {line}:")


def test_continuation_lines_keep_the_first_line_number() -> None:
    with pytest.raises(GrammarError) as exc:
        parse_grammar("grammar t 1\nA(x) -> B(x)\n       C(zz)\n")
    assert exc.value.line == 2


def test_expressions_are_elementwise() -> None:
    e = compile_expr("a if a > 1 and not b == 2 else -a", {"a", "b"})
    got = e.eval({"a": np.array([0.0, 2.0, 3.0]), "b": np.array([0.0, 0.0, 2.0])})
    assert got.tolist() == [-0.0, 2.0, -3.0]
    assert compile_expr("1 < 2 < 3", set()).constant


@given(st.integers(0, 2**31 - 1), st.integers(0, 1000))
def test_hash01_in_unit_interval_and_vectorised(seed: int, k: int) -> None:
    v = hash01(seed, k)
    assert 0.0 <= v < 1.0
    arr = hash01(np.array([seed, seed]), np.array([k, k + 1]))
    assert arr[0] == v
