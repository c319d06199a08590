"""Headless OpenGL for the bake (ID buffers) and the client renderer.

One way to get a context (:func:`create_context`), one way to check for GL errors
(:func:`check_gl_error`) and an offscreen framebuffer that cleans up after itself
(:class:`Framebuffer`).  Nothing here assumes a particular driver: the same code runs on
Mesa's llvmpipe (no GPU, no display) and on a real GPU through its EGL.

Environment
-----------
``WALKSTREAM_GL_BACKEND``
    Force one moderngl backend instead of trying EGL and then the platform default:
    ``egl``, or ``default`` for the platform's own (GLX/X11 on Linux, WGL, CGL).
    Any other value is passed to moderngl as the backend name.
``GLCONTEXT_DEVICE_INDEX``, ``GLCONTEXT_LINUX_LIBEGL``, ``GLCONTEXT_LINUX_LIBGL``
    Read by glcontext itself: which EGL device (GPU) to use on a multi-GPU machine,
    and explicit library paths.
"""

from __future__ import annotations

import os
import re
from types import TracebackType
from typing import TYPE_CHECKING, Any, Self

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.errors import InputError, RenderError

if TYPE_CHECKING:  # moderngl is imported lazily so that importing this module never fails
    import moderngl

__all__ = [
    "BACKEND_ENV",
    "VERTEX_ID_FRAGMENT_SHADER",
    "Framebuffer",
    "Releasable",
    "release_objects",
    "check_gl_error",
    "create_context",
]

VERTEX_ID_FRAGMENT_SHADER = """
#version 330
flat in uint v_id;
out uint f_id;
void main() {
    f_id = v_id;
}
"""
"""The fragment shader of an object-ID image: writes the id its vertex shader passes
as ``flat out uint v_id`` (the bake's visibility renderer, the client's batched id
pass) into an unsigned-integer colour attachment."""

#: Environment variable that forces a backend (see the module docstring).
BACKEND_ENV = "WALKSTREAM_GL_BACKEND"

_INSTALL_HINT = "install libegl1 libegl-mesa0 libgl1-mesa-dri (Mesa) or a GPU driver with EGL"


def _backends() -> list[str | None]:
    """Backends to try, in order; ``None`` is moderngl's platform default."""
    forced = os.environ.get(BACKEND_ENV, "").strip().lower()
    if forced in ("default", "native", "auto"):
        return [None]
    if forced:
        return [forced]
    # EGL first: it needs no display server, so it works on headless servers and CI
    # (Mesa llvmpipe or a GPU); the default (GLX on Linux) is the fallback for desktops.
    return ["egl", None]


def _explain(failures: list[tuple[str | None, str]], require: int) -> str:
    """One line that says what is missing, from the error text of each attempt."""
    detail = "; ".join(f"{b or 'default'}: {msg}" for b, msg in failures)
    forced = os.environ.get(BACKEND_ENV)
    where = f" ({BACKEND_ENV}={forced})" if forced else ""
    low = detail.lower()
    egl_errors = " ".join(msg for b, msg in failures if b == "egl")
    # glcontext reports a library it cannot dlopen as "<name> not loaded".
    missing = re.search(r"(\S*lib\S+)\s+not loaded", egl_errors, re.IGNORECASE)
    version = f"{require // 100}.{require % 100 // 10}"
    if "requested opengl version" in low:
        what = f"the driver offers an OpenGL older than the {version} core required"
    elif "eglcreatecontext" in low:
        # EGL itself works (display found), but not for this version/profile.
        what = f"EGL works but cannot create an OpenGL {version} core context"
    elif missing and "egl" in missing.group(1).lower():
        what = f"{missing.group(1)} / Mesa EGL not found; {_INSTALL_HINT}"
    elif missing:
        what = f"{missing.group(1)} (OpenGL library used by EGL) not found; {_INSTALL_HINT}"
    elif any(b == "egl" for b, _ in failures):
        what = f"EGL loaded but gave no usable display or device; {_INSTALL_HINT}"
    elif "display" in low:
        what = f"the default backend needs a display server; set {BACKEND_ENV}=egl or unset it"
    else:
        what = "the requested backend could not open a context"
    return f"no OpenGL context{where}: {what} [{detail}]"


def create_context(require: int = 330) -> moderngl.Context:
    """Create a standalone (headless) moderngl context.

    Tries EGL, then the platform default, unless ``WALKSTREAM_GL_BACKEND`` forces
    one.  The caller owns the context and must ``release()`` it.

    Parameters
    ----------
    require : int
        Minimum OpenGL version as ``major * 100 + minor * 10`` (330 = OpenGL 3.3).

    Returns
    -------
    moderngl.Context

    Raises
    ------
    RenderError
        When moderngl is not installed or no backend gives a context of at least
        ``require``; the message is one line naming what is missing.
    """
    try:
        import moderngl
    except ImportError as exc:  # an optional dependency fails only when used
        raise RenderError(f"no OpenGL context: moderngl is not installed ({exc})") from exc

    failures: list[tuple[str | None, str]] = []
    for backend in _backends():
        kwargs: dict[str, Any] = {"require": require}
        if backend is not None:
            kwargs["backend"] = backend
        try:
            return moderngl.create_standalone_context(**kwargs)
        except Exception as exc:  # glcontext raises bare Exception for a missing library
            failures.append((backend, " ".join(str(exc).split()) or type(exc).__name__))
    raise RenderError(_explain(failures, require))


