"""Derive and interpret many derivations at once (a batch of buildings).

:func:`~walkstream.shared.lsystem.derive.derive` and
:func:`~walkstream.shared.lsystem.interpret.interpret` already work per symbol on
arrays, but one building's derivation is only a few hundred modules, so their cost
is the Python around the numpy calls, paid once per building.  Here every module
carries its *owner* (the index of its derivation in the batch) and the globals and
lets are per-owner arrays, so one pass over the grammar derives every building of
the batch and one pass over the terminals builds every mesh: the per-building
interpreter overhead is paid once per batch.

The result for each owner is the same as its own derivation and interpretation:
the same arithmetic on the same values (element-wise, so bit for bit), the modules
of one owner in the same order (both engines visit symbols in grammar order and keep
the order within a symbol), hence the same triangles in the same order.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.errors import DerivationLimitError, GrammarError
from walkstream.shared.lsystem.derive import Modules, depth_error
from walkstream.shared.lsystem.grammar import Grammar, Production
from walkstream.shared.lsystem.interpret import BOX, QUAD, EdgeFrames, instance, valid_rows
from walkstream.shared.records import Mesh

__all__ = ["Owners", "FrameBatch", "derive_batch", "interpret_batch", "block_offsets"]

#: symbol -> ``(count,) int64`` owner (index in the batch) of each module
Owners = dict[str, NDArray[np.int64]]


@dataclass(frozen=True, slots=True)
class FrameBatch:
    """The edge frames of a batch of footprints, concatenated.

    ``frames`` holds every footprint's edges and cap vertices one after the other;
    its ``cap_tris (t, 3)`` index each footprint's own cap vertices (0-based per
    footprint).  ``edge_start``, ``cap_start`` and ``tri_start`` are ``(B + 1,)``
    offsets of each footprint's edges, cap vertices and cap triangles.
    """

    frames: EdgeFrames
    edge_start: NDArray[np.int64]
    cap_start: NDArray[np.int64]
    tri_start: NDArray[np.int64]

    @property
    def size(self) -> int:
        """Number of footprints ``B``."""
        return len(self.edge_start) - 1


def _uniform(v: Any) -> Any:
    """A per-owner array whose values are all equal, as that one float (cheaper to broadcast)."""
    if isinstance(v, np.ndarray) and v.ndim == 1:
        if len(v) and bool((v == v[0]).all()):
            return float(v[0])
        return v
    return float(v) if isinstance(v, int | float) else float(np.asarray(v, dtype=np.float64))


def _lets(grammar: Grammar, globals_: Mapping[str, Any]) -> dict[str, Any]:
    """Globals and lets, each a float or a ``(B,)`` per-owner array."""
    missing = [g for g in grammar.globals if g not in globals_]
    if missing:
        raise GrammarError(f"the host did not provide the global(s) {', '.join(missing)}")
    scope = {k: _uniform(np.asarray(v, np.float64) if isinstance(v, np.ndarray) else v) for k, v in globals_.items()}
    with np.errstate(all="ignore"):
        for name, expr in grammar.lets:
            scope[name] = _uniform(expr.eval(scope))
    return scope


def _bind(scope: Mapping[str, Any], names: frozenset[str], own: NDArray[np.int64]) -> dict[str, Any]:
    """The scope values ``names`` need, per-owner arrays gathered for the modules ``own``."""
    env: dict[str, Any] = {}
    for n in names:
        v = scope.get(n)
        if v is not None:
            env[n] = v[own] if isinstance(v, np.ndarray) else v
    return env


def _names(prod: Production) -> tuple[frozenset[str], frozenset[str]]:
    """Names the condition uses, and names the successors use."""
    cond = prod.condition.names if prod.condition is not None else frozenset()
    succ: set[str] = set()
    for s in prod.successors:
        for a in s.args:
            succ |= a.names
        if s.repeat is not None:
            succ |= s.repeat.names
    return cond, frozenset(succ)


def derive_batch(
    grammar: Grammar,
    seeds: Mapping[str, NDArray[np.float64]],
    owners: Mapping[str, NDArray[np.int64]],
    globals_: Mapping[str, Any],
    count: int,
    *,
    max_depth: int | None = None,
    max_modules: int | None = None,
) -> tuple[Modules, Owners]:
    """Derive ``count`` derivations at once.

    Parameters
    ----------
    grammar:
        The parsed grammar.
    seeds:
        symbol -> ``(m, arity)`` parameters of the starting modules of all owners.
    owners:
        symbol -> ``(m,) int64`` owner in ``[0, count)`` of each seed module.
    globals_:
        The grammar's globals, each a float (the same for all) or a ``(count,)`` array.
    count:
        Number of derivations ``B``.
    max_depth, max_modules:
        Override the grammar's ``limits`` (``max_modules`` holds per derivation).

    Returns
    -------
    (modules, owners)
        symbol -> ``(m, arity) float64`` and symbol -> ``(m,) int64``, sorted by owner;
        one owner's rows are what :func:`~walkstream.shared.lsystem.derive.derive`
        returns for it alone, in the same order.

    Raises
    ------
    DerivationLimitError
        When a derivation needs more than ``max_depth`` steps or more than
        ``max_modules`` modules (the message names the symbols, not the owner: derive
        the owners one by one to find it).
    """
    depth_limit = grammar.max_depth if max_depth is None else max_depth
    module_limit = grammar.max_modules if max_modules is None else max_modules
    scope = _lets(grammar, globals_)
    prods = grammar.productions
    used = {id(p): _names(p) for ps in prods.values() for p in ps}

    Part = tuple[NDArray[np.float64], NDArray[np.int64]]
    active: dict[str, list[Part]] = defaultdict(list)
    done: dict[str, list[Part]] = defaultdict(list)
    per_owner = np.zeros(count, np.int64)
    for sym, arr in seeds.items():
        a = np.asarray(arr, dtype=np.float64)
        want = grammar.arity.get(sym, a.shape[1] if a.ndim == 2 else 0)
        if a.ndim != 2 or a.shape[1] != want:
            raise GrammarError(f"seed {sym}: expected (count, {want}) parameters, got shape {a.shape}")
        own = np.asarray(owners[sym], np.int64)
        if len(a) == 0:
            continue
        per_owner += np.bincount(own, minlength=count)
        (active if sym in prods else done)[sym].append((a, own))

    def too_many(where: str) -> DerivationLimitError:
        return DerivationLimitError(f"grammar {grammar.name}: more than {module_limit} modules in one derivation {where}")

    step = 0
    with np.errstate(all="ignore"):
        while active:
            if step >= depth_limit:
                raise depth_error(grammar, depth_limit, {s: sum(len(x) for x, _ in v) for s, v in active.items()})
            step += 1
            nxt: dict[str, list[Part]] = defaultdict(list)
            for sym in prods:  # grammar order, as derive() does
                parts = active.get(sym)
                if not parts:
                    continue
                if len(parts) == 1:
                    arr, own = parts[0]
                else:
                    arr, own = np.concatenate([p for p, _ in parts]), np.concatenate([o for _, o in parts])
                n = len(arr)
                remaining = np.ones(n, dtype=bool)
                for prod in prods[sym]:
                    cond_names, succ_names = used[id(prod)]
                    if prod.condition is None:
                        hit = remaining
                    else:
                        env = _bind(scope, cond_names, own)
                        for k, p in enumerate(prod.params):
                            env[p] = arr[:, k]
                        cond = np.broadcast_to(np.asarray(prod.condition.eval(env), dtype=bool), (n,))
                        hit = remaining & cond
                    if not hit.any():
                        continue
                    all_hit = bool(hit.all())
                    sub, sub_own = (arr, own) if all_hit else (arr[hit], own[hit])
                    m = len(sub)
                    remaining = remaining & ~hit
                    sub_env = _bind(scope, succ_names, sub_own)
                    for k, p in enumerate(prod.params):
                        sub_env[p] = sub[:, k]
                    for succ in prod.successors:
                        if succ.repeat is None:
                            out = np.empty((m, len(succ.args)), np.float64)
                            for k, ex in enumerate(succ.args):
                                out[:, k] = ex.eval(sub_env)
                            out_own = sub_own
                        else:
                            raw = np.broadcast_to(np.asarray(succ.repeat.eval(sub_env), np.float64), (m,))
                            counts = np.floor(np.nan_to_num(raw, nan=0.0, posinf=0.0, neginf=0.0))
                            counts = np.clip(counts, 0, module_limit + 1).astype(np.int64)
                            reps = int(counts.sum())
                            if reps == 0:
                                continue
                            if (per_owner + np.bincount(sub_own, counts, count)).max() > module_limit:
                                raise too_many(f"at step {step} (line {succ.line}: {{{succ.repeat.text}}} {succ.symbol})")
                            rows = np.repeat(np.arange(m), counts)
                            starts = np.cumsum(counts) - counts
                            rep_env = _bind(scope, succ_names, sub_own[rows])
                            for k, p in enumerate(prod.params):
                                rep_env[p] = sub[rows, k]
                            rep_env["i"] = (np.arange(reps) - np.repeat(starts, counts)).astype(np.float64)
                            out = np.empty((reps, len(succ.args)), np.float64)
                            for k, ex in enumerate(succ.args):
                                out[:, k] = ex.eval(rep_env)
                            out_own = sub_own[rows]
                        per_owner += np.bincount(out_own, minlength=count)
                        (nxt if succ.symbol in prods else done)[succ.symbol].append((out, out_own))
                    per_owner -= np.bincount(sub_own, minlength=count)
                    if per_owner.max() > module_limit:
                        raise too_many(f"at step {step} (growing: {sym}, line {prod.line})")
                    if not remaining.any():
                        break
                if remaining.any():
                    # nothing matched these; their parameters never change, so they never will
                    done[sym].append((arr[remaining], own[remaining]))
            active = nxt

    modules: Modules = {}
    out_owners: Owners = {}
    for sym, parts in done.items():
        arr = parts[0][0] if len(parts) == 1 else np.concatenate([p for p, _ in parts])
        own = parts[0][1] if len(parts) == 1 else np.concatenate([o for _, o in parts])
        # stable: one owner's modules keep the order its own derivation gives them
        order = np.argsort(own, kind="stable")
        modules[sym], out_owners[sym] = arr[order], own[order]
    return modules, out_owners


def block_offsets(counts: NDArray[Any]) -> NDArray[np.int64]:
    """``(B + 1,)`` offsets of ``B`` consecutive blocks of ``counts`` rows (0 first, the total last).

    >>> block_offsets(np.array([2, 0, 3])).tolist()
    [0, 2, 2, 5]
    """
    out = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=out[1:])
    return out


def _starts(counts: NDArray[Any]) -> NDArray[np.int64]:
    """Where each of the blocks of ``counts`` rows starts."""
    return block_offsets(counts)[:-1]


class _Assembly:
    """Pieces of all meshes (caps, then each template kind), scattered per owner at the end.

    One owner's mesh is its caps, then its quads, then its boxes, each in module
    order: the layout :func:`~walkstream.shared.lsystem.interpret.interpret` makes.
    """

    def __init__(self, count: int) -> None:
        self.count = count
        self.pieces: list[tuple[Any, ...]] = []
        self.verts = np.zeros(count, np.int64)  # vertices so far per owner

    def add(
        self,
        pos: NDArray[np.float64],
        nor: NDArray[np.float64],
        tris: NDArray[np.int64],
        mats: NDArray[np.float64],
        v_own: NDArray[np.int64],
        t_own: NDArray[np.int64],
    ) -> None:
        """Add a piece: ``(n, 3)`` positions and normals, ``(n,)`` materials and owners,
        ``(t, 3)`` triangles and ``(t,)`` owners, rows sorted by owner; ``tris`` index the
        owner's own vertices of this piece (0-based per owner)."""
        v_count = np.bincount(v_own, minlength=self.count)
        t_count = np.bincount(t_own, minlength=self.count)
        # converted here, whole-array, so that each owner's mesh is only slices joined
        self.pieces.append(
            (
                pos.astype(np.float32),
                nor.astype(np.float32),
                (tris + self.verts[t_own][:, None]).astype(np.uint32),
                np.clip(mats, 0, 255).astype(np.uint8),
                block_offsets(v_count).tolist(),
                block_offsets(t_count).tolist(),
            )
        )
        self.verts = self.verts + v_count

    def meshes(self) -> list[Mesh]:
        """One :class:`Mesh` per owner (its own arrays: nothing keeps the batch alive)."""
        if not self.pieces:
            return [Mesh(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3))) for _ in range(self.count)]
        out = []
        for b in range(self.count):
            vs = [(p[4][b], p[4][b + 1]) for p in self.pieces]
            ts = [(p[5][b], p[5][b + 1]) for p in self.pieces]
            out.append(
                Mesh(
                    np.concatenate([p[0][v0:v1] for p, (v0, v1) in zip(self.pieces, vs, strict=True)]),
                    np.concatenate([p[1][v0:v1] for p, (v0, v1) in zip(self.pieces, vs, strict=True)]),
                    np.concatenate([p[2][t0:t1] for p, (t0, t1) in zip(self.pieces, ts, strict=True)]),
                    np.concatenate([p[3][v0:v1] for p, (v0, v1) in zip(self.pieces, vs, strict=True)]),
                )
            )
        return out


