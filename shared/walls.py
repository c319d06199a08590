"""Textured virtual walls (Ebbesmeyer): zones, their error bound and which texture a viewer sees.

A virtual wall is a vertical quad the bake puts across an open room (a portal of kind
``wall`` between two cells of one space, :mod:`walkstream.server.bake.rooms`).  Each
*side* of it carries textures of what lies behind it, one per **zone**: the strip of
floor in front of the wall whose viewers see that texture.  This module is the pure
part both sides share: the error metric, the zone layout, the zone and weight of a
viewer, and the texture's sampling point.

The error metric (the paper's section 4, derived again).  A texture sampled from
``B`` at distance ``x_s`` from the wall shows a point ``P`` behind it where the ray
``B -> P`` meets the wall, at ``T``.  A viewer ``B'`` sees ``T`` instead of ``P``;
the error is the angle ``P B' T``.  For ``B'`` moved by ``Δb`` along the wall, at
distance ``x`` from it, and ``P`` at depth ``p`` behind the wall straight behind
``B``, ``T`` is ``B``'s foot on the wall and ``P`` lies at lateral offset ``Δb`` and
depth ``x + p`` from ``B'``: the error is
``atan(Δb / x) - atan(Δb / (x + p))``, which grows with ``p`` to ``atan(Δb / x)``
(``P`` far behind; the paper writes it with ``x_P`` the viewer's distance to ``P``
and takes the point next to the wall, ``P_T = 0``, as the worst, but its own
equation (2) shows the error grows with ``x_P``: the worst point is the far one).
Both give the same bound: within ``Δb`` of the sampling line and at least
``x_T = Δb / tan A`` from the wall (the paper's equation (3)) the error stays under
``A``.  So a wall side of length ``L`` seen from ``x_T`` on needs
``n = ceil(L / (2 x_T tan A))`` zones of width ``L / n`` (the paper's equation (4),
``z_G = 2 Δb n_T``, solved for ``n_T``).  The same bound holds vertically: the
texture is sampled at eye height, so a viewer ``Δz`` above or below it at distance
``x`` errs by at most ``atan(|Δz| / x)``, and the texture is used only while that
is under ``A`` (stairs, a gallery: geometry instead).  What the paper leaves out, a
viewer nearer or farther than the sampling point seeing points far to the side, is
not bounded by this metric (a texture sampled from ``x_s`` and seen from ``x`` is
magnified ``x_s / x`` about the viewer's foot: :func:`zone_warp` lays it for the
viewer's distance); :func:`angular_error` computes any case exactly (the tests check
the bound where it holds and measure the rest).

Blend: nearer than ``x_T + blend`` the texture fades out linearly, reaching 0 at
``x_T``; below ``x_T`` the wall is open (the next cell drawn as geometry).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.shared.errors import InputError

__all__ = [
    "DEFAULT_WALL_ERROR_DEG",
    "EYE_HEIGHT",
    "NO_WARP",
    "RING_SIDES",
    "WallSide",
    "WallTable",
    "WallView",
    "WallWarp",
    "angular_error",
    "decode_walls",
    "ring_cell",
    "walls_wire",
    "wall_distance",
    "zone_count",
    "zone_mix",
    "zone_slide",
    "zone_warp",
]

DEFAULT_WALL_ERROR_DEG = 10.0
"""The paper's angle of error (10 degrees: six textures per wall in its laboratory)."""

EYE_HEIGHT = 1.6
"""Height above the floor at which textures are sampled (a walking viewer's eye), metres."""


RING_SIDES = 4
"""Walls per ring around an outdoor cell (:mod:`walkstream.server.bake.ringwalls`):
wall ``k`` (0-3) of cell ``c`` is portal ``4 c + k``, side 0."""


def ring_cell(portal: int) -> int:
    """The outdoor cell whose ring holds wall ``portal``."""
    return int(portal) // RING_SIDES


def zone_count(length: float, x_t: float, alpha: float) -> int:
    """Zones a wall side of ``length`` metres needs so that a viewer at least ``x_t``
    from it errs by under ``alpha`` radians: ``ceil(length / (2 x_t tan alpha))``, at least 1."""
    if not (length > 0 and x_t > 0 and 0 < alpha < math.pi / 2):
        raise InputError(f"zone_count: need length, x_t > 0 and 0 < alpha < 90 deg (got {length}, {x_t}, {alpha})")
    return max(1, math.ceil(length / (2.0 * x_t * math.tan(alpha)) - 1e-9))


