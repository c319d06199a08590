"""Camera matrices (pure numpy) for the client renderer and the visibility bake.

Conventions, the same as OpenGL's fixed pipeline had:

* Matrices are ``(4, 4)`` and act on column vectors: ``p_clip = proj @ view @ p``.
  GLSL expects column-major storage, so upload ``m.T`` (:func:`mat4_bytes` does it).
* The world is z-up (x east, y north).  View space is right-handed with the camera
  looking down ``-z`` and ``+y`` up on screen.
* :func:`perspective` maps view depth ``-near`` to NDC ``z = -1`` and ``-far`` to
  ``z = +1``.

The maths runs in float64 (eye positions may be hundreds of metres from the
scene-local origin) and only the results are float32, as they go to the GPU as such.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.arrays import F32
from walkstream.shared.errors import InputError

__all__ = [
    "MAX_PITCH_DEG",
    "camera",
    "CUBE_FACE_DIRECTIONS",
    "CUBE_FACE_NAMES",
    "CUBE_FACE_UPS",
    "cube_face_views",
    "fit_view",
    "frustum_projection",
    "look_at",
    "mat4_bytes",
    "off_axis",
    "orthographic",
    "perspective",
    "view_matrix",
]


#: The six 90-degree cube-face view directions, ``(6, 3) float64``, in the order of
#: :data:`CUBE_FACE_NAMES`.
CUBE_FACE_DIRECTIONS: NDArray[np.float64] = np.array(
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float64
)
CUBE_FACE_DIRECTIONS.flags.writeable = False

#: Screen-up vector of each cube face, ``(6, 3) float64``: world up (+z) for the four
#: horizontal faces; the up and down faces cannot use +z (it is their view axis), so
#: they take +y (north at the top of the image).
CUBE_FACE_UPS: NDArray[np.float64] = np.array(
    [[0, 0, 1], [0, 0, 1], [0, 0, 1], [0, 0, 1], [0, 1, 0], [0, 1, 0]], dtype=np.float64
)
CUBE_FACE_UPS.flags.writeable = False

#: Names of the cube faces, in order.
CUBE_FACE_NAMES: tuple[str, ...] = ("+x", "-x", "+y", "-y", "+z", "-z")


def _vec3(v: ArrayLike, name: str) -> NDArray[np.float64]:
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise InputError(f"{name}: expected 3 finite numbers, got {v!r}")
    return a


def perspective(fovy_deg: float, aspect: float, near: float, far: float) -> F32:
    """OpenGL perspective projection (like ``gluPerspective``).

    Parameters
    ----------
    fovy_deg : float
        Vertical field of view in degrees, in (0, 180).
    aspect : float
        Width over height of the viewport (> 0).
    near, far : float
        Distances of the clip planes, ``0 < near < far``.

    Returns
    -------
    (4, 4) float32
        Maps view-space depth ``-near`` to NDC ``z = -1`` and ``-far`` to ``+1``.
    """
    if not 0.0 < fovy_deg < 180.0:
        raise InputError(f"perspective: fovy_deg must be in (0, 180), got {fovy_deg}")
    if not aspect > 0.0:
        raise InputError(f"perspective: aspect must be > 0, got {aspect}")
    if not 0.0 < near < far or not math.isfinite(far):
        raise InputError(f"perspective: expected 0 < near < far < inf, got near={near}, far={far}")
    f = 1.0 / math.tan(math.radians(fovy_deg) / 2.0)
    return frustum_projection(f / aspect, f, near, far).astype(np.float32)


def frustum_projection(scale_x: float, scale_y: float, near: float, far: float) -> NDArray[np.float64]:
    """The symmetric perspective projection ``(4, 4)`` float64 that scales x and y by
    ``scale_x`` and ``scale_y`` (the cotangents of the half-angles across and up), with
    the clip planes at ``near`` and ``far`` (``0 < near < far``; not checked:
    :func:`perspective` checks a user's values).
    :func:`perspective` is this one in float32; a widened view (the culling cache's guard,
    :mod:`walkstream.shared.cullcache`) takes it in float64."""
    n, fa = float(near), float(far)
    m = np.zeros((4, 4), np.float64)
    m[0, 0] = scale_x
    m[1, 1] = scale_y
    m[2, 2] = (fa + n) / (n - fa)
    m[2, 3] = 2.0 * fa * n / (n - fa)
    m[3, 2] = -1.0
    return m


def view_matrix(rot: NDArray[np.float64], eye: NDArray[np.float64]) -> NDArray[np.float64]:
    """The view matrix ``(4, 4)`` float64 of the camera at ``eye`` ``(3,)`` whose rows of
    ``rot`` ``(3, 3)`` are its right, up and backward axes in world coordinates."""
    m = np.eye(4, dtype=np.float64)
    m[:3, :3] = rot
    m[:3, 3] = -(m[:3, :3] @ eye)
    return m


def orthographic(radius: float, near: float, far: float) -> NDArray[np.float64]:
    """OpenGL orthographic projection of a square ``2 radius`` across, centred on the
    view axis (the impostor images' camera).

    Returns
    -------
    (4, 4) float64
        Maps view-space depth ``-near`` to NDC ``z = -1`` and ``-far`` to ``+1``.
    """
    m = np.zeros((4, 4))
    m[0, 0] = m[1, 1] = 1.0 / radius
    m[2, 2] = -2.0 / (far - near)
    m[2, 3] = -(far + near) / (far - near)
    m[3, 3] = 1.0
    return m


def off_axis(
    eye: ArrayLike,
    corner: ArrayLike,
    right: ArrayLike,
    up: ArrayLike,
    width: float,
    height: float,
    near: float | None = None,
    far: float = 2000.0,
) -> NDArray[np.float64]:
    """``(4, 4)`` view-projection from ``eye`` through a rectangle: an **off-axis
    perspective** whose image is exactly the rectangle, as the eye sees it.

    The rectangle has its bottom-left at ``corner`` and spans ``width`` along the unit
    ``right`` and ``height`` along the unit ``up`` (perpendicular to ``right``); its
    plane's normal ``right x up`` points towards the eye.  The rectangle fills the
    image (``corner`` at the bottom-left, row 0 of an image read top-down at ``up``'s
    end), so a texture on a quad with those corners puts every texel where the eye saw
    it.  The virtual walls' textures and the perspective impostor images both use it.

    Parameters
    ----------
    eye, corner, right, up : (3,) array_like
        World positions and unit vectors (``up`` need not be the world's z).
    width, height : float
        The rectangle's sides, metres.
    near : float or None
        Distance of the near clip plane from the eye along the plane's normal; None:
        the rectangle's own plane (what lies in front of it is clipped, as a wall
        wants).  An impostor passes the front of the object's bounding sphere.
    far : float
        Distance of the far clip plane.

    Returns
    -------
    (4, 4) float64
        ``proj @ view``; view depth ``-near`` maps to NDC ``z = -1``, ``-far`` to ``+1``.
    """
    e = np.asarray(eye, np.float64).reshape(3)
    u = np.asarray(right, np.float64).reshape(3)
    v = np.asarray(up, np.float64).reshape(3)
    n = np.cross(u, v)
    p0 = np.asarray(corner, np.float64).reshape(3)
    plane = float((e - p0) @ n)  # the eye's distance to the rectangle's plane
    clip = plane if near is None else float(near)
    if not 0.0 < clip < far or plane <= 0.0:
        raise InputError(f"off_axis: expected the eye in front of the rectangle and 0 < near < far, "
                         f"got plane {plane:g}, near {clip:g}, far {far:g}")
    k = clip / plane  # the rectangle scaled onto the near plane
    left = float((p0 - e) @ u) * k
    right_ = left + width * k
    bottom = float((p0 - e) @ v) * k
    top = bottom + height * k
    view = view_matrix(np.stack([u, v, n]), e)
    proj = np.zeros((4, 4))
    proj[0, 0] = 2 * clip / (right_ - left)
    proj[0, 2] = (right_ + left) / (right_ - left)
    proj[1, 1] = 2 * clip / (top - bottom)
    proj[1, 2] = (top + bottom) / (top - bottom)
    proj[2, 2] = -(far + clip) / (far - clip)
    proj[2, 3] = -2 * far * clip / (far - clip)
    proj[3, 2] = -1.0
    out: NDArray[np.float64] = proj @ view
    return out


def _look_at64(
    eye: NDArray[np.float64], target: NDArray[np.float64], up: NDArray[np.float64]
) -> NDArray[np.float64]:
    fwd = target - eye
    dist = np.linalg.norm(fwd)
    if not dist > 0.0:
        raise InputError(f"look_at: eye and target coincide at {eye.tolist()}")
    fwd = fwd / dist
    side = np.cross(fwd, up)
    sn = np.linalg.norm(side)
    # A relative threshold: up nearly parallel to the view axis gives an unstable roll.
    if not sn > 1e-9 * max(float(np.linalg.norm(up)), 1e-300):
        raise InputError(
            f"look_at: up {up.tolist()} is parallel to the view direction {fwd.tolist()}"
        )
    side = side / sn
    true_up = np.cross(side, fwd)
    return view_matrix(np.stack([side, true_up, -fwd]), eye)


def look_at(eye: ArrayLike, target: ArrayLike, up: ArrayLike = (0.0, 0.0, 1.0)) -> F32:
    """View matrix of a camera at ``eye`` looking at ``target`` (like ``gluLookAt``).

    Parameters
    ----------
    eye, target : (3,) float
        Camera position and the point it looks at, scene-local metres.
    up : (3,) float
        Approximate screen-up direction; must not be parallel to ``target - eye``.

    Returns
    -------
    (4, 4) float32
        Rigid transform to view space: ``eye`` goes to the origin and ``target`` onto
        the negative z axis.

    Raises
    ------
    ValueError
        When ``eye == target`` or ``up`` is parallel to the view direction.
    """
    return _look_at64(_vec3(eye, "eye"), _vec3(target, "target"), _vec3(up, "up")).astype(
        np.float32
    )


def cube_face_views(eye: ArrayLike) -> F32:
    """The six 90-degree cube-face view matrices at a point.

    Used with ``perspective(90.0, 1.0, near, far)`` the six frusta tile the whole
    sphere of directions around ``eye`` without gaps (they share their edges).

    Parameters
    ----------
    eye : (3,) float
        The sample point, scene-local metres.

    Returns
    -------
    (6, 4, 4) float32
        One view matrix per face, looking along :data:`CUBE_FACE_DIRECTIONS` with the
        screen-up of :data:`CUBE_FACE_UPS` (order of :data:`CUBE_FACE_NAMES`).
    """
    e = _vec3(eye, "eye")
    out = np.empty((6, 4, 4), np.float32)
    for k in range(6):
        out[k] = _look_at64(e, e + CUBE_FACE_DIRECTIONS[k], CUBE_FACE_UPS[k])
    return out


def fit_view(
    bounds_min: ArrayLike,
    bounds_max: ArrayLike,
    direction: ArrayLike,
    fovy_deg: float,
    aspect: float,
    margin: float = 1.08,
    up: ArrayLike = (0.0, 0.0, 1.0),
) -> tuple[F32, F32]:
    """Frame an axis-aligned box from a given direction.

    The camera looks at the box centre from ``direction`` (pointing from the box to
    the eye) and backs off just far enough for all eight corners to fit in the view
    with ``margin`` to spare; near and far hug the box.

    Parameters
    ----------
    bounds_min, bounds_max : (3,) float
        Opposite corners of the box (a flat or empty-size box is fine).
    direction : (3,) float
        From the box centre towards the eye (need not be unit length).
    fovy_deg, aspect : float
        As for :func:`perspective`.
    margin : float
        Scale (>= 1) of the box's extent on screen; 1 touches the image border.
    up : (3,) float
        Screen-up direction.

    Returns
    -------
    view, proj : (4, 4) float32, (4, 4) float32
    """
    lo, hi = _vec3(bounds_min, "bounds_min"), _vec3(bounds_max, "bounds_max")
    d = _vec3(direction, "direction")
    if not np.linalg.norm(d) > 0.0:
        raise InputError("fit_view: direction must not be zero")
    d = d / np.linalg.norm(d)
    centre = (lo + hi) / 2.0
    # Floor the size so a single point or a degenerate box still gets a usable camera.
    size = max(float(np.linalg.norm(hi - lo)), 1e-3)
    rot = _look_at64(centre + d, centre, _vec3(up, "up"))[:3, :3]
    corners = np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )
    local = (corners - centre) @ rot.T  # corner offsets in camera axes (x right, y up, -z fwd)
    tan_y = math.tan(math.radians(fovy_deg) / 2.0) / margin
    tan_x = tan_y * aspect
    # A corner at view offset (x, y, z) relative to the centre has depth dist - z when
    # the eye is at distance dist; it fits when |x| <= tan_x * (dist - z) and likewise y.
    dist = float(
        np.max(
            np.maximum(
                local[:, 2] + np.abs(local[:, 0]) / tan_x, local[:, 2] + np.abs(local[:, 1]) / tan_y
            )
        )
    )
    dist = max(dist, size * 0.5, 1e-3)
    depths = dist - local[:, 2]
    near = max(float(depths.min()) * 0.9, dist * 1e-3)
    far = max(float(depths.max()) * 1.1, near * 2.0)
    view = _look_at64(centre + d * dist, centre, _vec3(up, "up")).astype(np.float32)
    return view, perspective(fovy_deg, aspect, near, far)


def mat4_bytes(m: ArrayLike) -> bytes:
    """Column-major float32 bytes of a ``(4, 4)`` matrix, as a GLSL ``mat4`` uniform wants."""
    a = np.asarray(m, dtype=np.float32)
    if a.shape != (4, 4):
        raise InputError(f"mat4_bytes: expected a (4, 4) matrix, got shape {a.shape}")
    return np.ascontiguousarray(a.T).tobytes()


#: :func:`camera` clamps the pitch to this many degrees up or down: straight up or
#: down the z-up look-at has no defined screen-up.
MAX_PITCH_DEG = 89.0


def camera(eye: ArrayLike, yaw: float, pitch: float = 0.0) -> NDArray[np.float32]:
    """View matrix of a walker's camera.

    Parameters
    ----------
    eye : (3,) float
        Eye position, scene-local metres (z up).
    yaw : float
        Heading in radians, 0 looking east (+x), counter-clockwise (pi/2 looks north).
    pitch : float
        Radians above the horizon (negative looks down); clamped to
        :data:`MAX_PITCH_DEG`.

    Returns
    -------
    (4, 4) float32
        As :func:`look_at` with world up +z.
    """
    e = np.asarray(eye, dtype=np.float64).reshape(-1)
    y, p = float(yaw), float(pitch)
    if e.shape != (3,) or not np.all(np.isfinite(e)) or not math.isfinite(y + p):
        raise InputError(
            f"camera: expected a finite eye (3,) and angles, got {eye!r}, {yaw}, {pitch}"
        )
    lim = math.radians(MAX_PITCH_DEG)
    p = min(max(p, -lim), lim)
    fwd = np.array([math.cos(p) * math.cos(y), math.cos(p) * math.sin(y), math.sin(p)])
    return look_at(e, e + fwd, (0.0, 0.0, 1.0))
