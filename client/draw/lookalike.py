"""Where a box with its facade pictures looks like the building's LOD2 on the screen.

A facade picture (:mod:`walkstream.client.draw.facades`) is LOD2 drawn flat onto a
plane 2 cm outside the box's wall.  Seen from a viewer it differs from LOD2 itself in
two ways only, both measurable in screen pixels:

- **parallax of the relief**: a point of LOD2 at depth ``δ`` from the face's plane
  (a recessed window, a ledge) is drawn on the plane where the picture's orthographic
  camera saw it.  Seen from ``e``, the real point and the painted one lie
  ``δ |t| f / |v|²`` pixels apart, with ``v`` the ray from the eye to the point,
  ``t`` its part along the plane and ``f`` the focal length in pixels (the shift on
  the plane, ``δ tan θ``, seen at ``cos θ / |v|``).  Zero head-on, largest near and
  at a grazing angle.
- **the texel**: a texel of ``s`` metres covers at most ``s f / |v|`` pixels; at or under
  one pixel the picture adds no blur the frame's own pixels would show.
- **the grazing view**: seen at a grazing angle a facade's windows shrink across the
  view to a fraction of a pixel, and the frame's pixels sample LOD2 (and the picture)
  at points a window's width apart: the two aliasings differ in most pixels, whatever
  the parallax.  A face is taken only when the eye sees its centre within
  ``acos(GRAZING_COS)`` of its normal.

:func:`face_screen_errors` takes the first two over sample points of each face turned
to the eye (a 3 × 3 grid and the face's point nearest the eye) and the third at its
centre; :func:`looks_alike` says whether every face of a building is within
:data:`PARALLAX_PX`, :data:`TEXEL_PX` and :data:`GRAZING_COS`
(:func:`buildings_alike`: many buildings in one pass).  Where they are, the box and its pictures
(two triangles a face turned to the eye, 12 for the box) stand for LOD2's ~1,200
triangles on any device (:mod:`walkstream.client.walk.facades`).  What this does not
see: LOD2's parts beyond the picture's depth range (a roof more than ``BACK_M`` behind
the wall), which the truth comparison's ``lod_colour`` cause measures.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

__all__ = ["GRAZING_COS", "PARALLAX_PX", "TEXEL_PX", "FaceGeometry", "buildings_alike", "face_geometry", "face_screen_errors",
           "facade_screen_error", "looks_alike", "texel_distance"]

PARALLAX_PX = 1.0
"""Largest parallax of a face's relief, in pixels, at which its picture stands for LOD2."""
TEXEL_PX = 1.0
"""Largest screen size of a texel, in pixels, at which a picture stands for LOD2."""
GRAZING_COS = math.cos(math.radians(70.0))
"""Smallest cosine between a face's normal and the ray from its centre to the eye
(70°) at which its picture stands for LOD2 (measured: docs/benchmarks.md)."""

FaceGeometry = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                     NDArray[np.float64], NDArray[np.float64]]
"""A building's faces as arrays: ``origin (n, 3)``, ``right (n, 3)``, ``normal (n, 3)``,
``size (n, 2)`` metres (width, height), ``texel (n,)`` metres a texel covers (the larger
side), ``relief (n,)`` metres of LOD2 in front of or behind the plane (the larger)."""

_GRID = np.array([0.0, 0.5, 1.0])


def face_geometry(images: Sequence[object]) -> FaceGeometry:
    """The arrays of :data:`FaceGeometry` of a building's facade images
    (:class:`~walkstream.client.draw.facades.FacadeImage`: ``face``, ``rgba``, ``relief``)."""
    n = len(images)
    origin, right, normal = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
    size, texel, relief = np.zeros((n, 2)), np.zeros(n), np.zeros(n)
    for k, im in enumerate(images):
        f = im.face  # type: ignore[attr-defined]
        h, w = im.rgba.shape[:2]  # type: ignore[attr-defined]
        origin[k], right[k], normal[k] = f.origin, f.right, f.normal
        size[k] = (f.width, f.height)
        texel[k] = max(f.width / max(w, 1), f.height / max(h, 1))
        relief[k] = float(im.relief)  # type: ignore[attr-defined]
    return origin, right, normal, size, texel, relief


