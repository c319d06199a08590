"""All uploaded meshes in one vertex and one index buffer, drawn with one multi-draw call.

:class:`MeshArena` is the batched path of :class:`~walkstream.client.draw.frames.FrameRenderer`:
instead of one vertex array and one ``glDrawElements`` per object, every mesh gets a
range of one shared vertex buffer and one shared index buffer (indices stay local to
the mesh; the range's first vertex is the draw's ``baseVertex``), and a frame is one
``glMultiDrawElementsIndirect`` over a command buffer built with numpy.  The per-frame
Python is then a gather of the drawn meshes' commands, not a call per object.  The
same buffers serve the object-id pass: each command's ``baseInstance`` picks the
draw's object id from a per-instance attribute, so ids need no uniform per draw.

Ranges are allocated first-fit from free lists; a buffer that is full grows to twice
its size (a GPU-side copy), so uploads never fail for lack of room.
"""

from __future__ import annotations

import moderngl
import numpy as np
from numpy.typing import NDArray

from walkstream.client.draw.meshes import pack_vertices
from walkstream.shared.records import Mesh

__all__ = ["MeshArena", "Ranges"]

_VERTEX_BYTES = 28
_FORMAT = "3f 3f 4f1"


class Ranges:
    """First-fit allocator of ``[start, start + size)`` ranges in ``[0, capacity)``."""

    def __init__(self, capacity: int) -> None:
        self.capacity = int(capacity)
        self._free: list[list[int]] = [[0, self.capacity]] if capacity > 0 else []

    def alloc(self, size: int) -> int | None:
        """Start of a free range of ``size`` units, or None when none is large enough."""
        for k, (start, n) in enumerate(self._free):
            if n >= size:
                if n == size:
                    del self._free[k]
                else:
                    self._free[k] = [start + size, n - size]
                return start
        return None

    def release(self, start: int, size: int) -> None:
        """Give ``[start, start + size)`` back, merging it with free neighbours."""
        free = self._free
        k = 0
        while k < len(free) and free[k][0] < start:
            k += 1
        free.insert(k, [start, size])
        if k + 1 < len(free) and free[k][0] + free[k][1] == free[k + 1][0]:
            free[k][1] += free.pop(k + 1)[1]
        if k > 0 and free[k - 1][0] + free[k - 1][1] == free[k][0]:
            free[k - 1][1] += free.pop(k)[1]

    def grow(self, capacity: int) -> None:
        """Extend the space to ``capacity`` units (the new tail is free)."""
        old, self.capacity = self.capacity, int(capacity)
        self.release(old, self.capacity - old)

    @property
    def free(self) -> int:
        """Free units in all."""
        return sum(n for _, n in self._free)