def wall_distance(half_width: float, alpha: float) -> float:
    """The least distance from the wall at which a zone ``2 half_width`` wide keeps the
    error under ``alpha`` radians: ``Δb / tan alpha`` (the paper's equation (3))."""
    return half_width / math.tan(alpha)


def angular_error(sample: ArrayLike, viewer: ArrayLike, point: ArrayLike, origin: ArrayLike, normal: ArrayLike) -> float:
    """The angle (radians) between where ``viewer`` sees ``point`` and where it sees the
    texture's picture of it: the ray ``sample -> point`` meets the wall plane (through
    ``origin``, unit ``normal``) at ``T``; the answer is the angle ``point, viewer, T``.

    All arguments are ``(3,)``; ``point`` must lie behind the plane seen from ``sample``.
    """
    s, v, p = (np.asarray(a, np.float64).reshape(3) for a in (sample, viewer, point))
    o, n = np.asarray(origin, np.float64).reshape(3), np.asarray(normal, np.float64).reshape(3)
    ds, dp = float((s - o) @ n), float((p - o) @ n)
    if ds * dp >= 0:
        raise InputError("angular_error: the point must lie behind the wall seen from the sample")
    t = s + (p - s) * (ds / (ds - dp))
    a, b = p - v, t - v
    c = float(a @ b) / (float(np.linalg.norm(a)) * float(np.linalg.norm(b)))
    return math.acos(max(-1.0, min(1.0, c)))


@dataclass(frozen=True)
class WallView:
    """Where a viewer stands for one wall side: its ``zone`` (texture index),
    ``distance`` in front of the wall (negative behind it), and ``weight``, the
    texture's opacity (1: texture only, the cell behind not drawn; 0: geometry only;
    between: the blend zone, both drawn)."""

    zone: int
    distance: float
    weight: float


