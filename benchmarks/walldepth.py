"""Wall textures with a coarse depth grid against the single-depth warp, offline
(``python -m walkstream.benchmarks.walldepth DB SOURCE REPORT``).

A virtual wall's texture is the render from its zone's sampling point; the client lays
it for the viewer's distance and offset by one affine map (:func:`~walkstream.shared.walls.zone_warp`),
exact only for what stands at one depth behind the wall.  A **textured depth mesh**
(Sillion, Drettakis and Bodelet 1997; Decoret et al. 1999) stores a coarse grid of
depths with the texture and draws it as a mesh displaced to those depths: each vertex
goes back to where the sampling point saw it, and the viewer's own projection puts it
on the wall.  This measures, on a replay's compared frames, how much of each wall the
viewer sees visibly wrong either way, with no byte, bake or client change:

1. each compared frame's eye from the walk (the report's ``truth.csv`` times, less the
   walk's start, found as the offset that puts the eye in the frame's logged cell);
2. each ring wall of the eye's cell it faces (the view direction within 72.5 degrees of
   the wall's normal) and weighs: the **truth**, what the eye sees through the wall's
   quad (:meth:`~walkstream.server.bake.wallrender.WallRenderer.render` with ``eye``), and
   the zone's texture with its depth (:meth:`~.WallRenderer.depth_behind`) rendered
   again (no lossy codec, no crossing objects left out: the same for every method);
3. the methods, each giving a picture of the wall at the texture's resolution: the
   texture laid by ``zone_warp`` (the client today, share 0.5); a ``G`` x ``G`` depth
   mesh (``G`` = 4, 8, 16) with each vertex's depth the **mean** (in the inverse depth
   ``x_s / (x_s + p)``, so far content does not swamp it) or the **nearest** of what the
   texture shows within half a cell of it, drawn from the eye with the texture; and, as
   a bound, the texture rendered from the viewer's own distance and slid by half its
   offset (as if every viewer had its own zone row);
4. a wall texel is **wrong** where a channel differs from the truth by more than 24 of
   255, weighed by the solid angle the eye sees it under, inside a cone of 37.6 degrees
   about the view direction (the frame, roughly); per wall view the wrong share, and for
   a mesh its **holes** (the share no triangle covers: the mesh's edges pulled inside the
   quad) and its **rubber** (the share under triangles whose corners' distances from the
   sampling point differ by more than a quarter: stretched across a depth step, where a
   disocclusion shows).

Prints a table: per method the mean, median and 90th percentile of the wall views'
wrong shares, and the meshes' holes and rubber.
"""

from __future__ import annotations

import argparse
import csv
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.walldepth import DEPTH_CAP, grid_reduce

_GRIDS = (4, 8, 16)
_VISIBLE = 24
"""A channel difference (of 255) above which a texel counts as visibly wrong."""
_CONE = np.radians(37.6)
_RUBBER = 1.25

_VERTEX = """
#version 330
uniform mat4 u_view_proj;
uniform mat4 u_tex_proj;
in vec3 in_position;
in float in_flag;
out vec4 v_tc;
out float v_flag;
void main() {
    gl_Position = u_view_proj * vec4(in_position, 1.0);
    // projective texturing from the sampling point: a point on a triangle whose
    // corners lie at different depths shows the texel the sampling point saw it through
    v_tc = u_tex_proj * vec4(in_position, 1.0);
    v_flag = in_flag;
}
"""
_FRAGMENT = """
#version 330
uniform sampler2D u_tex;
uniform float u_mask;
in vec4 v_tc;
in float v_flag;
out vec4 f_color;
void main() {
    f_color = u_mask > 0.5 ? vec4(1.0, v_flag, 0.0, 1.0) : texture(u_tex, v_tc.xy / v_tc.w * 0.5 + 0.5);
}
"""


def vertex_depths(inv: NDArray[np.float64], grid: int, how: str) -> NDArray[np.float64]:
    """``(grid + 1, grid + 1)`` inverse depths ``x_s / (x_s + p)`` at a ``grid`` x ``grid``
    mesh's vertices (row 0 at the top) from the per-sample ``inv`` ``(h, w)``: the mean
    (``how`` "mean") or the largest, the nearest (``how`` "nearest", what the bake
    stores), within half a cell of each vertex."""
    return grid_reduce(inv, grid, np.mean if how == "mean" else np.max)


