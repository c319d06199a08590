"""``walkstream bench walls``: the open scenes with and without textured virtual walls.

Ebbesmeyer's virtual walls cut an open space into cells and carry what lies behind a
wall as its texture.  This bench measures the scenes they are for, on the same walks
with and without walls:

- ``hall``: the generated production hall (``walkstream generate interior --preset
  hall``, :mod:`~walkstream.server.sources.hallgen`), its ``tour``;
- ``hall-ifc``: the same hall written as an IFC4 model (``walkstream generate interior
  --preset hall -o hall.ifc``) and read back by the IFC reader: one large open space
  whose bays are IFC spaces with no wall between them, the reader's open stretches
  made virtual walls (not in the default ``--scenes``);
- ``city``: the generated city (700 m, street cells), its ``SE`` walk (past its squares);
- ``squares``: a generated city small enough for its rings' bake to take minutes (300 m,
  seed 1: two squares, 186 buildings; the 700 m city's rings are tens of thousands of
  textures), its ``SM`` walk (along two sides of a square: :data:`SQUARES_CITY`);
- ``west-oakland`` and ``village``: the OpenStreetMap extracts of the data folder, street
  cells, the longest walk that does not repeat itself
  (:func:`~walkstream.server.bake.walks.longest_walk`).

Each scene is baked once into ``--out`` (reused when there) and replayed twice per
variant at 56 kbit/s, 200 ms, 25 fps: on the ``pda`` cost model (simulated clock, every
``--truth-every``-th frame compared with the full scene, the colour error of
:mod:`walkstream.client.truth.roomcolour` indoors and :mod:`walkstream.client.truth.missing`
outdoors) and on ``gl`` (real clock: frames drawn by moderngl and timed, the real frame
period).  Per row: triangles and cells drawn per frame, the frame time on ``gl`` and on
``pda`` (medians), the frames within 10 % of 25 fps, the fog distance the budget sets
(median, indoors), the colour error against the full scene (median mean linear-RGB
error, ΔE00, frames with more than 0.5 % of their pixels over ΔE00 2.3, the share of the
pixels visibly wrong because of the fog), the effective culling (1 - objects drawn as
geometry per frame / objects in the scene; indoors cells), and for walls texture bytes,
texture memory and textures per wall (from the replay's ``walls`` summary).

Variants: ``no walls`` always.  A variant with walls needs a bake that places them
(``BakeSettings.virtual_walls``) and a database whose features name them; then one
database per wall error ``A`` (``--wall-errors``, degrees) is baked and replayed with
walls on; for the hall the no-walls row of the same database
(``ReplayConfig.virtual_walls`` off) is the baseline too.  Outdoors the walls are rings
around the cells whose PVS is large (:mod:`walkstream.server.bake.ringwalls`), which
cut the cells' PVS: the baseline is the plain bake's row, on the same walk (the
cells, hence the walk, are the same).  Until then each scene's walls row says why
there is none.

For the halls, the triangles per frame of **frustum culling alone** and of drawing the
whole hall are measured on the tour's frames too
(:func:`~walkstream.benchmarks.portals.portal_figures`: cells behind portals in the
frustum, no fog; every part), with their ``gl`` and ``pda`` frame times: the issue's
"5 times fewer than frustum culling alone" is against the first, "drawing all of it
misses the targets" the second.

``--quick`` (for a test): a hall of two bays only, short walks, a small frame.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from walkstream.shared.errors import WalkstreamError

__all__ = ["SCENES", "TEXTURE_KEYS", "WALL_ERRORS", "format_walls_table", "parse_texture_variants", "plot_walls",
           "run_walls_bench", "texture_label", "texture_settings", "walls_support"]

Replayer = Callable[[str, Mapping[str, Any], str], Any]

#: The scenes, in table order.
SCENES: tuple[str, ...] = ("hall", "hall-ifc", "city", "squares", "west-oakland", "village")

HALLS: tuple[str, ...] = ("hall", "hall-ifc")
"""The interior scenes: each its own database plays without walls too, and has its frustum-alone figures."""
#: The ``squares`` scene: the generated city's side (m), seed and walk.  Every street
#: region of a generated city is ringed (its PVS is tens of objects, over ``--wall-keep``)
#: at the least distance (its nearest ``K`` objects stand within ``--wall-ring-min``), so
#: at A = 10 degrees each side of a ring is ~17 zones: a 300 m city is 4,162 textures
#: (~15 minutes' bake on two shared cores), the 700 m city several times that.
SQUARES_CITY: tuple[float, int, str] = (300.0, 1, "SM")
#: The wall errors A (degrees) the paper's question asks about: 10 good, 15 the limit.
WALL_ERRORS: tuple[float, ...] = (5.0, 10.0, 15.0, 20.0)
_OSM = {"west-oakland": "west-oakland.osm", "village": "village-10.068_48.135.osm"}
_BENCH_PATH = "bench"
_ROOMS = ("interior", "crossing")


def walls_support() -> tuple[bool, bool]:
    """``(bake, replay)``: whether this walkstream's bake places virtual walls (``bake(...,
    walls=WallSettings)``) and its replay can switch them (``ReplayConfig.virtual_walls``)."""
    import inspect

    from walkstream.client.config import ReplayConfig
    from walkstream.server.bake import bake as bake_fn

    bake = "walls" in inspect.signature(bake_fn).parameters
    play = "virtual_walls" in {f.name for f in dataclasses.fields(ReplayConfig)}
    return bake, play


def _has_walls(db: Path) -> bool:
    from walkstream.server.store import SceneReader

    reader = SceneReader.open(db)
    try:
        features = reader.summary().get("features") or []
    finally:
        reader.close()
    return any("wall" in str(f) for f in features)


def _bake_scene(name: str, out: Path, data: Path, quick: bool, settings: dict[str, Any], tag: str = "") -> tuple[Path, str]:
    """The scene's database (baked into ``out`` unless there) and the path to replay."""
    from walkstream.server.bake import BakeSettings, bake
    from walkstream.server.bake.walks import SE_SPEED_KMH, longest_walk
    from walkstream.server.store import SceneReader, write_path

    db = out / f"{name}{tag}.db"
    if name in HALLS:
        from walkstream.server.sources.hallgen import HALL_PRESETS, HallPlan, generate_hall
        from walkstream.server.sources.interiorgen import write_interior_doc

        src = out / ("hall.ifc" if name == "hall-ifc" else "hall.json")
        if not src.exists():
            plan = HallPlan(columns=2, rows=1, side_depth=0.0, seed=2) if quick else HALL_PRESETS["hall"]
            write_interior_doc(src, generate_hall(plan))
        path = "tour"
    elif name == "city":
        from walkstream.server.sources.citygen import write_city

        src = out / "city.geojson"
        if not src.exists():
            write_city(src, 700.0, 1)
        path = "SE"
    elif name == "squares":
        from walkstream.server.sources.citygen import write_city

        side, seed, path = SQUARES_CITY
        src = out / "squares.geojson"
        if not src.exists():
            write_city(src, side, seed)
    elif name in _OSM:
        src = data / _OSM[name]
        if not src.exists():
            raise WalkstreamError(f"{src}: extract not found (see {data / 'README.md'})")
        path = _BENCH_PATH
    else:
        raise WalkstreamError(f"bench walls: unknown scene {name!r}; choose from {', '.join(SCENES)}")
    if not db.exists():
        print(f"  baking {db.name} ...", file=sys.stderr, flush=True)
        cells = {} if name in HALLS else {"cells": "street"}
        extra: dict[str, Any] = {}
        if settings.get("virtual_walls"):
            from walkstream.server.bake.wallplan import WallSettings

            extra["walls"] = texture_settings(WallSettings(error_deg=float(settings.get("wall_error", 10.0)),
                                                           depth_grid=int(settings.get("wall_depth", 0))),
                                              settings.get("wall_texture") or {})
        settings = {k: v for k, v in settings.items()
                    if k not in ("virtual_walls", "wall_error", "wall_depth", "wall_texture")}
        bake(src, db, settings=BakeSettings(**(cells | settings)), **extra)
        base = out / f"{name}.db"
        if extra and path != _BENCH_PATH and base.exists():
            # the same walk as without walls: the walls' smaller cells give the bake's
            # own tour another route (through the equipment between the bays' middles)
            reader = SceneReader.open(base)
            try:
                blob = reader.path_blob(path)
            finally:
                reader.close()
            write_path(db, path, blob)
        if path == _BENCH_PATH:
            reader = SceneReader.open(db)
            try:
                walk = longest_walk(reader.cells(), SE_SPEED_KMH, _BENCH_PATH)
            finally:
                reader.close()
            if walk is None:
                raise WalkstreamError(f"{db}: no walk of two cells or more in its street cells")
            write_path(db, _BENCH_PATH, replace(walk, name=_BENCH_PATH).to_msgpack())
    return db, path