@dataclass(frozen=True)
class WallSide:
    """One side of a virtual wall with its zones.

    ``portal`` is the wall's portal id and ``side`` 0 for the side cell ``a`` sees, 1
    for cell ``b``'s; ``p0``, ``p1`` ``(2,)`` its ends, ordered so that the hidden
    space lies to the left of ``p0 -> p1`` seen from above (so the viewer, facing
    the wall, has ``p0`` on the left); ``z0``,
    ``z1`` its height range, ``floor`` the floor the eye height is measured from;
    ``x_t`` the distance from which textures are used, ``blend`` the width of the
    blend zone, ``depth`` how far its sampling points stand from the wall, ``alpha``
    the error bound (radians), ``zones`` how many, ``textures`` their ids (``zones``
    of them, or empty before the bake has made them).
    """

    portal: int
    side: int
    p0: tuple[float, float]
    p1: tuple[float, float]
    z0: float
    z1: float
    floor: float
    x_t: float
    blend: float
    depth: float
    alpha: float
    zones: int
    textures: tuple[int, ...] = ()

    @property
    def length(self) -> float:
        """Length along the floor, metres."""
        return math.hypot(self.p1[0] - self.p0[0], self.p1[1] - self.p0[1])

    @property
    def along(self) -> NDArray[np.float64]:
        """``(2,)`` unit vector from ``p0`` to ``p1``."""
        d = np.subtract(self.p1, self.p0).astype(np.float64)
        out: NDArray[np.float64] = d / max(float(np.linalg.norm(d)), 1e-12)
        return out

    @property
    def normal(self) -> NDArray[np.float64]:
        """``(2,)`` unit normal pointing into the hidden space (to the left of ``p0 -> p1``)."""
        u = self.along
        return np.array([-u[1], u[0]])

    def corners(self) -> NDArray[np.float64]:
        """``(4, 3)`` the quad as the viewer sees it: bottom-left, bottom-right, top-right,
        top-left (left is ``p0``)."""
        return np.array([[*self.p0, self.z0], [*self.p1, self.z0], [*self.p1, self.z1], [*self.p0, self.z1]])

    def zone_span(self, k: int) -> tuple[float, float]:
        """Zone ``k``'s range along the wall, metres from ``p0``."""
        w = self.length / self.zones
        return k * w, (k + 1) * w

    def sample_point(self, k: int) -> NDArray[np.float64]:
        """``(3,)`` zone ``k``'s sampling point: its middle along the wall, ``depth`` in
        front of it, at eye height above ``floor``."""
        if not 0 <= k < self.zones:
            raise InputError(f"wall {self.portal}/{self.side}: no zone {k} (it has {self.zones})")
        t = (k + 0.5) * self.length / self.zones
        xy = np.asarray(self.p0, np.float64) + self.along * t - self.normal * self.depth
        return np.array([xy[0], xy[1], self.floor + EYE_HEIGHT])

    def view(self, eye: ArrayLike) -> WallView:
        """The zone, distance and texture weight for a viewer at ``eye`` ``(3,)``.

        The zone is the one whose strip the viewer's foot on the wall line falls in
        (clamped to the wall's ends; a viewer exactly on a border takes the higher
        zone).  The weight is 0 nearer than ``x_t``, or behind the wall, or where the
        eye is too far above or below eye height for the error bound
        (``|dz| > distance tan alpha``); it rises linearly to 1 at ``x_t + blend``.
        """
        e = np.asarray(eye, np.float64).reshape(3)
        rel = e[:2] - np.asarray(self.p0, np.float64)
        t = float(rel @ self.along)
        d = -float(rel @ self.normal)
        w = self.length / self.zones
        zone = min(self.zones - 1, max(0, int(math.floor(t / w)))) if w > 0 else 0
        dz = abs(float(e[2]) - (self.floor + EYE_HEIGHT))
        if d <= self.x_t or dz > d * math.tan(self.alpha):
            return WallView(zone, d, 0.0)
        weight = 1.0 if self.blend <= 0 else min(1.0, (d - self.x_t) / self.blend)
        return WallView(zone, d, weight)

    def to_row(self, compact: bool = False) -> list[float | int]:
        """The side as one flat list (the store's and the wire's form; :meth:`from_row`).

        ``compact`` (the wire's form): textures numbered one after another (as the bake
        numbers them) are given by the first id alone when there are two or more, so
        that ``GET .../walls`` of a hall of 600 sides is a few kB, not 90."""
        tex = list(self.textures)
        if compact and self.zones > 1 and tex == list(range(tex[0], tex[0] + self.zones)):
            tex = tex[:1]
        return [self.portal, self.side, *self.p0, *self.p1, self.z0, self.z1, self.floor, self.x_t, self.blend,
                self.depth, self.alpha, self.zones, *tex]

    @classmethod
    def from_row(cls, row: list[float | int] | tuple[float | int, ...], what: str = "wall") -> WallSide:
        """A side from :meth:`to_row`'s list, full or compact (one texture id for two or
        more zones: ids from it on); :class:`InputError` naming ``what`` when malformed."""
        if len(row) < 14:
            raise InputError(f"{what}: a wall row has at least 14 numbers, got {len(row)}")
        try:
            nums = [float(v) for v in row[:13]]
            zones = int(row[13])
            tex = tuple(int(v) for v in row[14:])
        except (TypeError, ValueError) as exc:
            raise InputError(f"{what}: a wall row holds numbers only ({exc})") from exc
        if zones > 1 and len(tex) == 1:  # compact: the ids numbered on from the first
            if zones > 1 << 16:
                raise InputError(f"{what}: bad wall row ({zones} zones)")
            tex = tuple(range(tex[0], tex[0] + zones))
        if not all(math.isfinite(v) for v in nums) or zones < 1 or (tex and len(tex) != zones):
            raise InputError(f"{what}: bad wall row (zones {zones}, {len(tex)} textures)")
        return cls(int(nums[0]), int(nums[1]), (nums[2], nums[3]), (nums[4], nums[5]), nums[6], nums[7], nums[8],
                   nums[9], nums[10], nums[11], nums[12], zones, tex)