class MeshArena:
    """Meshes packed into one vertex and one index buffer, drawn by multi-draw.

    Parameters
    ----------
    ctx : moderngl.Context
    program : moderngl.Program
        The colour program (vertex layout ``"3f 3f 4f1"``, as
        :class:`~walkstream.client.draw.meshes.MeshRenderer`'s).
    vertices, indices : int
        Initial capacities (vertices, uint32 indices); both double when full.
    """

    def __init__(
        self,
        ctx: moderngl.Context,
        program: moderngl.Program,
        vertices: int = 1 << 16,
        indices: int = 1 << 18,
    ) -> None:
        self.ctx = ctx
        self._prog = program
        self._vr, self._ir = Ranges(vertices), Ranges(indices)
        self._vbo = ctx.buffer(reserve=vertices * _VERTEX_BYTES)
        self._ibo = ctx.buffer(reserve=indices * 4)
        self._cmd_buf = ctx.buffer(reserve=64 * 20)
        self._id_buf = ctx.buffer(reserve=64 * 4)
        # slot per mesh: (first index, index count, first vertex, vertex count)
        self._slots: dict[int, tuple[Mesh, int, int, int, int]] = {}
        # colour VAOs per program (MeshRenderer has one without fog and one with it)
        self._vaos: dict[int, tuple[moderngl.Program, moderngl.VertexArray]] = {}
        self._id_vao: moderngl.VertexArray | None = None
        self._id_prog: moderngl.Program | None = None
        self._released = False

    def __contains__(self, mesh: Mesh) -> bool:
        return id(mesh) in self._slots

    @property
    def capacity_bytes(self) -> int:
        """Bytes of the two shared buffers (used or free)."""
        return int(self._vbo.size + self._ibo.size)

    def add(self, mesh: Mesh) -> None:
        """Copy ``mesh`` into the shared buffers (no-op when there or without triangles)."""
        if id(mesh) in self._slots or mesh.triangles == 0:
            return
        verts = pack_vertices(mesh)
        idx = np.ascontiguousarray(mesh.indices, dtype="<u4").reshape(-1)
        v0 = self._alloc(self._vr, len(verts), "v")
        i0 = self._alloc(self._ir, len(idx), "i")
        self._vbo.write(verts.tobytes(), offset=v0 * _VERTEX_BYTES)
        self._ibo.write(idx.tobytes(), offset=i0 * 4)
        self._slots[id(mesh)] = (mesh, i0, len(idx), v0, len(verts))

    def remove(self, mesh: Mesh) -> None:
        """Free the ranges of ``mesh`` (no-op when it is not here)."""
        slot = self._slots.pop(id(mesh), None)
        if slot is not None:
            _, i0, ni, v0, nv = slot
            self._ir.release(i0, ni)
            self._vr.release(v0, nv)

    def _alloc(self, ranges: Ranges, n: int, which: str) -> int:
        start = ranges.alloc(n)
        while start is None:
            self._grow(which, max(2 * ranges.capacity, ranges.capacity + n))
            start = ranges.alloc(n)
        return start

    def _grow(self, which: str, capacity: int) -> None:
        unit = _VERTEX_BYTES if which == "v" else 4
        old = self._vbo if which == "v" else self._ibo
        new = self.ctx.buffer(reserve=capacity * unit)
        self.ctx.copy_buffer(new, old, old.size)
        old.release()
        if which == "v":
            self._vbo = new
            self._vr.grow(capacity)
        else:
            self._ibo = new
            self._ir.grow(capacity)
        self._release_vaos()

    def _release_vaos(self) -> None:
        for _, vao in self._vaos.values():
            vao.release()
        self._vaos.clear()
        if self._id_vao is not None:
            self._id_vao.release()
        self._id_vao = None

    def _commands(self, meshes: list[Mesh]) -> NDArray[np.uint32]:
        """``(n, 5)`` indirect commands (count, 1, first index, base vertex, k)."""
        slots = [s for s in (self._slots.get(id(m)) for m in meshes) if s is not None]
        cmd = np.zeros((len(slots), 5), dtype="<u4")
        if slots:
            cmd[:, [2, 0, 3]] = np.array([s[1:4] for s in slots], dtype=np.int64)
            cmd[:, 1] = 1
            cmd[:, 4] = np.arange(len(slots))
        return cmd

    def _write_commands(self, cmd: NDArray[np.uint32]) -> None:
        data = cmd.tobytes()
        if len(data) > self._cmd_buf.size:
            self._cmd_buf.release()
            self._cmd_buf = self.ctx.buffer(reserve=2 * len(data))
        self._cmd_buf.write(data)

    def draw(self, meshes: list[Mesh], program: moderngl.Program | None = None) -> None:
        """Issue one multi-draw of ``meshes`` (the ones here, in this order).

        ``program`` reads the vertex layout ``"3f 3f 4f1"`` (default: the one given at
        construction; :attr:`MeshRenderer.program
        <walkstream.client.draw.meshes.MeshRenderer.program>` changes with the fog).
        The caller has bound the framebuffer and set the uniforms and state
        (:meth:`~walkstream.client.draw.meshes.MeshRenderer.begin`).
        """
        cmd = self._commands(meshes)
        if not len(cmd):
            return
        prog = self._prog if program is None else program
        entry = self._vaos.get(id(prog))
        if entry is None or entry[0] is not prog:
            if entry is not None:
                entry[1].release()
            vao = self.ctx.vertex_array(
                prog,
                [(self._vbo, _FORMAT, "in_position", "in_normal", "in_color")],
                index_buffer=self._ibo,
                index_element_size=4,
            )
            entry = self._vaos[id(prog)] = (prog, vao)
        self._write_commands(cmd)
        entry[1].render_indirect(self._cmd_buf, moderngl.TRIANGLES, count=len(cmd))

    def draw_ids(
        self, meshes: list[Mesh], ids: NDArray[np.uint32], program: moderngl.Program
    ) -> None:
        """One multi-draw of ``meshes`` in the given order, mesh ``k`` writing ``ids[k]``.

        ``program`` reads ``in_position`` and the per-instance ``uint in_id``.  Meshes
        that are not here are skipped together with their ids.
        """
        keep = [k for k, m in enumerate(meshes) if id(m) in self._slots]
        if not keep:
            return
        cmd = self._commands([meshes[k] for k in keep])
        data = np.ascontiguousarray(np.asarray(ids, dtype="<u4")[keep]).tobytes()
        if len(data) > self._id_buf.size or self._id_prog is not program:
            if self._id_vao is not None:
                self._id_vao.release()
                self._id_vao = None
            if len(data) > self._id_buf.size:
                self._id_buf.release()
                self._id_buf = self.ctx.buffer(reserve=2 * len(data))
        self._id_buf.write(data)
        if self._id_vao is None:
            self._id_prog = program
            self._id_vao = self.ctx.vertex_array(
                program,
                [
                    (self._vbo, f"3f {_VERTEX_BYTES - 12}x", "in_position"),
                    (self._id_buf, "1u /i", "in_id"),
                ],
                index_buffer=self._ibo,
                index_element_size=4,
            )
        self._write_commands(cmd)
        self._id_vao.render_indirect(self._cmd_buf, moderngl.TRIANGLES, count=len(cmd))

    def release(self) -> None:
        """Release every GL object; idempotent."""
        if self._released:
            return
        self._released = True
        self._release_vaos()
        for b in (self._vbo, self._ibo, self._cmd_buf, self._id_buf):
            b.release()
        self._slots.clear()
