"""Anti-aliased colour for the truth renderer: N x N supersampling or GL multisampling.

The truth renderer (:class:`~walkstream.client.truth.render.TruthRenderer`) samples each
pixel once, at its centre.  Where a pixel is about a window's width on a facade, that
point-sampled picture aliases: a moiré of whole dark and light pixels whose local mean is
not the facade's.  An image-based stand-in (an impostor, a facade picture) is a filtered
image, so against a point-sampled truth it is punished for not reproducing the truth's
aliasing.  A :class:`Sampling` other than :data:`POINT` asks the renderer for the colour
of a frame anti-aliased; its key indices and depths stay point-sampled (one sample at the
pixel centre, as before), so every id-based figure is unchanged.

Two ways, each a :class:`SmoothTarget` beside the renderer's own framebuffer:

- **N x N supersampling** (``Sampling(grid=N)``): the frame drawn at N times the width
  and height and each pixel the mean of its N x N samples (a box filter over the pixel).
  Every sample is shaded, so textures drawn over it (impostors, facades) are filtered too.
- **Multisampling** (``Sampling(msaa=S)``): a multisampled framebuffer of S samples a
  pixel, resolved by the GL (``glBlitFramebuffer``): coverage at S positions, the fragment
  shaded once per pixel and primitive.  What a GPU's anti-aliasing does for a picture; the
  truth's surfaces are flat-lit per face, so for geometry it equals S-sample supersampling,
  and a texture is sampled once a pixel as without it.  Mesa's llvmpipe offers 4 samples.

Both average the stored (sRGB-encoded) 8-bit values, as a GL resolve into an 8-bit
framebuffer does.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.errors import InputError, RenderError
from walkstream.shared.gl import Releasable, check_gl_error, create_context, release_objects

__all__ = ["MAX_GRID", "POINT", "Sampling", "SmoothTarget", "parse_sampling", "check_sampling"]

MAX_GRID = 8
"""The largest N of N x N supersampling (64 samples a pixel)."""


@dataclass(frozen=True)
class Sampling:
    """How the truth samples a pixel's colour: ``grid`` x ``grid`` supersampled, or ``msaa`` samples."""

    grid: int = 1
    """N of N x N samples a pixel on a regular grid, averaged (1: one sample, at the centre)."""
    msaa: int = 0
    """Samples a pixel of GL multisampling (0: none); excludes ``grid`` > 1."""

    def __post_init__(self) -> None:
        if not 1 <= int(self.grid) <= MAX_GRID:
            raise InputError(f"Sampling.grid: expected 1 to {MAX_GRID}, got {self.grid}")
        if int(self.msaa) < 0 or int(self.msaa) == 1 or (self.msaa and self.grid > 1):
            raise InputError(f"Sampling: msaa {self.msaa} with grid {self.grid}: expected msaa 0 or >= 2, grid 1 with it")

    @property
    def point(self) -> bool:
        """Whether this is one sample at the pixel centre (no anti-aliasing)."""
        return self.grid == 1 and self.msaa == 0

    @property
    def samples(self) -> int:
        """Samples a pixel (1, N², or the multisample count)."""
        return self.msaa if self.msaa else self.grid * self.grid

    def __str__(self) -> str:
        if self.msaa:
            return f"msaa{self.msaa}"
        return "1" if self.grid == 1 else f"{self.grid}x{self.grid}"


POINT = Sampling()
"""One sample a pixel, at its centre: the truth as it always was."""

_FORM = re.compile(r"^\s*(?:(?P<n>\d+)(?:\s*x\s*(?P<m>\d+))?|msaa\s*(?P<s>\d+))\s*$", re.IGNORECASE)


def parse_sampling(text: str, flag: str = "--truth-samples") -> Sampling:
    """``"1"``, ``"N"`` or ``"NxN"`` (N x N supersampling), ``"msaaS"`` (S-sample multisampling).

    Raises :class:`~walkstream.shared.errors.InputError` naming ``flag`` on anything else.
    """
    m = _FORM.match(str(text))
    if m is None:
        raise InputError(f"{flag} {text!r}: expected N (N x N samples a pixel, 1 to {MAX_GRID}), NxN, or msaaS")
    if m.group("s") is not None:
        s = int(m.group("s"))
        if s < 2:
            raise InputError(f"{flag} {text!r}: multisampling needs at least 2 samples")
        return Sampling(msaa=s)
    n = int(m.group("n"))
    if m.group("m") is not None and int(m.group("m")) != n:
        raise InputError(f"{flag} {text!r}: expected a square grid (NxN)")
    if not 1 <= n <= MAX_GRID:
        raise InputError(f"{flag} {text!r}: expected 1 to {MAX_GRID} samples a side")
    return Sampling(grid=n)