def quantised(inv_v: NDArray[np.float64], bits: int, floor: float) -> NDArray[np.float64]:
    """``inv_v`` as stored in ``bits`` bits a vertex (0: as it is), no smaller than ``floor``."""
    if bits <= 0:
        return inv_v
    levels = (1 << bits) - 1
    out: NDArray[np.float64] = np.maximum(np.round(inv_v * levels) / levels, floor)
    return out


def grid_bytes(inv_v: NDArray[np.float64], bits: int) -> int:
    """Bytes of a vertex grid stored at ``bits`` (8 when 0) a vertex, deflated (row
    differences, as PNG's filter does, then zlib at level 9)."""
    import zlib

    levels = (1 << (bits or 8)) - 1
    q = np.round(inv_v * levels).astype(np.int64)
    diff = np.diff(q, axis=1, prepend=0) % (levels + 1)
    raw = diff.astype(np.uint8 if levels < 256 else np.uint16).tobytes()
    return len(zlib.compress(raw, 9))


def merged_triangles(inv_v: NDArray[np.float64]) -> int:
    """Triangles of the mesh of vertex grid ``inv_v`` with each row's runs of cells whose
    four corners share one depth (a plane parallel to the wall: the sky, a facade
    square on) drawn as one quad each: what a client would draw."""
    flat = ((inv_v[:-1, :-1] == inv_v[:-1, 1:]) & (inv_v[:-1, :-1] == inv_v[1:, :-1])
            & (inv_v[:-1, :-1] == inv_v[1:, 1:]))
    quads = 0
    for r in range(flat.shape[0]):
        row, depth = flat[r], inv_v[r, :-1]
        run_starts = row & ~np.concatenate([[False], row[:-1] & (depth[1:] == depth[:-1])])
        quads += int((~row).sum() + run_starts.sum())
    return 2 * quads


def depth_mesh(side: Any, at: NDArray[np.float64], inv_v: NDArray[np.float64]) -> NDArray[np.float32]:
    """``(n, 6) float32`` the triangles of the depth mesh (position, texture u and v,
    rubber flag) of a texture sampled from ``at`` with vertex inverse depths ``inv_v``
    ``(g + 1, g + 1)``: each vertex where the sampling point saw it."""
    g = inv_v.shape[0] - 1
    t = np.linspace(0.0, 1.0, g + 1)
    s, v = np.meshgrid(t, 1.0 - t)  # v: 1 at the top row
    wall = np.stack([side.p0[0] + side.along[0] * s * side.length, side.p0[1] + side.along[1] * s * side.length,
                     side.z0 + v * (side.z1 - side.z0)], -1)
    pos = at + (wall - at) / inv_v[..., None]
    dist = 1.0 / inv_v
    tris = []
    for i in range(g):
        for j in range(g):
            quad = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)]
            for a, b, c in ((0, 1, 2), (0, 2, 3)):
                corners = [quad[a], quad[b], quad[c]]
                d = [dist[k] for k in corners]
                flag = 1.0 if max(d) / min(d) > _RUBBER else 0.0
                for k in corners:
                    tris.append([*pos[k], s[k], v[k], flag])
    return np.asarray(tris, np.float32)


