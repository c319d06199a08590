"""The dense visibility field's renderer: the bake's ID renderer with two passes in flight.

The field (:mod:`.field`) renders thousands of points in passes of
``points_per_pass`` points, each pass drawn into one framebuffer and read back once.
On a software rasteriser (Mesa llvmpipe) the calling thread issues the draws (vertex
work, binning) and the rasteriser's threads fill the pixels only when the pass is read
back, so the two take turns.  :class:`FieldRenderer` draws each pass into the other of
two framebuffers of the same size and reads the previous pass back only after the
next one is issued: the rasteriser fills one pass while this thread culls and issues
the next.  The points keep their places in the framebuffer (a point's row moves its
vertices by a rounding step), so the counts are those of
:meth:`~.visibility.VisibilityRenderer.each_point_counts` pixel for pixel
(``walkstream bench field`` checks it on every point it renders).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from walkstream.server.bake.visibility import VisibilityRenderer
from walkstream.shared.arrays import F64, I64
from walkstream.shared.gl import Framebuffer, check_gl_error

__all__ = ["FieldRenderer"]


class FieldRenderer(VisibilityRenderer):
    """A :class:`~.visibility.VisibilityRenderer` whose :meth:`field_counts` keeps two passes in flight.

    The same constructor.  With the edge pass on (it reads each pass back twice)
    :meth:`field_counts` is :meth:`~.visibility.VisibilityRenderer.each_point_counts`.
    """

    _fb2: Framebuffer | None = None

    def field_counts(self, points: ArrayLike) -> list[tuple[I64, I64]]:
        """Per sample point, the pixels each object covers in its six cube faces.

        Parameters
        ----------
        points : (p, 3) float
            Sample points (camera centres), scene-local metres.

        Returns
        -------
        list of (ids, pixels)
            As :meth:`~.visibility.VisibilityRenderer.each_point_counts`, the same counts.
        """
        if self.edge_pass or float(getattr(self, "thin_pass", 0)):
            return self.each_point_counts(points)
        pts = self._check_points(points)
        if not (len(pts) and len(self._ids)):
            return [(np.zeros(0, np.int64), np.zeros(0, np.int64)) for _ in pts]
        assert self.ctx is not None and self._fb is not None
        if self._fb2 is None:
            self._fb2 = Framebuffer(self.ctx, self._fb.size, 1, "u4")
        fbs = (self._fb, self._fb2)
        images = (self._pixels, np.empty_like(self._pixels))
        own: list[I64] = []
        pending: tuple[int, int] | None = None
        n = len(self._ids) + 1
        res = self.resolution
        for k, s in enumerate(range(0, len(pts), self.points_per_pass)):
            batch = pts[s : s + self.points_per_pass]
            self._issue(batch, fbs[k % 2])
            if pending is not None:
                own.extend(self._collect(fbs[pending[0]], images[pending[0]], pending[1], n, res))
            pending = (k % 2, len(batch))
        if pending is not None:
            own.extend(self._collect(fbs[pending[0]], images[pending[0]], pending[1], n, res))
        check_gl_error(self.ctx, f"after rendering {len(pts)} field points")
        return [self._ids_pixels(c.astype(np.int64)) for c in own]

    def _issue(self, points: F64, fb: Framebuffer) -> None:
        """Cull and draw one pass into ``fb`` (as the plain pass does), without reading it."""
        import moderngl

        ctx = self.ctx
        assert ctx is not None
        _, commands, offsets, mvps = self._prepare_pass(points)
        self._begin_pass(fb, (0, 0, 6 * self.resolution, len(points) * self.resolution))
        try:
            self._draw_faces(commands, offsets, mvps)
        finally:
            ctx.scissor = None
            if self.cull_back_faces:
                ctx.disable(moderngl.CULL_FACE)

    @staticmethod
    def _collect(fb: Framebuffer, image: np.ndarray, p: int, n: int, res: int) -> list[I64]:
        """Read a pass back and count each point's pixels per object (``(n,)`` each)."""
        rows = image[: p * res]
        fb.fbo.read_into(rows, viewport=(0, 0, 6 * res, p * res), components=1, dtype="u4", alignment=1)
        return [np.bincount(rows[i * res : (i + 1) * res].reshape(-1), minlength=n)[:n] for i in range(p)]

    def release(self) -> None:
        """Release the second framebuffer too; idempotent."""
        if self._fb2 is not None:
            self._fb2.release()
            self._fb2 = None
        super().release()
