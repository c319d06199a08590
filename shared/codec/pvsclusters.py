"""Visibility-list clusters: object sets shared by neighbouring cells, stored once.

m-LOMA (Nurminen 2006) stores its visibility lists as clusters of neighbouring cells
that share most of their objects.  Here a *cluster* is a set of object ids that
several adjacent cells all hold in their PVS; a clustered cell record names its
clusters and lists only the rest of its ids.  The ACH cannot be shared: it is each
cell's own coverage of each object, so a clustered record still carries one ACH
value per object of the whole (expanded) list, in ascending id order, exactly as the
delta-coded record does.

cluster record
    ``{id, pvs}``: the cluster's object ids ascending, delta-coded
    (:func:`~walkstream.shared.codec.pack_ints`, like a cell record's ``pvs``).
clustered cell record
    a cell record (``{id, kind, pvs, ach}``, :class:`~walkstream.shared.wire.CellRecord`)
    with ``cl``: its cluster ids ascending, delta-coded; ``pvs`` holds only the ids
    in none of them, and ``ach`` the units of every object of the expanded list
    (the union of the clusters and ``pvs``, ascending).

:func:`expand_list` rebuilds a cell's list from untrusted parts, bounded: a cluster
it does not know, clusters that overlap each other or the rest, more objects than
the limit, or a count that does not match the ACH are a
:class:`~walkstream.shared.errors.CodecError`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import msgpack
import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.codec.bounded import unpack_bounded
from walkstream.shared.codec.ints import pack_ints, unpack_ints
from walkstream.shared.codec.pvs import ACH_UNITS
from walkstream.shared.errors import CodecError

__all__ = [
    "MAX_CLUSTER_OBJECTS",
    "MAX_CELL_CLUSTERS",
    "cluster_to_wire",
    "encode_cluster",
    "decode_cluster",
    "cluster_from_wire",
    "cluster_ids_from_wire",
    "expand_list",
    "clustered_cell_to_wire",
    "clustered_cell_from_wire",
    "decode_clustered_cell",
]

MAX_CLUSTER_OBJECTS = 1 << 22
"""Most objects a cluster, or a cell's expanded list, may hold (a cell record's own limit)."""
MAX_CELL_CLUSTERS = 1 << 16
"""Most clusters one cell record may name."""
_MAX_CLUSTER_BYTES = 8 << 20


def _ascending(values: ArrayLike, what: str, field: str) -> NDArray[np.int64]:
    """``values`` as ``(k,) int64``, checked strictly ascending and non-negative."""
    a = np.asarray(values)
    if a.size == 0:
        return np.zeros(0, np.int64)
    if a.ndim != 1 or a.dtype.kind not in "iu":
        raise CodecError(f"{what}: {field}: expected a 1-d integer array, got {a.dtype} shape {a.shape}")
    a = a.astype(np.int64)
    if a[0] < 0 or (np.diff(a) <= 0).any():
        raise CodecError(f"{what}: {field}: ids must be non-negative and strictly ascending")
    return a


def _deltas(ids: NDArray[np.int64]) -> list[int]:
    return np.diff(ids, prepend=0).tolist() if len(ids) else []


def _cumsum(deltas: list[int], what: str, field: str) -> NDArray[np.int64]:
    """Ids from ``[first, d1, d2, ...]``, checked non-negative, strictly ascending, in range."""
    d = np.asarray(deltas, dtype=np.int64)
    if len(d) == 0:
        return np.zeros(0, np.int64)
    if d[0] < 0 or (d[1:] <= 0).any():
        raise CodecError(f"{what}: {field} are not strictly ascending non-negative ids")
    if int(d.max()) >= 2**62 // len(d):
        raise CodecError(f"{what}: {field}: ids out of range")
    out: NDArray[np.int64] = np.cumsum(d)
    return out


def cluster_to_wire(cid: int, ids: ArrayLike, *, compact: bool = True) -> dict[str, Any]:
    """The cluster record ``{id, pvs}`` as sent (``compact=False``: a plain list, for JSON).

    Parameters
    ----------
    cid:
        The cluster's id (non-negative).
    ids:
        ``(k,)`` its object ids, strictly ascending, ``k >= 1``.
    """
    a = _ascending(ids, "cluster", "pvs")
    if cid < 0 or len(a) == 0:
        raise CodecError(f"cluster {cid}: needs a non-negative id and at least one object")
    return {"id": int(cid), "pvs": pack_ints(_deltas(a), compact=compact)}


def encode_cluster(cid: int, ids: ArrayLike) -> bytes:
    """A cluster record as msgpack bytes (what ``GET .../clusters/{id}`` sends)."""
    data: bytes = msgpack.packb(cluster_to_wire(cid, ids), use_bin_type=True)
    return data


def cluster_from_wire(obj: Any, what: str = "cluster") -> tuple[int, NDArray[np.int64]]:
    """``(id, ids)`` of an unpacked cluster record, checked (``ids`` strictly ascending, non-empty)."""
    if not isinstance(obj, dict):
        raise CodecError(f"{what}: expected a map")
    cid = obj.get("id")
    if type(cid) is not int or cid < 0:
        raise CodecError(f"{what}: id is not a non-negative integer")
    if "pvs" not in obj:
        raise CodecError(f"{what}: missing field 'pvs'")
    ids = _cumsum(unpack_ints(obj["pvs"], what, "pvs", MAX_CLUSTER_OBJECTS), what, "pvs")
    if len(ids) == 0:
        raise CodecError(f"{what}: holds no object")
    ids.flags.writeable = False
    return cid, ids


def decode_cluster(body: bytes | bytearray | memoryview, what: str = "cluster") -> tuple[int, NDArray[np.int64]]:
    """Decode and check a cluster record body (msgpack, bounded)."""
    obj = unpack_bounded(
        body, what, max_bytes=_MAX_CLUSTER_BYTES, max_array_len=MAX_CLUSTER_OBJECTS,
        max_map_len=16, max_bin_len=_MAX_CLUSTER_BYTES,
    )
    return cluster_from_wire(obj, what)


def cluster_ids_from_wire(obj: Any, what: str) -> NDArray[np.int64]:
    """The cluster ids of a cell record's ``cl`` field (absent: none), checked strictly ascending."""
    if obj is None:
        return np.zeros(0, np.int64)
    return _cumsum(unpack_ints(obj, what, "cl", MAX_CELL_CLUSTERS), what, "cl")