class MeshDrawer:
    """Draws a depth mesh with its texture from an eye through a wall's quad."""

    def __init__(self, ctx: Any) -> None:
        self.ctx = ctx
        self.prog = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)

    def draw(self, side: Any, eye: NDArray[np.float64], at: NDArray[np.float64], tris: NDArray[np.float32],
             tex: NDArray[np.uint8], fb: Any) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
        """The premultiplied picture ``(h, w, 4)`` of the mesh ``tris`` textured from
        ``at`` and seen from ``eye``, and the mask (red: covered, green: rubber), at the
        texture's resolution."""
        from walkstream.server.bake.wallrender import off_axis
        from walkstream.shared.camera import mat4_bytes
        from walkstream.shared.litimage import average_samples

        gl_tex = self.ctx.texture((tex.shape[1], tex.shape[0]), 4, np.ascontiguousarray(tex[::-1]).tobytes())
        gl_tex.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
        gl_tex.repeat_x = gl_tex.repeat_y = False
        vbo = self.ctx.buffer(tris.tobytes())
        vao = self.ctx.vertex_array(self.prog, [(vbo, "3f 2x4 1f", "in_position", "in_flag")])
        self.prog["u_view_proj"].write(mat4_bytes(off_axis(eye, side)))
        self.prog["u_tex_proj"].write(mat4_bytes(off_axis(at, side)))
        gl_tex.use(0)
        self.prog["u_tex"].value = 0
        out = []
        for mask in (0.0, 1.0):
            fb.use()
            fb.clear((0.0, 0.0, 0.0, 0.0))
            self.ctx.enable(self.ctx.DEPTH_TEST)
            self.ctx.disable(self.ctx.CULL_FACE)
            self.prog["u_mask"].value = mask
            vao.render()
            out.append(average_samples(fb.read()))
        vao.release()
        vbo.release()
        gl_tex.release()
        return out[0], out[1]

    def release(self) -> None:
        """Free the program."""
        self.prog.release()


def _lay(tex: NDArray[np.uint8], side: Any, warp: Sequence[float]) -> NDArray[np.uint8]:
    """The texture as the client lays it by ``warp`` ``(k, a, u)``: wall texel ``(s, z)``
    shows the texture at ``(a + k s, u + k z)``, clamped to its edge."""
    h, w = tex.shape[:2]
    k, a, u = warp
    s = (np.arange(w) + 0.5) / w * side.length
    z = side.z1 - (np.arange(h) + 0.5) / h * (side.z1 - side.z0)
    ci = np.clip(np.floor((a + k * s) / side.length * w), 0, w - 1).astype(int)
    ri = np.clip(np.floor((side.z1 - (u + k * z)) / (side.z1 - side.z0) * h), 0, h - 1).astype(int)
    return tex[ri[:, None], ci[None, :]]


def _weights(side: Any, eye: NDArray[np.float64], look: NDArray[np.float64], distance: float,
             shape: tuple[int, int]) -> NDArray[np.float64]:
    """Each wall texel's solid angle from the eye, 0 outside the cone about ``look``."""
    h, w = shape
    ss = (np.arange(w) + 0.5) / w * side.length
    zz = side.z1 - (np.arange(h) + 0.5) / h * (side.z1 - side.z0)
    foot = float((eye[:2] - np.asarray(side.p0)) @ side.along)
    d2 = (ss[None, :] - foot) ** 2 + (zz[:, None] - eye[2]) ** 2 + distance ** 2
    px = side.p0[0] + side.along[0] * ss - eye[0]
    py = side.p0[1] + side.along[1] * ss - eye[1]
    cos = (px * look[0] + py * look[1]) / np.maximum(np.hypot(px, py), 1e-9)
    out: NDArray[np.float64] = distance / d2 ** 1.5 * (cos > np.cos(_CONE))[None, :]
    return out


def _share(mask: NDArray[np.bool_], weight: NDArray[np.float64]) -> float:
    return float((mask * weight).sum() / weight.sum())


def _wrong(a: NDArray[np.uint8], b: NDArray[np.uint8]) -> NDArray[np.bool_]:
    out: NDArray[np.bool_] = np.abs(a.astype(np.int16) - b.astype(np.int16))[..., :3].max(axis=-1) > _VISIBLE
    return out


def _walk_offset(reader: Any, path: Any, frames: list[dict[str, str]], cells: dict[int, Any]) -> float:
    """The walk's start on the report's clock: the offset that puts the most of the
    frames' eyes in their logged cells."""
    import shapely

    rows = [r for r in frames[100:400:7] if r["cell"]] or [r for r in frames if r["cell"]]
    t = np.array([float(r["t"]) for r in rows])
    logged = [int(float(r["cell"])) for r in rows]
    best = (-1, 0.0)
    for off in np.arange(0.0, 4.0, 0.02):
        xyz, _, _ = path.sample(t - off)
        hits = sum(1 for p, c in zip(xyz, logged, strict=True)
                   if c in cells and cells[c].contains(shapely.Point(p[:2])))
        if hits > best[0]:
            best = (hits, float(off))
    return best[1]