def face_screen_errors(geom: FaceGeometry, eye: NDArray[np.float64],
                       focal_px: float) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``(parallax_px (n,), texel_px (n,), cos (n,))``: per face of ``geom``, the largest
    parallax of its relief and the largest texel on the screen over its sample points,
    and the cosine of the angle between its normal and the ray from its centre to the
    eye (module docstring), seen from ``eye`` ``(3,)``, ``focal_px`` the focal length in
    pixels; 0, 0 and 1 for a face turned away from the eye (it is not drawn)."""
    origin, right, normal, size, texel, relief = geom
    e = np.asarray(eye, np.float64)
    n = len(origin)
    if not n:
        return np.zeros(0), np.zeros(0), np.ones(0)
    up = np.array([0.0, 0.0, 1.0])
    # the face's point nearest the eye, then a 3 x 3 grid: (n, 10, 3)
    rel = e[None, :] - origin
    front = np.einsum("ij,ij->i", rel, normal) > 0.0
    u = np.clip(np.einsum("ij,ij->i", rel, right), 0.0, size[:, 0])
    z = np.clip(rel[:, 2], 0.0, size[:, 1])
    gu, gz = np.meshgrid(_GRID, _GRID, indexing="ij")
    us = np.concatenate([u[:, None], gu.reshape(1, -1) * size[:, :1]], axis=1)
    zs = np.concatenate([z[:, None], gz.reshape(1, -1) * size[:, 1:]], axis=1)
    pts = origin[:, None, :] + us[:, :, None] * right[:, None, :] + zs[:, :, None] * up[None, None, :]
    v = pts - e[None, None, :]
    d2 = np.maximum(np.einsum("ijk,ijk->ij", v, v), 1e-12)
    along = np.einsum("ijk,ik->ij", v, normal)
    tang = np.sqrt(np.maximum(d2 - along * along, 0.0))
    with np.errstate(invalid="ignore"):  # an infinite relief at a nil tangent: inf, not nan
        parallax = np.where(tang > 0.0, relief[:, None] * tang, 0.0) * focal_px / d2
    texel_px = texel[:, None] * focal_px / np.sqrt(d2)
    centre = rel - right * size[:, :1] / 2.0 - up[None, :] * size[:, 1:] / 2.0  # centre to eye
    cos = np.einsum("ij,ij->i", centre, normal) / np.maximum(np.linalg.norm(centre, axis=1), 1e-12)
    return (np.where(front, parallax.max(axis=1), 0.0), np.where(front, texel_px.max(axis=1), 0.0),
            np.where(front, cos, 1.0))


def facade_screen_error(geom: FaceGeometry, eye: NDArray[np.float64],
                        focal_px: float) -> tuple[float, float, float]:
    """``(parallax_px, texel_px, cos)``: the largest parallax and texel and the smallest
    cosine of :func:`face_screen_errors` over the building's faces turned to ``eye``;
    ``(0, 0, 1)`` when none is turned to it."""
    p, t, c = face_screen_errors(geom, eye, focal_px)
    return (float(p.max()), float(t.max()), float(c.min())) if len(p) else (0.0, 0.0, 1.0)


def looks_alike(geom: FaceGeometry, eye: NDArray[np.float64], focal_px: float) -> bool:
    """Whether the box with the pictures of ``geom`` stands for LOD2 seen from ``eye``:
    parallax within :data:`PARALLAX_PX`, texels within :data:`TEXEL_PX`, no face turned
    to the eye more grazing than :data:`GRAZING_COS` (module docstring)."""
    parallax, texel, cos = facade_screen_error(geom, eye, focal_px)
    return parallax <= PARALLAX_PX and texel <= TEXEL_PX and cos >= GRAZING_COS


def buildings_alike(geoms: Sequence[FaceGeometry], eye: NDArray[np.float64], focal_px: float,
                    grazing_cos: float = GRAZING_COS, parallax_px: float = PARALLAX_PX) -> NDArray[np.bool_]:
    """``(m,)`` :func:`looks_alike` of each of ``geoms`` (one building each), in one pass
    over all their faces; ``grazing_cos`` in place of :data:`GRAZING_COS` (0: no limit),
    ``parallax_px`` in place of :data:`PARALLAX_PX`."""
    counts = np.array([len(g[0]) for g in geoms], np.int64)
    if not len(geoms) or not counts.sum():
        return np.ones(len(geoms), bool)
    joined: FaceGeometry = tuple(np.concatenate([g[i] for g in geoms]) for i in range(6))  # type: ignore[assignment]
    p, t, c = face_screen_errors(joined, eye, focal_px)
    ok = (p <= parallax_px) & (t <= TEXEL_PX) & (c >= grazing_cos)
    owner = np.repeat(np.arange(len(geoms)), counts)
    bad = np.bincount(owner[~ok], minlength=len(geoms))
    out: NDArray[np.bool_] = bad == 0
    return out


def texel_distance(texel_m: float, focal_px: float) -> float:
    """Metres beyond which a texel of ``texel_m`` metres is within :data:`TEXEL_PX` on
    the screen: nearer, a picture cannot stand for LOD2 (no use baking it for that)."""
    return float(texel_m) * float(focal_px) / TEXEL_PX
