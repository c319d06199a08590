"""Rebuilt geometry handed from a worker process to the client without copying it twice.

A worker packs a batch's meshes into one byte block (:func:`pack_layout` says where each
array goes; :func:`write_packed` copies them there): into a region of the client's
shared-memory segment (:class:`ShmArena`) when one was reserved for the batch and the
block fits, else into a private buffer sent through the pipe.  The client then makes
every mesh array a read-only numpy *view* of that block (:func:`unpack`): no copy on its
side either way.  A shared region stays reserved while any view of it is alive (a
``weakref.finalize`` on the block's base array gives it back), so the segment's size is
a hard bound on the shared memory the client holds, whatever the cache keeps.

The segment's name is unlinked as soon as every worker has attached (:meth:`ShmArena.unlink`),
so nothing is left in ``/dev/shm`` even when the client is killed; the memory itself goes
when the last mapping does.  The name carries the client's process id
(``walkstream_<pid>_<random>``), so a segment can be told apart from other programs' ones
(the tests look only at their own).
"""

from __future__ import annotations

import contextlib
import os
import secrets
import weakref
from collections.abc import Sequence
from multiprocessing import shared_memory
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.rewrite.geometry import ObjectGeometry
from walkstream.shared.records import Mesh

__all__ = ["ALIGN", "SHM_PREFIX", "ShmArena", "pack_layout", "write_packed", "unpack"]

ALIGN = 64
"""Byte alignment of every array in a block and of every region of the segment."""

SHM_PREFIX = "walkstream_"
"""Start of every segment's name; the creating process's id and ``_`` follow."""

Layout = tuple[list[tuple[Any, ...]], list[tuple[int, int, int, int, int, int]], int]
"""(objects, meshes, total bytes): what :func:`unpack` needs besides the bytes.

An object is ``(id, cpu_s, (mesh index or -1) x 3, triangles x 3, available x 3,
bbox_min, bbox_max, nbytes)``; a mesh is ``(vertices, triangles, positions offset,
normals offset, indices offset, materials offset)``."""