def measure(db: str, source: str, report: str, path_name: str = "bench", share: float = 0.5,
            bits: int = 0) -> dict[str, list[float]]:
    """Per method the wall views' wrong shares (and ``holes G how``, ``rubber G how``,
    ``bytes G how``: the grid's deflated bytes), the grids' depths stored in ``bits``
    bits a vertex (0: exact)."""
    import shapely

    from walkstream.server.bake.wallrender import WallRenderer
    from walkstream.server.sources.read import read_source
    from walkstream.server.store import SceneReader
    from walkstream.shared.gl import Framebuffer
    from walkstream.shared.litimage import SUPERSAMPLE
    from walkstream.shared.paths import RecordedPath
    from walkstream.shared.walls import EYE_HEIGHT, WallSide, ring_cell, zone_slide, zone_warp

    reader = SceneReader.open(db)
    path = RecordedPath.from_msgpack(reader.path_blob(path_name))
    cells = {c.id: shapely.Polygon(c.boundary[:, :2]) for c in reader.cells()}
    sides = [WallSide.from_row(x) for x in reader.wall_sides()]
    info = reader.wall_texture_info()
    with open(Path(report) / "frames.csv") as f:
        frames = list(csv.DictReader(f))
    with open(Path(report) / "truth.csv") as f:
        truth_rows = list(csv.DictReader(f))
    off = _walk_offset(reader, path, frames, cells)
    ren = WallRenderer(read_source(source, network="walk"))
    drawer = MeshDrawer(ren.ctx)
    fbs: dict[tuple[int, int], Any] = {}
    out: dict[str, list[float]] = {}
    for row in truth_rows:
        wt = float(row["t"]) - off
        if wt < 0:
            continue
        eye, yaw, _ = path.at(wt)
        eye = np.asarray(eye, np.float64)
        cell = next((c for c, p in cells.items() if p.contains(shapely.Point(eye[:2]))), None)
        look = np.array([np.cos(yaw), np.sin(yaw)])
        for s in (s for s in sides if ring_cell(s.portal) == cell):
            v = s.view(eye)
            if v.weight <= 0 or float(look @ s.normal) < 0.3:
                continue
            width = info[s.textures[v.zone]][3]
            truth = ren.render(s, v.zone, width, eye=eye)
            weight = _weights(s, eye, look, v.distance, truth.shape[:2])
            if weight.sum() <= 0:
                continue
            tex = ren.render(s, v.zone, width)
            behind = ren.depth_behind(s, v.zone, width).astype(np.float64)
            at = s.sample_point(v.zone)
            inv = s.depth / (s.depth + np.minimum(behind, DEPTH_CAP))
            foot = float((eye[:2] - np.asarray(s.p0)) @ s.along)
            zw = s.length / s.zones
            res: dict[str, float] = {}
            res["fixed"] = _share(_wrong(tex, truth), weight)
            warp = zone_warp(foot, eye[2], v.distance, v.zone, zw, s.depth, s.floor + EYE_HEIGHT, share)
            laid = _lay(tex, s, tuple(float(g) for g in warp))
            res["warp"] = _share(_wrong(laid, truth), weight)
            size = (width * SUPERSAMPLE, truth.shape[0] * SUPERSAMPLE)
            fb = fbs.get(size) or fbs.setdefault(size, Framebuffer(ren.ctx, size))
            for g in _GRIDS:
                for how in ("mean", "nearest"):
                    inv_v = vertex_depths(inv, g, how)
                    res[f"bytes {g} {how}"] = float(grid_bytes(inv_v, bits))
                    inv_v = quantised(inv_v, bits, s.depth / (s.depth + DEPTH_CAP))
                    res[f"triangles {g} {how}"] = float(merged_triangles(inv_v))
                    tris = depth_mesh(s, at, inv_v)
                    pic, mask = drawer.draw(s, eye, at, tris, tex, fb)
                    res[f"mesh {g} {how}"] = _share(_wrong(pic, truth), weight)
                    # the holes filled by the warped texture drawn under the mesh
                    filled = np.where(mask[..., :1] >= 128, pic, laid)
                    res[f"mesh {g} {how} + warp"] = _share(_wrong(filled, truth), weight)
                    res[f"holes {g} {how}"] = _share(mask[..., 0] < 128, weight)
                    rubber = (mask[..., 0] >= 128) & (mask[..., 1] >= 128)
                    res[f"rubber {g} {how}"] = _share(rubber, weight)
                    res[f"wrong on rubber {g} {how}"] = _share(_wrong(filled, truth) & rubber, weight)
            # the bound: a texture from the viewer's own distance, slid by half its offset
            own = at + np.array([*(s.normal * (s.depth - v.distance)), 0.0])
            tex_own = ren.render(s, v.zone, width, eye=own)
            slide = float(zone_slide(foot, v.zone, zw, share))
            res["own distance"] = _share(_wrong(_lay(tex_own, s, (1.0, -slide, 0.0)), truth), weight)
            for k, val in res.items():
                out.setdefault(k, []).append(val)
    for fb in fbs.values():
        fb.release()
    drawer.release()
    ren.release()
    return out