def check_sampling(sampling: Sampling, flag: str = "--truth-samples", ctx: Any = None) -> None:
    """Refuse, before a walk starts, a multisample count this GL does not offer.

    The truth draws its frames after the walk, so without this check a replay would walk
    to its end and only then fail.  Opens a context of its own when ``ctx`` is None
    (only for ``msaaS``: other samplings need nothing of the GL).

    Raises
    ------
    InputError
        ``msaaS`` with S over the GL's ``GL_MAX_SAMPLES``, naming ``flag``.
    RenderError
        No GL context could be opened.
    """
    if not sampling.msaa:
        return
    own = ctx is None
    gl = create_context() if own else ctx
    try:
        most = int(gl.max_samples)
    finally:
        if own:
            gl.release()
    if sampling.msaa > most:
        raise InputError(f"{flag} {sampling}: this GL offers at most {most} samples a pixel")


class SmoothTarget(Releasable):
    """A colour and depth target drawn anti-aliased as ``sampling`` says, resolved to ``size``.

    Parameters
    ----------
    ctx : moderngl.Context
        The renderer's context (not released here).
    size : (int, int)
        The frame's width and height in pixels.
    sampling : Sampling
        Not :data:`POINT`.
    """

    def __init__(self, ctx: Any, size: tuple[int, int], sampling: Sampling) -> None:
        if sampling.point:
            raise InputError("SmoothTarget: expected an anti-aliased sampling, got one sample a pixel")
        self.ctx = ctx
        self.size = (int(size[0]), int(size[1]))
        self.sampling = sampling
        self._gl: list[Any] = []
        w, h = self.size
        try:
            if sampling.msaa:
                most = int(ctx.max_samples)
                if sampling.msaa > most:
                    raise RenderError(f"{sampling}: this GL offers at most {most} samples a pixel")
                s = sampling.msaa
                self._colour = ctx.renderbuffer((w, h), components=4, samples=s)
                self._depth = ctx.depth_renderbuffer((w, h), samples=s)
                self._resolved = ctx.renderbuffer((w, h), components=4)
                self._resolve = ctx.framebuffer(color_attachments=[self._resolved])
                self._gl += [self._resolve, self._resolved]
            else:
                n = sampling.grid
                self._colour = ctx.renderbuffer((w * n, h * n), components=4)
                self._depth = ctx.depth_renderbuffer((w * n, h * n))
            self.fbo = ctx.framebuffer(color_attachments=[self._colour], depth_attachment=self._depth)
            self._gl += [self.fbo, self._colour, self._depth]
            check_gl_error(ctx, f"after creating the truth's {sampling} target")
        except BaseException:
            self.release()
            raise

    def use(self) -> None:
        """Bind the target (and its whole viewport) for drawing."""
        self.fbo.use()

    def clear(self, rgb: tuple[float, float, float]) -> None:
        """Clear to ``rgb`` (0-1) and the far depth, and bind the target."""
        self.fbo.clear(rgb[0], rgb[1], rgb[2], 1.0, depth=1.0)
        self.fbo.use()

    def colour(self) -> NDArray[np.uint8]:
        """``(h, w, 3)`` the frame drawn, anti-aliased and resolved, row 0 at the top."""
        w, h = self.size
        if self.sampling.msaa:
            self.ctx.copy_framebuffer(self._resolve, self.fbo)
            raw = self._resolve.read(components=3, alignment=1)
            return np.frombuffer(raw, np.uint8).reshape(h, w, 3)[::-1].copy()
        n = self.sampling.grid
        raw = self.fbo.read(components=3, alignment=1)
        fine = np.frombuffer(raw, np.uint8).reshape(h, n, w, n, 3)[::-1]
        # integer sums, rounded to nearest: the box filter of each pixel's n x n samples
        total = fine.sum(axis=(1, 3), dtype=np.uint32)
        out: NDArray[np.uint8] = ((total + (n * n) // 2) // (n * n)).astype(np.uint8)
        return out

    def release(self) -> None:
        """Release the target's GL objects (not the context); idempotent."""
        release_objects(self.ctx, self._gl, False)
