"""Bounded, vectorised derivation of a parametric L-system.

Modules of one symbol are kept together as a ``(count, arity) float64`` array, so one
derivation step evaluates each production's condition and each successor's argument
expressions once per symbol, not once per module.  The order of modules in the
string is not kept: the interpretation of this project's grammars (generic geometric
operations placed by their own parameters) does not depend on it.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.errors import DerivationLimitError, GrammarError
from walkstream.shared.lsystem.grammar import Grammar

__all__ = ["derive", "evaluate_lets", "depth_error", "Modules"]

#: symbol -> (count, arity) float64 parameters of the modules with that symbol
Modules = dict[str, NDArray[np.float64]]


def evaluate_lets(grammar: Grammar, globals_: Mapping[str, float]) -> dict[str, Any]:
    """Check the host's globals and evaluate the grammar's ``let`` constants in order."""
    missing = [g for g in grammar.globals if g not in globals_]
    if missing:
        raise GrammarError(f"the host did not provide the global(s) {', '.join(missing)}")
    scope: dict[str, Any] = {k: float(v) for k, v in globals_.items()}
    with np.errstate(all="ignore"):
        for name, expr in grammar.lets:
            v = expr.eval(scope)
            # most lets are plain Python numbers; skip numpy for them (hot path per building)
            scope[name] = float(v) if isinstance(v, int | float) else float(np.asarray(v, dtype=np.float64))
    return scope


def depth_error(grammar: Grammar, limit: int, growing: Mapping[str, int]) -> DerivationLimitError:
    """The error of a derivation still rewriting ``growing`` (symbol -> modules) at depth ``limit``."""
    names = ", ".join(f"{s} ({n})" for s, n in sorted(growing.items()))
    return DerivationLimitError(
        f"grammar {grammar.name}: derivation did not finish within depth {limit}; still being rewritten: {names}"
    )


def _column_stack(values: list[Any], n: int) -> NDArray[np.float64]:
    if not values:
        return np.empty((n, 0), np.float64)
    out = np.empty((n, len(values)), np.float64)
    for k, v in enumerate(values):
        out[:, k] = v
    return out


def derive(
    grammar: Grammar,
    seeds: Mapping[str, NDArray[np.float64]],
    globals_: Mapping[str, float],
    *,
    max_depth: int | None = None,
    max_modules: int | None = None,
) -> Modules:
    """Rewrite ``seeds`` until no production applies; return the final modules.

    Parameters
    ----------
    grammar:
        The parsed grammar.
    seeds:
        symbol -> ``(count, arity)`` parameters of the starting modules.
    globals_:
        Values of the grammar's declared globals for this derivation.
    max_depth, max_modules:
        Override the grammar's ``limits``.

    Returns
    -------
    dict
        symbol -> ``(count, arity) float64`` for every symbol left when the
        derivation stops (terminals, and non-terminals no production matched).

    Raises
    ------
    DerivationLimitError
        When more than ``max_depth`` steps are needed or the string would hold more
        than ``max_modules`` modules; the message names the symbols still growing.
    """
    depth_limit = grammar.max_depth if max_depth is None else max_depth
    module_limit = grammar.max_modules if max_modules is None else max_modules
    scope = evaluate_lets(grammar, globals_)
    prods = grammar.productions

    active: dict[str, list[NDArray[np.float64]]] = defaultdict(list)
    done: dict[str, list[NDArray[np.float64]]] = defaultdict(list)
    total = 0
    for sym, arr in seeds.items():
        a = np.asarray(arr, dtype=np.float64)
        want = grammar.arity.get(sym, a.shape[1] if a.ndim == 2 else 0)
        if a.ndim != 2 or a.shape[1] != want:
            raise GrammarError(f"seed {sym}: expected (count, {want}) parameters, got shape {a.shape}")
        if len(a) == 0:
            continue
        total += len(a)
        (active if sym in prods else done)[sym].append(a)

    step = 0
    with np.errstate(all="ignore"):
        while active:
            if step >= depth_limit:
                raise depth_error(grammar, depth_limit, {s: sum(len(x) for x in v) for s, v in active.items()})
            step += 1
            nxt: dict[str, list[NDArray[np.float64]]] = defaultdict(list)
            # symbols in the grammar's order, not in the order they first appeared: the
            # modules a building gets then come out in the same order alone or in a batch
            for sym in prods:
                parts = active.get(sym)
                if not parts:
                    continue
                arr = parts[0] if len(parts) == 1 else np.concatenate(parts)
                n = len(arr)
                remaining = np.ones(n, dtype=bool)
                for prod in prods[sym]:
                    env: dict[str, Any] = dict(scope)
                    for k, p in enumerate(prod.params):
                        env[p] = arr[:, k]
                    if prod.condition is None:
                        hit = remaining
                    else:
                        cond = np.broadcast_to(np.asarray(prod.condition.eval(env), dtype=bool), (n,))
                        hit = remaining & cond
                    if not hit.any():
                        continue
                    all_hit = bool(hit.all())
                    sub = arr if all_hit else arr[hit]
                    m = len(sub)
                    remaining = remaining & ~hit
                    sub_env: dict[str, Any] = dict(scope)
                    for k, p in enumerate(prod.params):
                        sub_env[p] = sub[:, k]
                    for succ in prod.successors:
                        if succ.repeat is None:
                            vals = [a.eval(sub_env) for a in succ.args]
                            out = _column_stack(vals, m)
                        else:
                            raw = np.broadcast_to(np.asarray(succ.repeat.eval(sub_env), np.float64), (m,))
                            counts = np.floor(np.nan_to_num(raw, nan=0.0, posinf=0.0, neginf=0.0))
                            counts = np.clip(counts, 0, module_limit + 1).astype(np.int64)
                            reps = int(counts.sum())
                            if total + reps > module_limit:
                                raise DerivationLimitError(
                                    f"grammar {grammar.name}: more than {module_limit} modules at step "
                                    f"{step} (line {succ.line}: {{{succ.repeat.text}}} {succ.symbol})"
                                )
                            if reps == 0:
                                continue
                            rows = np.repeat(np.arange(m), counts)
                            starts = np.cumsum(counts) - counts
                            rep_env: dict[str, Any] = dict(scope)
                            for k, p in enumerate(prod.params):
                                rep_env[p] = sub[rows, k]
                            rep_env["i"] = (np.arange(reps) - np.repeat(starts, counts)).astype(np.float64)
                            vals = [a.eval(rep_env) for a in succ.args]
                            out = _column_stack(vals, reps)
                        total += len(out)
                        (nxt if succ.symbol in prods else done)[succ.symbol].append(out)
                    total -= m
                    if total > module_limit:
                        raise DerivationLimitError(
                            f"grammar {grammar.name}: more than {module_limit} modules at step {step} "
                            f"(growing: {sym}, line {prod.line})"
                        )
                    if not remaining.any():
                        break
                if remaining.any():
                    # nothing matched these; their parameters never change, so they never will
                    done[sym].append(arr[remaining])
            active = nxt
    return {s: (v[0] if len(v) == 1 else np.concatenate(v)) for s, v in done.items()}