def expand_list(
    cluster_ids: Sequence[int] | NDArray[np.int64],
    rest: NDArray[np.int64],
    clusters: Mapping[int, NDArray[np.int64]],
    what: str = "cell",
    max_objects: int = MAX_CLUSTER_OBJECTS,
) -> NDArray[np.int64]:
    """A cell's whole list: the union of its clusters' ids and its own ``rest``, ascending.

    Parameters
    ----------
    cluster_ids:
        ``(m,)`` the clusters the cell names.
    rest:
        ``(r,)`` its ids in no cluster, strictly ascending.
    clusters:
        Cluster id -> ``(k_i,)`` strictly ascending object ids (as decoded).
    max_objects:
        Most objects the expanded list may hold.

    Returns
    -------
    ndarray
        ``(r + sum k_i,) int64`` strictly ascending.

    Raises
    ------
    CodecError
        A named cluster is not in ``clusters``, the list would exceed ``max_objects``,
        or an object is in two parts (clusters overlap each other or the rest).
    """
    parts = [np.asarray(rest, np.int64).reshape(-1)]
    total = len(parts[0])
    for c in cluster_ids:
        ids = clusters.get(int(c))
        if ids is None:
            raise CodecError(f"{what}: names cluster {int(c)}, which is not given")
        total += len(ids)
        if total > max_objects:
            raise CodecError(f"{what}: more than {max_objects} objects with its clusters")
        parts.append(np.asarray(ids, np.int64).reshape(-1))
    if len(parts) == 1:
        return parts[0]
    out = np.sort(np.concatenate(parts), kind="stable")
    if len(out) > 1 and (np.diff(out) == 0).any():
        raise CodecError(f"{what}: an object is in two of its clusters (or a cluster and its own list)")
    return out