TEXTURE_KEYS: tuple[str, ...] = ("view", "texels", "max-side", "quality")
"""The keys of a ``--wall-textures`` variant: ``walkstream bake``'s ``--wall-view``,
``--wall-texels``, ``--wall-max-side`` and ``--wall-quality``."""


def texture_settings(base: Any, texture: Mapping[str, str]) -> Any:
    """``base`` (a :class:`~walkstream.server.bake.wallplan.WallSettings`) with a
    ``--wall-textures`` variant's keys set, checked (a bad value: one-line error)."""
    from walkstream.server.bake.wallplan import parse_wall_quality

    def number(key: str, kind: type) -> Any:
        try:
            return None if key not in texture else kind(texture[key])
        except ValueError:
            raise WalkstreamError(f"--wall-textures {key}={texture[key]!r}: expected a number") from None

    view = number("view", int)
    st = base if view is None else replace(base, view_height=view)
    return st.with_texture(texels=number("texels", float), max_side=number("max-side", int),
                           quality=parse_wall_quality(texture.get("quality"))).check()


def parse_texture_variants(text: str) -> list[dict[str, str]]:
    """``--wall-textures``: variants separated by ``;``, each ``key=value`` pairs separated
    by ``,`` (:data:`TEXTURE_KEYS`), e.g. ``view=120;texels=4,quality=75``; each checked."""
    from walkstream.server.bake.wallplan import WallSettings

    out: list[dict[str, str]] = []
    for part in (p.strip() for p in text.split(";")):
        if not part:
            continue
        spec: dict[str, str] = {}
        for pair in (q.strip() for q in part.split(",") if q.strip()):
            key, eq, value = pair.partition("=")
            if not eq or key.strip() not in TEXTURE_KEYS:
                raise WalkstreamError(f"--wall-textures {pair!r}: expected key=value with a key of {', '.join(TEXTURE_KEYS)}")
            spec[key.strip()] = value.strip()
        texture_settings(WallSettings(), spec)
        out.append(spec)
    return out