def _up(n: int) -> int:
    return -(-n // ALIGN) * ALIGN


def pack_layout(geoms: Sequence[ObjectGeometry]) -> tuple[Layout, list[Mesh]]:
    """Where each array of ``geoms``' meshes goes in one block (a mesh shared by LODs once).

    Returns the layout and the distinct meshes in block order.
    """
    meshes: list[Mesh] = []
    index: dict[int, int] = {}
    rows: list[tuple[int, int, int, int, int, int]] = []
    objects: list[tuple[Any, ...]] = []
    at = 0
    for g in geoms:
        ks: list[int] = []
        for m in g.meshes:
            if m is None:
                ks.append(-1)
                continue
            k = index.get(id(m))
            if k is None:
                k = index[id(m)] = len(meshes)
                meshes.append(m)
                n, t = len(m.positions), len(m.indices)
                offs = []
                for size in (n * 12, n * 12, t * 12, n):
                    offs.append(at)
                    at += _up(size)
                rows.append((n, t, offs[0], offs[1], offs[2], offs[3]))
            ks.append(k)
        objects.append(
            (g.id, g.cpu_s, tuple(ks), g.triangles.tolist(), g.available.tolist(),
             g.bbox_min.tolist(), g.bbox_max.tolist(), g.nbytes)
        )
    return (objects, rows, at), meshes


def write_packed(dst: NDArray[np.uint8], layout: Layout, meshes: Sequence[Mesh]) -> None:
    """Copy ``meshes``' arrays into ``dst`` (``(layout total,) uint8``) where ``layout`` says."""
    for m, (_, _, p, n, i, t) in zip(meshes, layout[1], strict=True):
        for off, a in ((p, m.positions), (n, m.normals), (i, m.indices), (t, m.materials)):
            b = a.reshape(-1).view(np.uint8)
            dst[off : off + len(b)] = b


def unpack(base: NDArray[np.uint8], layout: Layout) -> list[ObjectGeometry]:
    """The batch's geometry as read-only views of ``base`` (the packed block), in order."""
    meshes = []
    for n, t, p, nrm, i, mat in layout[1]:
        meshes.append(
            Mesh(
                base[p : p + n * 12].view(np.float32).reshape(n, 3),
                base[nrm : nrm + n * 12].view(np.float32).reshape(n, 3),
                base[i : i + t * 12].view(np.uint32).reshape(t, 3),
                base[mat : mat + n],
            )
        )
    out = []
    for oid, cpu_s, ks, tri, avail, lo, hi, nbytes in layout[0]:
        lods = tuple(None if k < 0 else meshes[k] for k in ks)
        out.append(
            ObjectGeometry(
                oid, lods, np.array(tri, np.int64), np.array(avail, bool),  # type: ignore[arg-type]
                np.array(lo), np.array(hi), nbytes, cpu_s,
            )
        )
    return out


class _Segment(shared_memory.SharedMemory):
    # the client's views may outlive the arena: their last one closes the mapping
    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self.close()


def _new_segment(nbytes: int) -> _Segment:
    # a name of our own (the process id, then random), tried again on the rare clash
    for _ in range(8):
        name = f"{SHM_PREFIX}{os.getpid()}_{secrets.token_hex(4)}"
        try:
            return _Segment(name=name, create=True, size=nbytes)
        except FileExistsError:
            continue
    raise FileExistsError(f"no free shared-memory name starting {SHM_PREFIX}{os.getpid()}_")


class ShmArena:
    """The client's bounded shared-memory segment, cut into regions for batches.

    Parameters
    ----------
    nbytes:
        The bound: the segment's size.  0 (or a segment that cannot be made: no
        ``/dev/shm``, no room) leaves the arena unavailable (:attr:`error` says why),
        and every batch comes through the pipe.
    """

    def __init__(self, nbytes: int) -> None:
        self.nbytes = int(nbytes) // ALIGN * ALIGN
        self.error = "bound 0" if self.nbytes <= 0 else ""
        self.shm: _Segment | None = None
        if self.nbytes > 0:
            try:
                self.shm = _new_segment(self.nbytes)
            except (OSError, ValueError) as e:
                self.error = f"shared memory unavailable: {e}"
        # (imported here: a worker process needs the packing, not the draw module)
        from walkstream.client.draw.arena import Ranges

        self._ranges = Ranges(self.nbytes // ALIGN if self.shm is not None else 0)
        self._linked = self.shm is not None
        self.held = 0
        """Bytes of the segment reserved or viewed now."""
        self.peak = 0

    @property
    def name(self) -> str | None:
        """The segment's name while workers may still attach (None: no segment)."""
        return self.shm.name if self.shm is not None and self._linked else None

    def reserve(self, cap: int) -> tuple[int, int]:
        """Reserve a region of at most ``cap`` bytes: ``(offset, size)``; size 0 when full.

        Takes the largest free range when none of ``cap`` is left.
        """
        units = min(cap, self.nbytes) // ALIGN
        if self.shm is None or units <= 0:
            return 0, 0
        start = self._ranges.alloc(units)
        if start is None:
            free = self._ranges._free
            if not free:
                return 0, 0
            units = max(n for _, n in free)
            start = self._ranges.alloc(units)
            assert start is not None
        self.held += units * ALIGN
        self.peak = max(self.peak, self.held)
        return start * ALIGN, units * ALIGN

    def release(self, offset: int, size: int) -> None:
        """Give a region (or the unused tail of one) back."""
        if size > 0:
            self._ranges.release(offset // ALIGN, size // ALIGN)
            self.held -= size

    def view(self, offset: int, size: int, used: int) -> NDArray[np.uint8]:
        """The first ``used`` bytes of a reserved region as the base of a batch's views.

        The tail is given back now; the rest when the returned array and every view of
        it are gone.
        """
        assert self.shm is not None
        keep = _up(used)
        self.release(offset + keep, size - keep)
        base = np.frombuffer(self.shm.buf, np.uint8, count=used, offset=offset)  # type: ignore[arg-type]
        weakref.finalize(base, self.release, offset, keep)
        return base

    def unlink(self) -> None:
        """Remove the segment's name (every worker has attached, or none will)."""
        if self.shm is not None and self._linked:
            self._linked = False
            with contextlib.suppress(FileNotFoundError):
                self.shm.unlink()

    def close(self) -> None:
        """Unlink, and unmap unless views of the segment are still alive (they unmap it last)."""
        self.unlink()
        if self.shm is not None:
            with contextlib.suppress(BufferError):
                self.shm.close()