class WallTable:
    """Many wall sides as arrays: :meth:`WallSide.view` for every side and many eyes at once.

    The frame asks every side for its zone and weight at the eye and at a few eyes the
    motion predictor puts ahead (so the textures of the zones the viewer walks into
    are fetched before they are needed); one side at a time that is a Python loop per
    side per eye.  ``views`` gives the same zones and weights as :meth:`WallSide.view`.
    """

    def __init__(self, sides: tuple[WallSide, ...] | list[WallSide]) -> None:
        self.sides = tuple(sides)
        n = len(self.sides)
        self.p0 = np.array([s.p0 for s in self.sides], np.float64).reshape(n, 2)
        self.along = np.array([s.along for s in self.sides], np.float64).reshape(n, 2)
        self.normal = np.array([s.normal for s in self.sides], np.float64).reshape(n, 2)
        self.width = np.array([s.length / s.zones for s in self.sides], np.float64)
        self.zones = np.array([s.zones for s in self.sides], np.int64)
        self.x_t = np.array([s.x_t for s in self.sides], np.float64)
        self.blend = np.array([s.blend for s in self.sides], np.float64)
        self.eye_z = np.array([s.floor + EYE_HEIGHT for s in self.sides], np.float64)
        self.depth = np.array([s.depth for s in self.sides], np.float64)
        self.tan = np.tan(np.array([s.alpha for s in self.sides], np.float64))

    def along_of(self, eyes: ArrayLike) -> NDArray[np.float64]:
        """``(m, n)`` each eye's ``(m, 3)`` foot on each side's wall line, metres from ``p0``."""
        e = np.asarray(eyes, np.float64).reshape(-1, 3)
        out: NDArray[np.float64] = np.einsum("mnk,nk->mn", e[:, None, :2] - self.p0[None], self.along)
        return out

    def views(self, eyes: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
        """Zones ``(m, n)``, distances ``(m, n)`` and weights ``(m, n)`` of the ``n`` sides
        for ``m`` eyes ``(m, 3)`` (each as :meth:`WallSide.view`)."""
        e = np.asarray(eyes, np.float64).reshape(-1, 3)
        rel = e[:, None, :2] - self.p0[None]
        t = np.einsum("mnk,nk->mn", rel, self.along)
        d = -np.einsum("mnk,nk->mn", rel, self.normal)
        w = np.where(self.width > 0, self.width, 1.0)
        zone = np.clip(np.floor(t / w), 0, self.zones - 1).astype(np.int64)
        zone = np.where(self.width > 0, zone, 0)
        dz = np.abs(e[:, None, 2] - self.eye_z[None])
        blend = np.where(self.blend > 0, self.blend, 1.0)
        weight = np.where(self.blend > 0, np.minimum(1.0, (d - self.x_t) / blend), 1.0)
        weight = np.where((d <= self.x_t) | (dz > d * self.tan), 0.0, weight)
        return zone, d, weight


def zone_mix(along: ArrayLike, width: ArrayLike, zones: ArrayLike, band: float) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """The neighbour zone blended in near a zone border, and its share.

    A hard swap of one zone's texture for the next as the viewer crosses the border
    between them changes every pixel of the wall in one frame.  Within ``band / 2``
    zone widths of a border the next zone's texture is blended in, its share rising
    linearly to one half on the border itself, where both zones' textures weigh the
    same from either side: the picture is continuous across the border.  (At the
    border the viewer is within ``Δb`` of both sampling lines, so both textures keep
    the error bound there; ``band / 2`` zone widths inside, the neighbour's errs by
    up to ``(1 + band) Δb / x``, at a share that falls to 0.)

    Parameters
    ----------
    along : (...) float
        The viewer's foot on the wall line, metres from ``p0``.
    width, zones : (...) float, int
        The zones' width and count (broadcast with ``along``).
    band : float
        Width of the blend around each border, in zone widths (0: a hard swap; at most 1).

    Returns
    -------
    neighbour : (...) int64
        The zone blended in (-1: none: away from any border, at the wall's ends, or
        ``band`` 0).
    share : (...) float64
        Its share, 0 to 0.5.
    """
    t = np.asarray(along, np.float64)
    w = np.where(np.asarray(width, np.float64) > 0, width, 1.0)
    n = np.asarray(zones, np.int64)
    u = t / w
    zone = np.clip(np.floor(u), 0, n - 1)
    frac = u - zone  # 0..1 across the viewer's zone
    right = frac >= 0.5
    gap = np.where(right, 1.0 - frac, frac)  # zone widths to the nearer border
    nb = np.where(right, zone + 1, zone - 1).astype(np.int64)
    half = max(float(band), 0.0) / 2.0
    share = 0.5 * np.clip(1.0 - gap / half, 0.0, 1.0) if half > 0 else np.zeros_like(gap)
    ok = (nb >= 0) & (nb < n) & (share > 0) & (u >= 0) & (u <= n)
    return np.where(ok, nb, -1), np.where(ok, share, 0.0)


def zone_slide(along: ArrayLike, zone: ArrayLike, width: ArrayLike, share: float) -> NDArray[np.float64]:
    """How far (metres, towards ``p1``) zone ``zone``'s texture slides along the wall for a
    viewer whose foot on the wall line is ``along``: ``share`` of the viewer's offset from
    the zone's sampling line (its middle).

    A texture sampled from ``B`` shows a point ``P`` at depth ``p`` behind the wall where
    ``B -> P`` meets it; a viewer at the same distance ``x`` from the wall but ``Δ``
    along it sees ``P`` ``Δ p / (x + p)`` farther along (the module's error metric):
    slid by ``share Δ`` the texture is exact for the points at depth ``p = x share /
    (1 - share)`` (at one half: as far behind the wall as the viewer stands before it)
    and errs by at most ``max(share, 1 - share) Δ / x`` on the rest, against ``Δ / x``
    fixed; two neighbour zones' textures slid so agree, for those points, on their
    border, where the viewer is ``w / 2`` from both sampling lines, and the blend
    across it (:func:`zone_mix`) cross-fades pictures that agree there.

    ``along``, ``zone``, ``width`` broadcast; returns their shape (0 where ``zone`` < 0)."""
    t = np.asarray(along, np.float64)
    z = np.asarray(zone, np.int64)
    out: NDArray[np.float64] = np.where(z >= 0, float(share) * (t - (z + 0.5) * np.asarray(width, np.float64)), 0.0)
    return out


WallWarp = tuple[float, float, float]
"""How a wall's texture is laid on its quad: ``(scale, along, up)``, the texture's point
shown at the wall's point ``(s, z)`` (``s`` metres from ``p0``, ``z`` the height) is the
one the texture holds at ``(along + scale s, up + scale z)``; ``(1, 0, 0)`` as baked, and
``(1, -d, 0)`` the texture slid ``d`` metres towards ``p1``."""

NO_WARP: WallWarp = (1.0, 0.0, 0.0)
"""The texture as baked."""


def zone_warp(along: ArrayLike, eye_z: ArrayLike, distance: ArrayLike, zone: ArrayLike, width: ArrayLike,
              depth: ArrayLike, sample_z: ArrayLike, share: float) -> NDArray[np.float64]:
    """``(..., 3)`` the :data:`WallWarp` of zone ``zone``'s texture for a viewer whose foot on
    the wall line is ``along`` (metres from ``p0``), eye at height ``eye_z``, ``distance``
    in front of the wall, the zone's sampling point ``depth`` in front of it at height
    ``sample_z``: exact for what stands ``p = x share / (1 - share)`` behind the wall
    (``x`` the viewer's distance; at one half as far behind the wall as the viewer stands
    before it), as :func:`zone_slide` along the wall.

    :func:`zone_slide` is the case of a viewer as far from the wall as the sampling point.
    A viewer nearer or farther sees a texture sampled from ``x_s`` magnified: a point
    ``P`` far behind the wall, at angle ``θ`` from the wall's normal, is on the texture
    ``x_s tan θ`` from the sampling point's foot, and the viewer at ``x`` sees it at
    ``atan(x_s tan θ / x)``, not ``θ``: at ``x_s / x`` = 1.6 that is 13 degrees off at
    ``θ`` = 38 degrees, whatever the zone's width (the paper's error metric moves the
    viewer along the wall only).  A ring's regions are tens of metres deep, so a viewer
    stands anywhere from ``r`` to ``r`` plus the region's depth from a wall sampled from its
    middle.  From a sampling foot ``F_s`` and the viewer's ``F_v`` (along the wall and at
    eye height), a point at depth ``p`` shows on the texture at ``T_s = F_s + (P - F_s) x_s
    / (x_s + p)`` and the viewer sees it at ``T_v = F_v + (P - F_v) x / (x + p)``; with
    ``R = share = p / (x + p)``, ``T_s = F_s + k (T_v - F_v - (1 - R) (F_s - F_v))`` with
    ``k = x_s / (x_s (1 - R) + x R)``: the same affine map along the wall and up it, so
    the texture is laid on the quad by its corners' texture coordinates alone.

    ``along`` ... ``sample_z`` broadcast; ``share`` from 0 (the texture fixed on the wall)
    to 1 (exact for what is far)."""
    t = np.asarray(along, np.float64)
    x = np.maximum(np.asarray(distance, np.float64), 1e-6)
    xs = np.maximum(np.asarray(depth, np.float64), 1e-6)
    r = float(share)
    b_s = (np.asarray(zone, np.float64) + 0.5) * np.asarray(width, np.float64)
    z_s = np.asarray(sample_z, np.float64)
    k = xs / (xs * (1.0 - r) + x * r)
    out: NDArray[np.float64] = np.stack(np.broadcast_arrays(
        k, b_s - k * (r * t + (1.0 - r) * b_s), z_s - k * (r * np.asarray(eye_z, np.float64) + (1.0 - r) * z_s)),
        axis=-1)
    return out


def walls_wire(rows: list[list[float | int]]) -> dict[str, list[list[float | int]]]:
    """The body of ``GET .../walls`` from the sides' rows (:meth:`WallSide.to_row`):
    ``{"sides": [row, ...]}``, and where rows differ only in their portal (the cells of
    an outdoor region list one ring's walls each, :mod:`walkstream.server.bake.ringwalls`)
    the first alone in ``sides`` and ``"same": [[k, portal, ...], ...]``, the other
    portals of ``sides[k]`` (a city's 2,000 ring walls were 35 kB gzip-compressed, one
    per cell)."""
    first: dict[tuple[float | int, ...], int] = {}
    sides: list[list[float | int]] = []
    same: dict[int, list[float | int]] = {}
    for row in rows:
        key = tuple(row[1:])
        k = first.get(key)
        if k is None:
            first[key] = len(sides)
            sides.append(list(row))
        else:
            same.setdefault(k, [k]).append(row[0])
    out = {"sides": sides}
    if same:
        out["same"] = [same[k] for k in sorted(same)]
    return out


def decode_walls(body: bytes, what: str) -> tuple[WallSide, ...]:
    """The wall sides of ``GET .../walls`` (msgpack ``{"sides": [row, ...]}``, with
    ``"same"`` as :func:`walls_wire` writes it), bounded and checked
    (:class:`~walkstream.shared.errors.CodecError` naming ``what``)."""
    from walkstream.shared.codec.bounded import unpack_bounded
    from walkstream.shared.errors import CodecError

    obj = unpack_bounded(body, what, max_bytes=16 << 20, max_array_len=1 << 20, max_map_len=4, max_bin_len=0)
    if not isinstance(obj, dict) or not isinstance(obj.get("sides"), list):
        raise CodecError(f"{what}: expected a map with a list 'sides'")
    out = []
    for k, row in enumerate(obj["sides"]):
        if not isinstance(row, list):
            raise CodecError(f"{what}: sides[{k}] is not a list")
        try:
            out.append(WallSide.from_row(row, f"{what}: sides[{k}]"))
        except InputError as exc:
            raise CodecError(str(exc)) from None
    same = obj.get("same", [])
    if not isinstance(same, list):
        raise CodecError(f"{what}: 'same' is not a list")
    for g in same:
        if not (isinstance(g, list) and g and all(isinstance(v, int) and not isinstance(v, bool) for v in g)
                and 0 <= g[0] < len(obj["sides"])):
            raise CodecError(f"{what}: bad 'same' entry {str(g)[:40]}")
        base = out[g[0]]
        out += [dataclasses.replace(base, portal=int(v)) for v in g[1:]]
    return tuple(out)