def clustered_cell_to_wire(
    record: Mapping[str, Any], cluster_ids: ArrayLike, rest: ArrayLike, *, compact: bool = True
) -> dict[str, Any]:
    """A delta-coded cell record (``CellRecord.to_wire()``) as a clustered one.

    ``pvs`` becomes the ``rest`` and ``cl`` the cluster ids; ``ach`` stays as it is
    (one value per object of the whole list).  A cell naming no cluster keeps its
    record as it is.

    Parameters
    ----------
    record:
        The record as :meth:`walkstream.shared.wire.CellRecord.to_wire` gives it.
    cluster_ids:
        ``(m,)`` the clusters the cell names, strictly ascending.
    rest:
        ``(r,)`` its ids in none of them, strictly ascending.
    """
    cl = _ascending(cluster_ids, f"cell {record.get('id')}", "cl")
    out = dict(record)
    if len(cl) == 0:
        return out
    out["pvs"] = pack_ints(_deltas(_ascending(rest, f"cell {record.get('id')}", "rest")), compact=compact)
    out["cl"] = pack_ints(_deltas(cl), compact=compact)
    return out


def clustered_cell_from_wire(
    obj: Any, clusters: Mapping[int, NDArray[np.int64]], what: str = "cell"
) -> tuple[int, NDArray[np.int64], NDArray[np.int64]]:
    """``(id, ids, units)`` of an unpacked cell record, clustered or not, expanded and checked.

    Parameters
    ----------
    obj:
        The unpacked record (untrusted).
    clusters:
        The clusters it may name (id -> ascending ids, as :func:`decode_cluster` gives).

    Returns
    -------
    id, ids, units
        The cell id, its whole list ``(k,) int64`` ascending and its ACH ``(k,) int64``
        units summing to :data:`~walkstream.shared.codec.pvs.ACH_UNITS` (``k > 0``).

    Raises
    ------
    CodecError
        Not a map, a field missing or mistyped, an unknown or overlapping cluster, or
        ACH values that do not match the expanded list.
    """
    if not isinstance(obj, dict):
        raise CodecError(f"{what}: expected a map")
    cid = obj.get("id")
    if type(cid) is not int or cid < 0:
        raise CodecError(f"{what}: id is not a non-negative integer")
    for key in ("pvs", "ach"):
        if key not in obj:
            raise CodecError(f"{what}: missing field {key!r}")
    rest = _cumsum(unpack_ints(obj["pvs"], what, "pvs", MAX_CLUSTER_OBJECTS), what, "pvs")
    cl = cluster_ids_from_wire(obj.get("cl"), what)
    ids = expand_list(cl, rest, clusters, what)
    units = np.asarray(unpack_ints(obj["ach"], what, "ach", MAX_CLUSTER_OBJECTS), dtype=np.int64)
    if len(units) != len(ids):
        raise CodecError(f"{what}: {len(ids)} objects with its clusters but {len(units)} ach values")
    if len(units) and ((units < 0).any() or (units > ACH_UNITS).any() or int(units.sum()) != ACH_UNITS):
        raise CodecError(f"{what}: ach units must lie in [0, {ACH_UNITS}] and sum to {ACH_UNITS}")
    return cid, ids, units


def decode_clustered_cell(
    body: bytes | bytearray | memoryview, clusters: Mapping[int, NDArray[np.int64]], what: str = "cell"
) -> tuple[int, NDArray[np.int64], NDArray[np.int64]]:
    """Decode (bounded) and expand a cell record body: :func:`clustered_cell_from_wire` of its msgpack."""
    obj = unpack_bounded(
        body, what, max_bytes=_MAX_CLUSTER_BYTES, max_array_len=MAX_CLUSTER_OBJECTS,
        max_map_len=64, max_bin_len=_MAX_CLUSTER_BYTES,
    )
    return clustered_cell_from_wire(obj, clusters, what)
