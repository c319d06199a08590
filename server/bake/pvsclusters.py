"""Visibility lists clustered along the cell adjacency (after m-LOMA, Nurminen 2006).

m-LOMA grows its visibility clusters from a root cell into the adjacent cell with the
smallest difference, branch by branch, until a maximum difference, depth or size is
reached, then starts a new root until every cell is in a tree.  Here the same growth
finds *shared object sets*: from a seed cell, the cluster's cells grow one adjacent
cell at a time (the one keeping most of the shared set), the shared set being the
intersection of their lists still uncovered; the prefix of the growth with the best
estimated saving becomes a cluster, and every other cell whose uncovered list holds
the whole set names it too.  A cell's list is then its clusters plus the rest
(:mod:`walkstream.shared.codec.pvsclusters`); each object of a cell is in at most
one of its parts, so the expanded list is exactly the cell's PVS.

The ACH stays per cell and object: the clusters share ids only.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.codec.pvsclusters import expand_list

__all__ = ["ClusterSettings", "ListClusters", "cluster_lists"]


@dataclass(frozen=True)
class ClusterSettings:
    """The growth's limits and the byte model its choices use.

    The model only ranks candidate clusters; the sizes reported are the real
    encoders' (``walkstream bench clusters``).
    """

    min_objects: int = 12
    """Smallest shared set worth a cluster."""
    max_cells: int = 64
    """Most cells one growth adds (m-LOMA's maximum tree size)."""
    id_bytes: float = 1.3
    """Bytes one id takes in a delta-coded list (estimate)."""
    ref_bytes: float = 1.5
    """Bytes one cluster id takes in a cell record (estimate)."""
    cluster_bytes: float = 24.0
    """Bytes a cluster record takes beyond its ids (estimate)."""


@dataclass(frozen=True)
class ListClusters:
    """A scene's lists as clusters and rests.

    Attributes
    ----------
    clusters:
        Cluster id -> ``(k,) int64`` object ids, ascending (ids count from 0).
    cell_clusters:
        Cell id -> ``(m,) int64`` ascending ids of the clusters it names (empty: none).
    rest:
        Cell id -> ``(r,) int64`` ascending ids of its objects in none of its clusters.
    """

    clusters: dict[int, NDArray[np.int64]]
    cell_clusters: dict[int, NDArray[np.int64]]
    rest: dict[int, NDArray[np.int64]]

    def expanded(self, cell: int) -> NDArray[np.int64]:
        """Cell ``cell``'s whole list, ascending (its clusters' ids and its rest)."""
        return expand_list(self.cell_clusters[cell], self.rest[cell], self.clusters, f"cell {cell}")


def _gain(n_objects: int, n_cells: int, s: ClusterSettings) -> float:
    """Estimated bytes saved by a cluster of ``n_objects`` named by ``n_cells`` cells."""
    return (n_cells - 1) * n_objects * s.id_bytes - n_cells * s.ref_bytes - s.cluster_bytes


def cluster_lists(
    pvs: Mapping[int, NDArray[np.int64]],
    neighbours: Mapping[int, Sequence[int]],
    settings: ClusterSettings | None = None,
) -> ListClusters:
    """Cluster the cells' lists by greedy growth along their adjacency.

    Parameters
    ----------
    pvs:
        Cell id -> ``(k,)`` its PVS object ids (ascending or not).
    neighbours:
        Cell id -> ids of its adjacent cells (ids not in ``pvs`` are ignored).
    settings:
        Limits and byte model (defaults: :class:`ClusterSettings`).

    Returns
    -------
    ListClusters
        For every cell of ``pvs``, its clusters and rest; ``expanded(c)`` equals
        ``sorted(pvs[c])``.  Deterministic for the same input.
    """
    s = settings or ClusterSettings()
    cells = sorted(pvs)
    row = {c: n for n, c in enumerate(cells)}
    lists = [np.unique(np.asarray(pvs[c], np.int64)) for c in cells]
    objects = np.unique(np.concatenate(lists)) if lists else np.zeros(0, np.int64)
    # remaining[i, j]: object j of cell i is in none of its clusters yet
    remaining = np.zeros((len(cells), len(objects)), dtype=bool)
    for n, ids in enumerate(lists):
        remaining[n, np.searchsorted(objects, ids)] = True
    adj = [
        sorted({row[m] for m in neighbours.get(c, ()) if m in row and m != c}) for c in cells
    ]
    uses: list[list[int]] = [[] for _ in cells]
    clusters: list[NDArray[np.int64]] = []
    order = np.argsort(-remaining.sum(axis=1), kind="stable")
    for seed in order.tolist():
        while remaining[seed].sum() >= s.min_objects:
            found = _grow(seed, remaining, adj, s)
            if found is None:
                break
            shared, group = found
            # every cell still holding the whole set uncovered names it too
            holders = np.flatnonzero(remaining[:, shared].all(axis=1))
            users = sorted(set(group) | set(holders.tolist()))
            remaining[np.ix_(np.asarray(users, np.int64), shared)] = False
            k = len(clusters)
            clusters.append(objects[shared])
            for u in users:
                uses[u].append(k)
    return ListClusters(
        clusters={k: ids for k, ids in enumerate(clusters)},
        cell_clusters={c: np.asarray(uses[n], np.int64) for n, c in enumerate(cells)},
        rest={c: objects[remaining[n]] for n, c in enumerate(cells)},
    )


def _grow(
    seed: int, remaining: NDArray[np.bool_], adj: list[list[int]], s: ClusterSettings
) -> tuple[NDArray[np.int64], list[int]] | None:
    """The best cluster grown from ``seed``: (object columns, cells), or None when none saves bytes."""
    shared = remaining[seed].copy()
    group = [seed]
    in_group = {seed}
    frontier = set(adj[seed])
    best: tuple[float, NDArray[np.bool_], int] | None = None
    while frontier and len(group) < s.max_cells:
        cand = sorted(frontier)
        kept = remaining[cand] & shared
        counts = kept.sum(axis=1)
        pick = int(np.argmax(counts))
        if counts[pick] < s.min_objects:
            break
        nxt = cand[pick]
        shared = kept[pick]
        group.append(nxt)
        in_group.add(nxt)
        frontier.discard(nxt)
        frontier.update(m for m in adj[nxt] if m not in in_group)
        gain = _gain(int(counts[pick]), len(group), s)
        if gain > 0 and (best is None or gain > best[0]):
            best = (gain, shared.copy(), len(group))
    if best is None:
        return None
    return np.flatnonzero(best[1]), group[: best[2]]