def interpret_batch(modules: Modules, owners: Owners, batch: FrameBatch) -> list[Mesh]:
    """Build the mesh of every owner of a batch derivation (non-terminals are ignored).

    Parameters
    ----------
    modules, owners:
        What :func:`derive_batch` returns (rows sorted by owner).
    batch:
        The owners' edge frames.

    Returns
    -------
    list of Mesh
        ``B`` meshes, each the same as
        :func:`~walkstream.shared.lsystem.interpret.interpret` makes for that owner alone.
    """
    B = batch.size
    fr = batch.frames
    n_edges = np.diff(batch.edge_start)
    asm = _Assembly(B)

    caps = modules.get("Cap")
    if caps is not None and len(caps):
        own = owners["Cap"]
        nv_all = np.diff(batch.cap_start)
        nt_all = np.diff(batch.tri_start)
        ok = valid_rows("Cap", caps, 0) & (nt_all[own] > 0)
        caps, own = caps[ok], own[ok]
        nv, nt = nv_all[own], nt_all[own]
        # vertex j of cap module c: cap vertex cap_start[owner] + j
        v_mod = np.repeat(np.arange(len(caps)), nv)
        v_first = _starts(nv)
        v_idx = batch.cap_start[own][v_mod] + np.arange(len(v_mod)) - v_first[v_mod]
        pos = np.empty((len(v_idx), 3))
        pos[:, :2] = fr.cap_xy[v_idx]
        pos[:, 2] = caps[v_mod, 0]
        up = np.where(caps[:, 1] >= 0, 1.0, -1.0)
        nor = np.zeros((len(v_idx), 3))
        nor[:, 2] = up[v_mod]
        t_mod = np.repeat(np.arange(len(caps)), nt)
        t_idx = batch.tri_start[own][t_mod] + np.arange(len(t_mod)) - _starts(nt)[t_mod]
        tris = fr.cap_tris[t_idx]
        tris = np.where((up[t_mod] > 0)[:, None], tris, tris[:, ::-1])
        # one owner's caps follow each other: a cap's vertices start after the owner's earlier caps
        v_before = v_first - _starts(np.bincount(own, nv, B).astype(np.int64))[own]
        tris = tris + v_before[t_mod][:, None]
        asm.add(pos, nor, tris, caps[v_mod, 2], own[v_mod], own[t_mod])

    for sym, template in (("Quad", QUAD), ("Box", BOX)):
        p = modules.get(sym)
        if p is None or len(p) == 0:
            continue
        own = owners[sym]
        e_local = p[:, 0]
        ok = valid_rows(sym, p, 1 << 62) & (e_local < n_edges[own])
        p, own = p[ok], own[ok]
        if len(p) == 0:
            continue
        e = p[:, 0].astype(np.int64) + batch.edge_start[own]
        u0, z0, u1, z1, off = p[:, 1], p[:, 2], p[:, 3], p[:, 4], p[:, 5]
        depth, mat = (np.zeros(len(p)), p[:, 6]) if sym == "Quad" else (p[:, 6], p[:, 7])
        v, t = len(template[0]), len(template[2])
        pos, nor, _ = instance(template, fr, e, u0, z0, u1 - u0, z1 - z0, off, depth)
        rank = np.arange(len(p)) - _starts(np.bincount(own, minlength=B))[own]
        tris = (template[2][None, :, :] + (rank * v)[:, None, None]).reshape(-1, 3)
        asm.add(pos, nor, tris, np.repeat(mat, v), np.repeat(own, v), np.repeat(own, t))
    return asm.meshes()