def table(res: dict[str, list[float]]) -> str:
    """The Markdown table of :func:`measure`'s shares (percent of the wall views' weight)."""
    views = len(res.get("fixed", []))
    lines = [f"{views} wall views", "",
             "| method | wrong, mean | median | 90th pct | holes, mean | rubber, mean | of it on rubber | triangles a wall (flat runs merged) | depth bytes |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    names = ["fixed", "warp"] + [f"mesh {g} {h}{f}" for g in _GRIDS for h in ("mean", "nearest")
                                 for f in ("", " + warp")] + ["own distance"]
    for name in names:
        if name not in res:
            continue
        a = 100.0 * np.asarray(res[name])
        extra = ["", "", "", "2", ""]
        if name.startswith("mesh"):
            key = name[5:].removesuffix(" + warp")
            g = int(key.split()[0])
            extra = [f"{100.0 * np.mean(res['holes ' + key]):.1f} %", f"{100.0 * np.mean(res['rubber ' + key]):.1f} %",
                     f"{100.0 * np.mean(res['wrong on rubber ' + key]):.1f} %" if name.endswith("warp") else "",
                     f"{2 * g * g} ({np.mean(res['triangles ' + key]):.0f}){' + 2' if name.endswith('warp') else ''}",
                     f"{np.mean(res['bytes ' + key]):.0f}"]
        lines.append(f"| {name} | {a.mean():.1f} % | {np.median(a):.1f} % | {np.percentile(a, 90):.1f} % | "
                     + " | ".join(extra) + " |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m walkstream.benchmarks.walldepth DB SOURCE REPORT [--path NAME]``."""
    ap = argparse.ArgumentParser(prog="python -m walkstream.benchmarks.walldepth", description=__doc__.split("\n")[0])
    ap.add_argument("db", help="a walls database (bench walls' SCENE-walls-A.db)")
    ap.add_argument("source", help="the scene's source (the OSM file) the database was baked from")
    ap.add_argument("report", help="a replay report of that database (its truth.csv and frames.csv)")
    ap.add_argument("--path", default="bench", help="the recorded path the replay walked (default bench)")
    ap.add_argument("--share", type=float, default=0.5, help="zone_warp's share (the client's --wall-parallax)")
    ap.add_argument("--bits", type=int, default=8, choices=range(0, 17), metavar="0-16",
                    help="bits a stored vertex depth (default 8; 0: exact)")
    a = ap.parse_args(argv)
    for name, p in (("db", a.db), ("source", a.source), ("report", a.report)):
        if not Path(p).exists():
            print(f"walldepth: {name} {p}: no such file", file=sys.stderr)
            return 2
    for name in ("truth.csv", "frames.csv"):
        if not (Path(a.report) / name).is_file():
            print(f"walldepth: report {a.report}: no {name}", file=sys.stderr)
            return 2
    from walkstream.shared.errors import WalkstreamError

    try:
        res = measure(a.db, a.source, a.report, a.path, a.share, a.bits)
    except WalkstreamError as exc:
        print(f"walldepth: {exc}", file=sys.stderr)
        return 2
    print(table(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