def check_gl_error(ctx: moderngl.Context, where: str) -> None:
    """Raise if OpenGL has recorded an error (reading it also clears it).

    Parameters
    ----------
    ctx : moderngl.Context
    where : str
        What was just done, for the message (e.g. ``"after drawing cell 12"``).

    Raises
    ------
    RenderError
        When ``ctx.error`` is not ``"GL_NO_ERROR"``.
    """
    err = ctx.error
    if err != "GL_NO_ERROR":
        raise RenderError(f"OpenGL error {where}: {err}")


class Releasable:
    """A holder of GL objects: ``release()`` frees them, and ``with`` releases on exit.

    Subclasses define :meth:`release` (safe to call twice).
    """

    def release(self) -> None:  # pragma: no cover - every subclass defines it
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.release()


def release_objects(ctx: Any, objects: list[Any], own_ctx: bool) -> None:
    """Release ``objects`` (GL objects made in ``ctx``), then ``ctx`` itself if ``own_ctx``.

    The default framebuffer is bound first, for the reason :meth:`Framebuffer.release`
    gives.  ``objects`` is emptied, so a second call releases nothing twice.
    """
    if ctx is not None and objects:
        ctx.detect_framebuffer(0).use()
    for obj in objects:
        obj.release()
    objects.clear()
    if own_ctx and ctx is not None:
        ctx.release()


class Framebuffer(Releasable):
    """An offscreen colour + depth framebuffer, released on exit.

    Parameters
    ----------
    ctx : moderngl.Context
    size : (int, int)
        Width and height in pixels.
    components : int
        Colour components (4 = RGBA).
    dtype : str
        moderngl renderbuffer type: ``"f1"`` is 8-bit normalised (RGBA8); the bake
        may use ``"u4"`` for integer object ids.

    Examples
    --------
    >>> with Framebuffer(ctx, (64, 64)) as fb:  # doctest: +SKIP
    ...     fb.use(); fb.clear((0, 0, 0, 1)); vao.render()
    ...     img = fb.read()  # (64, 64, 4) uint8, row 0 at the top
    """

    def __init__(
        self,
        ctx: moderngl.Context,
        size: tuple[int, int],
        components: int = 4,
        dtype: str = "f1",
    ) -> None:
        w, h = (int(v) for v in size)
        if w <= 0 or h <= 0:
            raise InputError(f"Framebuffer.size: expected positive width and height, got {size}")
        self.ctx = ctx
        self.size = (w, h)
        self.components = components
        self.dtype = dtype
        self._color: moderngl.Renderbuffer | None = None
        self._depth: moderngl.Renderbuffer | None = None
        self._fbo: moderngl.Framebuffer | None = None
        try:
            self._color = ctx.renderbuffer(self.size, components=components, dtype=dtype)
            self._depth = ctx.depth_renderbuffer(self.size)
            self._fbo = ctx.framebuffer(
                color_attachments=[self._color], depth_attachment=self._depth
            )
        except Exception as exc:
            self.release()  # do not leak the attachments made before the failure
            raise RenderError(f"cannot create a {w}x{h} framebuffer: {exc}") from exc

    @property
    def fbo(self) -> moderngl.Framebuffer:
        """The moderngl framebuffer (raises once released)."""
        if self._fbo is None:
            raise RenderError("Framebuffer: used after release()")
        return self._fbo

    def use(self) -> None:
        """Bind it for drawing; the viewport becomes the whole framebuffer."""
        self.fbo.use()
        self.ctx.viewport = (0, 0, *self.size)

    def clear(self, color: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)) -> None:
        """Clear colour (components in 0..1) and depth (to the far plane)."""
        self.fbo.clear(*color, depth=1.0)

    def read(self, components: int | None = None) -> NDArray[Any]:
        """Read the colour attachment back.

        Parameters
        ----------
        components : int, optional
            How many components to read (default: all of them).

        Returns
        -------
        (h, w, components) array
            ``uint8`` for ``"f1"``, otherwise the numpy type of ``dtype``; row 0 is the
            top of the image (OpenGL's row 0 is the bottom, hence the flip).
        """
        c = self.components if components is None else components
        w, h = self.size
        np_dtype = np.uint8 if self.dtype == "f1" else np.dtype(self.dtype)
        # alignment=1: rows of 3-component RGB8 images are not 4-byte multiples.
        raw = self.fbo.read(components=c, dtype=self.dtype, alignment=1)
        return np.frombuffer(raw, dtype=np_dtype).reshape(h, w, c)[::-1].copy()

    def read_depth(self) -> NDArray[np.float32]:
        """``(h, w) float32`` the depth buffer (0 at the near plane, 1 at the far plane
        and where nothing was drawn), row 0 the top of the image as :meth:`read`."""
        w, h = self.size
        raw = self.fbo.read(components=1, attachment=-1, dtype="f4", alignment=1)
        return np.frombuffer(raw, dtype=np.float32).reshape(h, w)[::-1].copy()

    def release(self) -> None:
        """Release the GL objects (safe to call twice)."""
        if self._fbo is not None and self.ctx.fbo is self._fbo:
            # moderngl re-binds its "current" framebuffer after creating the next one;
            # if that is a deleted name, GL records GL_INVALID_OPERATION.  Bind the
            # default framebuffer (name 0, owns nothing, always valid) before deleting.
            self.ctx.detect_framebuffer(0).use()
        for name in ("_fbo", "_depth", "_color"):
            obj = getattr(self, name)
            if obj is not None:
                obj.release()
                setattr(self, name, None)