def texture_label(spec: Mapping[str, str]) -> str:
    """A ``--wall-textures`` variant as it names its row and database (``view=120 quality=75``)."""
    return " ".join(f"{k}={spec[k]}" for k in TEXTURE_KEYS if k in spec)


def _frames(report: Path) -> dict[str, np.ndarray]:
    import csv

    with open(report / "frames.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    keys = rows[0].keys() if rows else ()
    return {k: np.array([float(r[k] or "nan") for r in rows]) for k in keys}


def _row(scene: str, variant: str, pda: Any, gl: Any, reports: tuple[Path, Path | None], objects: int,
         bake_s: float | None = None) -> dict[str, Any]:
    """One table row from the pda replay's summary (and the gl one's)."""
    s = pda.summary
    f = _frames(reports[0])
    interior = s.get("kind") in _ROOMS
    c = (s.get("truth") or {}).get("colour") or {}
    drawn = f.get("visible", np.zeros(0))
    cells = s.get("visible_cells_mean")
    in_scene = s.get("cells_in_scene") if interior else objects
    walls = s.get("walls") or {}
    # outdoors: objects drawn as geometry, the same count with walls and without (the
    # frame log's `visible` holds the walls' and the facades' quads too)
    geometry = s.get("geometry_objects_mean", walls.get("geometry_objects_mean"))
    if geometry is None and len(drawn):
        geometry = float(drawn.mean())
    row: dict[str, Any] = {
        "scene": scene,
        "variant": variant,
        "kind": s.get("kind"),
        "frames": s.get("frames"),
        "triangles_median": float(np.median(f["triangles"])) if len(f.get("triangles", ())) else None,
        "triangles_mean": s.get("triangles_mean"),
        "cells_drawn_mean": cells,
        "objects_drawn_mean": geometry,
        "pda_frame_ms": 1e3 * float(np.median(f["frame_time"])) if len(f.get("frame_time", ())) else None,
        "pda_within_10pct": s.get("fps_within_10pct_ratio"),
        "fog_m_median": s.get("fog_m_median"),
        "colour_error_median": (c.get("mean_error") or {}).get("median"),
        "delta_e_median": (c.get("delta_e_mean") or {}).get("median"),
        "frames_over_visible": c.get("frames_over_visible_ratio"),
        "fog_visible_share": (c.get("causes") or {}).get("fog"),
        "compared_frames": c.get("frames"),
        "effective_culling": _culling(cells if interior else geometry, in_scene),
        "texture_bytes": walls.get("texture_bytes", 0),
        "texture_memory_bytes": walls.get("texture_memory_bytes", 0),
        "textures_per_wall": walls.get("textures_per_wall"),
        "perfect_frame_ratio": s.get("perfect_frame_ratio"),
        "bytes_received": s.get("bytes_received"),
        "bake_s": bake_s,
        "seam_ratio": ((s.get("truth") or {}).get("seam") or {}).get("ratio"),
        "far_field_frames": walls.get("far_field_frames"),
        **_visible_shares(reports[0]),
    }
    if gl is not None and reports[1] is not None:
        g = _frames(reports[1])
        period = np.diff(g["t"]) if len(g.get("t", ())) > 1 else np.zeros(0)
        row |= {
            "gl_frame_ms": 1e3 * float(np.median(g["frame_time"])) if len(g.get("frame_time", ())) else None,
            "gl_period_ms": 1e3 * float(np.median(period)) if len(period) else None,
            "gl_within_10pct": gl.summary.get("fps_within_10pct_ratio"),
            "gl_triangles_median": float(np.median(g["triangles"])) if len(g.get("triangles", ())) else None,
            "gl_fog_m_median": gl.summary.get("fog_m_median"),
        }
    return row


VISIBLE_SHARE = 0.01
"""The issue's bound on a compared frame's pixels over the visible threshold (ΔE00 2.3)."""


def _visible_shares(report: Path) -> dict[str, float | None]:
    """Of the compared frames (``truth.csv``), the share whose pixels over the visible
    threshold are at most :data:`VISIBLE_SHARE` of the frame, all causes together
    (``frames_visible_1pct``) and those the walls' textures caused
    (``frames_wall_visible_1pct``, the truth's cause ``wall``); None without a truth."""
    path = report / "truth.csv"
    if not path.exists():
        return {"frames_visible_1pct": None, "frames_wall_visible_1pct": None}
    import csv

    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows or "visible" not in rows[0]:
        return {"frames_visible_1pct": None, "frames_wall_visible_1pct": None}
    vis = np.array([float(r["visible"] or 0.0) for r in rows])
    wall = np.array([float(r.get("colour_wall") or 0.0) for r in rows])
    return {"frames_visible_1pct": float((vis <= VISIBLE_SHARE).mean()),
            "frames_wall_visible_1pct": float((wall <= VISIBLE_SHARE).mean())}


def _culling(drawn: float | None, in_scene: float | None) -> float | None:
    """Effective culling: 1 - drawn per frame / in the scene (None when either is unknown)."""
    if drawn is None or not in_scene:
        return None
    return 1.0 - float(drawn) / float(in_scene)


def _summary(db: Path) -> dict[str, Any]:
    from walkstream.server.store import SceneReader

    reader = SceneReader.open(db)
    try:
        return dict(reader.summary())
    finally:
        reader.close()


def _objects(db: Path) -> int:
    return int(_summary(db).get("objects") or 0)


def run_walls_bench(
    replay: Replayer,
    *,
    out: Path,
    data: Path,
    scenes: Sequence[str] = SCENES,
    wall_errors: Sequence[float] = WALL_ERRORS,
    duration: str = "60s",
    gl_duration: str = "20s",
    truth_every: int = 25,
    size: str = "640x480",
    gl: bool = True,
    quick: bool = False,
    frustum_frames: int = 40,
    wall_depth: int = 0,
    wall_textures: Sequence[Mapping[str, str]] = (),
) -> dict[str, Any]:
    """Bake and replay every scene with and without walls (module docstring); with
    ``wall_depth`` ``G`` > 0 each A also baked with ``--wall-depth G`` and played as the
    variant ``walls A=a G=g`` (textured depth meshes), beside the walls without; each of
    ``wall_textures`` (:func:`parse_texture_variants`) bakes each A once more with those
    texture settings, the variant ``walls A=a view=... quality=...``.

    Returns ``{"rows": [...], "frustum": {hall scene: {...}}, "notes": [...]}`` and writes
    ``bench_walls.json`` and ``bench_walls.png`` into ``out``.
    """
    out.mkdir(parents=True, exist_ok=True)
    can_bake, can_play = walls_support()
    rows: list[dict[str, Any]] = []
    notes: list[str] = []
    frustum: dict[str, Any] = {}
    link = {"bandwidth": "56kbit", "rtt": "200ms", "fps": 25.0}
    for scene in scenes:
        print(f"{scene}:", file=sys.stderr, flush=True)
        db, path = _bake_scene(scene, out, data, quick, {})
        variants: list[tuple[str, Path, dict[str, Any]]] = [
            ("no walls", db, {"virtual_walls": False} if can_play else {})
        ]
        if not can_bake:
            notes.append(f"{scene}: no walls in this database (this walkstream's bake places no virtual walls)")
        else:
            for a in wall_errors:
                wdb, _ = _bake_scene(scene, out, data, quick, {"virtual_walls": True, "wall_error": float(a)},
                                     tag=f"-walls-{a:g}")
                if not _has_walls(wdb):
                    notes.append(f"{scene} A={a:g}: no walls in this database (the bake placed none)")
                    continue
                variants.append((f"walls A={a:g}", wdb, {"virtual_walls": True} if can_play else {}))
                if wall_depth:
                    ddb, _ = _bake_scene(scene, out, data, quick, {"virtual_walls": True, "wall_error": float(a),
                                                                   "wall_depth": wall_depth},
                                         tag=f"-walls-{a:g}-depth{wall_depth}")
                    variants.append((f"walls A={a:g} G={wall_depth}", ddb, {"virtual_walls": True} if can_play else {}))
                for spec in wall_textures:
                    label = texture_label(spec)
                    tdb, _ = _bake_scene(scene, out, data, quick, {"virtual_walls": True, "wall_error": float(a),
                                                                   "wall_texture": spec},
                                         tag=f"-walls-{a:g}-" + label.replace(" ", "-").replace("=", ""))
                    variants.append((f"walls A={a:g} {label}", tdb, {"virtual_walls": True} if can_play else {}))
                if can_play and scene in HALLS:
                    # indoors the walls' database plays without them too (every portal
                    # open); a city's rings cut its PVS, so without walls it is the plain bake
                    variants.append((f"no walls (A={a:g} db)", wdb, {"virtual_walls": False}))
        objects = _objects(db)
        for variant, vdb, extra in variants:
            tag = f"{scene}-{variant}".replace(" ", "-").replace("(", "").replace(")", "").replace("=", "")
            rep_pda = out / f"{tag}-pda"
            opts = {"path": path, "device": "pda", "clock": "sim", "duration": duration, "size": size,
                    "report": str(rep_pda)} | link | extra | ({"truth_every": truth_every} if truth_every else {})
            print(f"  {variant}: pda ...", file=sys.stderr, flush=True)
            pda = replay(str(vdb), opts, f"{scene}, {variant}, pda")
            g = None
            rep_gl = None
            if gl:
                rep_gl = out / f"{tag}-gl"
                gopts = {"path": path, "device": "gl", "clock": "real", "duration": gl_duration, "size": size,
                         "report": str(rep_gl)} | link | extra
                print(f"  {variant}: gl (real clock) ...", file=sys.stderr, flush=True)
                g = replay(str(vdb), gopts, f"{scene}, {variant}, gl")
            bake_s = _summary(vdb).get("bake_seconds")
            rows.append(_row(scene, variant, pda, g, (rep_pda, rep_gl), objects,
                             None if bake_s is None else float(bake_s)))
        if scene in HALLS:
            from walkstream.benchmarks.portals import portal_figures

            w, h = (int(v) for v in size.lower().split("x"))
            fig = portal_figures(db, frames=frustum_frames, step_s=2.0, size=(w, h), gl=gl)
            frustum[scene] = {
                "frames": fig["frames"],
                "triangles_in_hall": fig["triangles"],
                "modes": {m: {"triangles_median": fig["modes"][m]["tris"]["median"],
                              "cells_median": fig["modes"][m]["cells"]["median"],
                              "pda_ms_median": fig["modes"][m]["pda_ms"]["median"],
                              "gl_ms_median": fig["modes"][m]["gl_ms"]["median"] if gl else None}
                          for m in ("portals", "frustum", "none")},
            }
    result = {"rows": rows, "frustum": frustum, "notes": notes, "walls_support": {"bake": can_bake, "replay": can_play}}
    (out / "bench_walls.json").write_text(json.dumps(result, indent=2, default=str))
    if rows:
        plot_walls(out / "bench_walls.png", rows)
    return result


def _f(v: Any, fmt: str, scale: float = 1.0) -> str:
    width = int(fmt.split(".")[0] or 0)
    return "—".rjust(width) if v is None else format(float(v) * scale, fmt)


def format_walls_table(result: Mapping[str, Any]) -> str:
    """The table (one line per scene and variant), the hall's frustum-alone figures and the notes.

    Columns: ``tri/fr`` triangles per frame (pda, median); ``drawn`` cells drawn per frame
    indoors, objects drawn as geometry outdoors (mean); ``pda ms`` and ``gl ms`` the
    frame time (median), ``gl per`` the real frame period on ``gl``; ``pda10%`` and
    ``gl10%`` frames within 10 % of 25 fps; ``fog m`` the budget's fog (median, pda);
    ``err %`` the mean linear-RGB error against the full scene (median, % of full
    scale), ``dE00`` the mean ΔE00 (median), ``over%`` frames with more than 0.5 % of
    their pixels over ΔE00 2.3, ``fog%`` the mean share of pixels visibly wrong because
    of the fog; ``cull%`` effective culling; ``tex kB`` and ``tex/wall`` the walls'
    texture bytes and textures per wall; ``seam`` the change of a wall's pixels across
    a zone border over that of plain motion (``truth.seam.ratio``; at most 1: no seam;
    over the pairs of successive compared frames, so measured best with
    ``--truth-every 1``); ``perf%`` perfect frames and ``kB`` bytes received (pda walk,
    56 kbit/s); ``bake s`` the database's bake time; ``far%`` the frames that drew a
    ring's far field as geometry while a texture was missing (outdoors); ``vis1%`` the
    compared frames with at most 1 % of their pixels over ΔE00 2.3, and ``wall1%`` those
    with at most 1 % over it because of the walls (the truth's cause ``wall``: an
    interior's walls and a city's ring walls alike).
    """
    head = (f"{'scene':<13} {'variant':<20} {'tri/fr':>7} {'drawn':>6} {'pda ms':>7} {'pda10%':>7} {'gl ms':>7} "
            f"{'gl per':>7} {'gl10%':>6} {'fog m':>6} {'err %':>6} {'dE00':>6} {'over%':>6} {'fog%':>6} "
            f"{'cull%':>6} {'tex kB':>7} {'tex/wall':>8} {'seam':>5} {'perf%':>6} {'kB':>7} {'bake s':>7} "
            f"{'far%':>6} {'vis1%':>6} {'wall1%':>6}")
    lines = [head, "-" * len(head)]
    for r in result.get("rows", []):
        lines.append(
            f"{r['scene']:<13} {r['variant']:<20} {_f(r.get('triangles_median'), '7.0f')} "
            f"{_f(r.get('cells_drawn_mean') if r.get('kind') in _ROOMS else r.get('objects_drawn_mean'), '6.1f')} "
            f"{_f(r.get('pda_frame_ms'), '7.1f')} {_f(r.get('pda_within_10pct'), '7.1f', 100)} "
            f"{_f(r.get('gl_frame_ms'), '7.1f')} {_f(r.get('gl_period_ms'), '7.1f')} {_f(r.get('gl_within_10pct'), '6.1f', 100)} "
            f"{_f(r.get('fog_m_median'), '6.1f')} {_f(r.get('colour_error_median'), '6.2f', 100)} "
            f"{_f(r.get('delta_e_median'), '6.2f')} {_f(r.get('frames_over_visible'), '6.1f', 100)} "
            f"{_f(r.get('fog_visible_share'), '6.1f', 100)} {_f(r.get('effective_culling'), '6.1f', 100)} "
            f"{_f(r.get('texture_bytes'), '7.1f', 1e-3)} {_f(r.get('textures_per_wall'), '8.1f')} "
            f"{_f(r.get('seam_ratio'), '5.2f')} {_f(r.get('perfect_frame_ratio'), '6.1f', 100)} "
            f"{_f(r.get('bytes_received'), '7.1f', 1e-3)} {_f(r.get('bake_s'), '7.1f')} "
            f"{_f(r.get('far_field_frames'), '6.1f', 100)} {_f(r.get('frames_visible_1pct'), '6.1f', 100)} "
            f"{_f(r.get('frames_wall_visible_1pct'), '6.1f', 100)}"
        )
    for scene, fr in (result.get("frustum") or {}).items():
        lines.append("")
        lines.append(f"{scene}, {fr['frames']} tour frames, {fr['triangles_in_hall']:,} triangles in the hall (no fog):")
        for m, label in (("portals", "portal culling"), ("frustum", "frustum culling alone"), ("none", "drawn whole")):
            d = fr["modes"][m]
            lines.append(f"  {label:<22} {d['triangles_median']:>9,.0f} triangles/frame, {d['cells_median']:>5.0f} cells, "
                         f"pda {d['pda_ms_median']:>8.1f} ms, gl {_f(d['gl_ms_median'], '7.1f')} ms")
    for n in result.get("notes", []):
        lines.append(f"note: {n}")
    return "\n".join(lines)


def plot_walls(path: Path, rows: Sequence[Mapping[str, Any]]) -> Path:
    """``bench_walls.png``: per scene and variant, triangles per frame, the fog distance and the colour error."""
    from walkstream.client.report.plots import grid_figure, save_figure

    fig, axes = grid_figure(3, height=2.6)
    labels = [f"{r['scene']}\n{r['variant']}" for r in rows]
    x = np.arange(len(rows))
    panels = (
        ("triangles_median", 1.0, "triangles per frame (pda, median)"),
        ("fog_m_median", 1.0, "fog distance the budget sets (m, median)"),
        ("colour_error_median", 100.0, "colour error vs the full scene (% of full scale, median)"),
    )
    for ax, (key, scale, title) in zip(axes, panels, strict=True):
        vals = [float(r[key]) * scale if r.get(key) is not None else 0.0 for r in rows]
        colours = ["#0072B2" if "no walls" in r["variant"] else "#D55E00" for r in rows]
        ax.bar(x, vals, color=colours)
        ax.set_ylabel(title, fontsize=8)
        ax.set_xticks(x)
        ax.set_xticklabels(labels, fontsize=7)
    axes[0].set_title("bench walls: blue without walls, orange with", fontsize=10)
    return save_figure(fig, path)
