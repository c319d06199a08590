"""``walkstream bench portals --cull``: the portal culling's CPU time per frame.

The culling of a frame is the portal walk (:func:`~walkstream.shared.portals.cull_portals`)
and the parts culling of the cells it finds (:func:`~walkstream.shared.partcull.cull_parts`);
both are timed with ``time.process_time`` (the process's CPU, not the wall clock a
loaded machine stretches), apart and together, median and 99th percentile over the
frames:

- ``hall``: the open 16 x 16 hall of :func:`~walkstream.benchmarks.portals.hall_topology`
  at 640x480 from a corner, the view swept from 30 to 60 degrees so that 200-236
  cells are visible; each cell holds :data:`HALL_PARTS` part boxes (floor, ceiling and
  furniture at fixed random places), so the parts culling tests a few thousand boxes;
- ``hall walk``: the same hall walked at 1.4 m/s and 25 frames a second from the
  corner along the diagonal (5.6 cm a frame), the view swept likewise, from the
  cell the eye stands in: consecutive frames as a walker makes them;
- ``seed S``: the tour of the generated office of seed ``S`` (3 storeys, ``walkstream
  generate interior --storeys 3 --seed S``, baked into ``--out`` once), a pose every
  10 s culled from its cell at a 40 m fog, 640x480;
- ``seed S walk`` (with ``cache`` only): a minute of that tour (:data:`WALK_SPAN_S`)
  frame by frame at 25 frames a second.

With ``against`` (a git revision of this repository) the culling of that revision is
loaded beside the current one (its ``shared/screenrects.py``, ``shared/portals.py`` and
``shared/partcull.py`` where it has one)
and timed frame by frame alternately with it, so that both see the same load, each
going first on every other frame (the one timed second may find the frame's arrays
in the cache); today's must keep every part that revision keeps (a superset), which is
checked on every frame.

With ``cache`` today's culling is the one reused frame to frame
(:class:`~walkstream.shared.cullcache.CullCache`, one per scene, its misses counted):
its walk column is the walk of the frames that make a guard and the checks of those
that reuse one (with the next guard's walk, made ahead), its parts column the parts
culling of a guard; the other side is each frame culled anew (``against``'s revision,
or today's culling).  The cache keeps every part a frame sees (its guard tests rays),
not every part the frame's own rectangles keep by their pixel rounding: the parts kept
anew and left out by the cache are counted (``dropped``), and the id truth decides
whether any was seen (tests/test_cullcache.py).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
import subprocess
import sys
import time
import types
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.benchmarks.portals import hall_topology
from walkstream.server.bake import bake
from walkstream.server.service.interiors import InteriorState
from walkstream.server.sources.interiorgen import InteriorPlan, write_interior
from walkstream.server.store import SceneReader
from walkstream.shared import cullkernels, partcull, portals
from walkstream.shared.camera import camera, perspective
from walkstream.shared.codec.cellpieces import decode_cell_pieces
from walkstream.shared.cullcache import CullCache
from walkstream.shared.errors import InputError, WalkstreamError
from walkstream.shared.paths import RecordedPath
from walkstream.shared.portalgraph import PortalGraph
from walkstream.shared.roomview import cell_of, stack_planes
from walkstream.shared.roomwire import decode_topology

__all__ = ["HALL_PARTS", "hall_boxes", "culling_at", "cull_cpu_rows", "cull_cpu_table"]

#: Part boxes per cell of the benchmark's hall (the generated offices hold about 16 per cell).
HALL_PARTS = 16

#: The functions timed: ``(cull_portals, cull_parts)``.
Culling = tuple[Callable[..., Any], Callable[..., Any]]

Frame = tuple[PortalGraph, int, NDArray[np.float64], NDArray[np.float64]]

SIZE = (640, 480)

#: A scene of the bench: its frames, part boxes, fog and a locator of points' cells.
Scene = tuple[list[Frame], dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]], float,
              Callable[[NDArray[np.float64]], "int | None"]]

#: The hall walk's step a frame: 1.4 m/s at 25 frames a second.
WALK_STEP_M = 1.4 / 25.0

#: The stretch of a seed's tour culled frame by frame with ``cache``, seconds.
WALK_SPAN_S = (60.0, 120.0)


def hall_boxes(k: int, per_cell: int = HALL_PARTS, cell_m: float = 4.0, height: float = 3.0,
               seed: int = 0) -> dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """Part boxes for the cells of :func:`~walkstream.benchmarks.portals.hall_topology` ``(k)``:
    per cell ``(lo, hi)`` ``(per_cell, 3)``, a floor and a ceiling slab and furniture (0.4 to
    1.6 m wide, 0.4 to 2.2 m high) at fixed random places."""
    rng = np.random.default_rng(seed)
    out = {}
    for y in range(k):
        for x in range(k):
            x0, y0 = x * cell_m, y * cell_m
            lo = [(x0, y0, -0.2), (x0, y0, height)]
            hi = [(x0 + cell_m, y0 + cell_m, 0.0), (x0 + cell_m, y0 + cell_m, height + 0.2)]
            for _ in range(per_cell - 2):
                w, d, h = rng.uniform(0.4, 1.6), rng.uniform(0.4, 1.6), rng.uniform(0.4, 2.2)
                px, py = x0 + rng.uniform(0.0, cell_m - w), y0 + rng.uniform(0.0, cell_m - d)
                lo.append((px, py, 0.0))
                hi.append((px + w, py + d, h))
            out[y * k + x] = (np.array(lo, np.float64), np.array(hi, np.float64))
    return out


def culling_at(rev: str) -> Culling:
    """``(cull_portals, cull_parts)`` as they were at git revision ``rev`` of this repository,
    loaded as modules of their own beside the current ones (``shared/screenrects.py``,
    ``shared/portals.py`` and, where the revision has them, ``shared/portalgraph.py``,
    ``shared/cullkernels.py`` and ``shared/partcull.py``; that revision's kernels compiled
    anew, not cached, their source being no file, unless they are today's).  Its walk is handed each graph made anew
    as that revision's :class:`PortalGraph` (once per graph, on the untimed first frame:
    the derived tables it walks over are its own)."""
    root = Path(portals.__file__).resolve().parents[1]
    mods: dict[str, types.ModuleType] = {}
    for name in ("screenrects", "portalgraph", "cullkernels", "portals", "partcull"):
        try:
            got = subprocess.run(["git", "-C", str(root), "show", f"{rev}:shared/{name}.py"],
                                 capture_output=True, text=True, check=False)
        except OSError as exc:
            raise InputError(f"--cull-against {rev}: git could not be run ({exc.strerror})") from None
        if got.returncode != 0:
            if name in ("portalgraph", "cullkernels"):  # before the graph had a module, the culling was compiled
                continue
            if name == "partcull":  # before the parts culling had a module of its own
                break
            raise InputError(f"--cull-against {rev}: no shared/{name}.py at that revision of {root}")
        if name == "cullkernels" and got.stdout == Path(cullkernels.__file__).read_text():
            mods[name] = cullkernels  # the same kernels: today's, compiled and cached
            continue
        mod_name = f"walkstream_cull_{name}_at_{abs(hash(rev))}"
        text = got.stdout if name != "cullkernels" else got.stdout.replace("cache=True", "cache=False")
        for dep, mod in mods.items():  # that revision's own modules, not today's
            text = re.sub(rf"\bwalkstream\.shared\.{dep}\b", mod.__name__, text)
        mod = types.ModuleType(mod_name)
        mod.__file__ = f"{rev}:shared/{name}.py"
        sys.modules[mod_name] = mod  # dataclasses look their module up by name
        exec(compile(text, mod.__file__, "exec"), mod.__dict__)  # noqa: S102 - this repository's own code
        mods[name] = mod
    walk = mods["portals"].cull_portals
    if "portalgraph" in mods:
        walk = _graph_as(mods["portalgraph"].PortalGraph, walk)
    return walk, mods.get("partcull", mods["portals"]).cull_parts


def _graph_as(cls: Any, walk: Callable[..., Any]) -> Callable[..., Any]:
    """``walk`` called with each graph remade as ``cls`` (an earlier revision's
    :class:`PortalGraph`, from today's one's fields; made once per graph)."""
    made: dict[int, tuple[PortalGraph, Any]] = {}

    def run(graph: PortalGraph, *args: Any, **kwargs: Any) -> Any:
        got = made.get(id(graph))
        if got is None or got[0] is not graph:
            fields = {f.name: getattr(graph, f.name) for f in dataclasses.fields(graph) if f.init}
            got = made[id(graph)] = (graph, cls(**fields))
        return walk(got[1], *args, **kwargs)

    return run


def _hall_frames(frames: int) -> Scene:
    k = 16
    graph = PortalGraph.from_topology(hall_topology(k))
    eye = np.array([0.5, 0.5, 1.6])
    yaws = np.linspace(math.radians(30.0), math.radians(60.0), frames)
    return ([(graph, 0, eye, camera(eye, float(a), 0.0).astype(np.float64)) for a in yaws], hall_boxes(k), math.inf,
            _hall_cell(k))


def _hall_cell(k: int, cell_m: float = 4.0) -> Callable[[NDArray[np.float64]], int | None]:
    """The cell of the hall of ``k`` x ``k`` cells that holds a point (None outside)."""
    def locate(eye: NDArray[np.float64]) -> int | None:
        x, y = int(eye[0] // cell_m), int(eye[1] // cell_m)
        return y * k + x if 0 <= x < k and 0 <= y < k else None
    return locate


def _hall_walk(frames: int) -> Scene:
    k, cell_m = 16, 4.0
    graph = PortalGraph.from_topology(hall_topology(k))
    out: list[Frame] = []
    for i, a in enumerate(np.linspace(math.radians(30.0), math.radians(60.0), frames).tolist()):
        eye = np.array([0.5, 0.5, 1.6]) + i * WALK_STEP_M * np.array([math.sqrt(0.5), math.sqrt(0.5), 0.0])
        cell = _hall_cell(k, cell_m)(eye)
        assert cell is not None
        out.append((graph, cell, eye, camera(eye, a, 0.0).astype(np.float64)))
    return out, hall_boxes(k), math.inf, _hall_cell(k, cell_m)


def _seed_frames(seed: int, out: Path, log: Callable[[str], None], step_s: float = 10.0,
                 storeys: int = 3, span: tuple[float, float] | None = None) -> Scene:
    src, db = out / f"seed{seed}.json", out / f"seed{seed}.db"
    if not db.exists():
        out.mkdir(parents=True, exist_ok=True)
        write_interior(src, InteriorPlan(storeys=storeys, seed=seed))
        log(f"bench portals: baking seed {seed}")
        bake(src, db)
    with SceneReader.open(db) as r:
        state = InteriorState(r, list(r.cells()))
        topo = decode_topology(state.topology["msgpack"].content, f"{db}: topology")
        meshes = {c.id: decode_cell_pieces(r.contents(c.id), f"{db}: cell {c.id}") for c in topo.cells}
        tour = RecordedPath.from_msgpack(r.path_blob("tour"))
    graph = PortalGraph.from_topology(topo)
    ids, planes = stack_planes([c for c in topo.cells if c.kind != "outside" and len(c.planes)])
    boxes = {cid: (np.array([p.bbox[0] for p in m.parts]).reshape(-1, 3), np.array([p.bbox[1] for p in m.parts]).reshape(-1, 3))
             for cid, m in meshes.items()}
    frames: list[Frame] = []
    t0, t1 = span if span is not None else (0.0, tour.duration)
    for t in np.arange(t0, min(t1, tour.duration), step_s).tolist():
        xyz, yaw, pitch = tour.at(t)
        eye = np.asarray(xyz, np.float64)
        hit = np.flatnonzero(cell_of(planes, eye))
        if len(hit):
            frames.append((graph, int(ids[hit[0]]), eye, camera(eye, float(yaw), float(pitch)).astype(np.float64)))

    def locate(eye: NDArray[np.float64]) -> int | None:
        hit = np.flatnonzero(cell_of(planes, eye))
        return int(ids[hit[0]]) if len(hit) else None

    return frames, boxes, 40.0, locate


def _time(culling: Culling, frame: Frame, boxes: dict[int, Any], proj: NDArray[np.float64],
          fog_m: float) -> tuple[float, float, int, dict[int, NDArray[np.bool_]]]:
    """One frame's walk and parts culling: their CPU seconds, the visible cells, the parts kept."""
    walk, parts = culling
    graph, start, eye, view = frame
    t0 = time.process_time()
    pc = walk(graph, start, eye, view, proj, SIZE, fog_m=fog_m)
    t1 = time.process_time()
    keep = parts("portals", pc.order, boxes, eye, view, proj, SIZE, vsas=pc.vsas, fog_m=fog_m)
    t2 = time.process_time()
    return t1 - t0, t2 - t1, len(pc.order), keep


def _cache_culling(cache: CullCache) -> Culling:
    """``(walk, parts)`` functions that time :meth:`CullCache.cull` as :func:`_time` times the
    two steps: the walk returns the whole answer, whose own split of the CPU the parts step
    hands back (the bench's clock around it is the check)."""
    got: dict[str, Any] = {}

    def walk(graph: PortalGraph, start: int, eye: Any, view: Any, proj: Any, size: Any, *, fog_m: float) -> Any:
        got["r"] = r = cache.cull(start, eye, view, proj, size, got["boxes"], fog_m=fog_m)
        return types.SimpleNamespace(order=r.order, vsas=None)

    def parts(_mode: str, _cells: Any, _boxes: Any, *_a: Any, **_k: Any) -> dict[int, NDArray[np.bool_]]:
        return dict(got["r"].masks)

    walk.got = got  # type: ignore[attr-defined]
    return walk, parts


def _time_cached(culling: Culling, frame: Frame, boxes: dict[int, Any], proj: NDArray[np.float64],
                 fog_m: float) -> tuple[float, float, int, dict[int, NDArray[np.bool_]]]:
    """:func:`_time` of a :func:`_cache_culling` pair: the cache's own split of its CPU seconds."""
    walk, _parts = culling
    walk.got["boxes"] = boxes  # type: ignore[attr-defined]
    graph, start, eye, view = frame
    t0 = time.process_time()
    walk(graph, start, eye, view, proj, SIZE, fog_m=fog_m)
    total = time.process_time() - t0
    r = walk.got["r"]  # type: ignore[attr-defined]
    return total - r.parts_s, r.parts_s, len(r.order), dict(r.masks)


def _ms(x: Sequence[float]) -> dict[str, float]:
    a = 1e3 * np.asarray(x, np.float64)
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99))}


def cull_cpu_rows(seeds: Sequence[int], out: Path, *, against: str | None = None, hall_frames: int = 120,
                  repeats: int = 2, cache: bool = False,
                  log: Callable[[str], None] = lambda s: None) -> list[dict[str, Any]]:
    """The culling's CPU time on the hall, the hall walked and the tours of ``seeds`` (module
    docstring): a row per scene with the frames, the visible cells and per part (``walk``,
    ``parts``, ``total``) the median and p99 milliseconds, now and (``against``) at that
    revision; with ``cache``, now is the culling reused frame to frame (its ``misses``
    counted) and the other each frame culled anew (``against``'s, or today's, labelled
    ``anew``).  Each frame is culled ``repeats`` times over (every frame once, then again)."""
    exact: Culling = (portals.cull_portals, partcull.cull_parts)
    then = culling_at(against) if against else (exact if cache else None)
    label = against if against else ("anew" if cache else None)
    proj = perspective(60.0, SIZE[0] / SIZE[1], 0.1, 1000.0).astype(np.float64)
    scenes: list[tuple[str, Callable[[], Any]]] = [("hall 16x16", lambda: _hall_frames(hall_frames)),
                                                   ("hall walk", lambda: _hall_walk(hall_frames))]
    scenes += [(f"seed {s}", functools.partial(_seed_frames, s, out, log)) for s in seeds]
    if cache:  # consecutive frames of a tour, where reuse can pay: 25 a second over a minute
        scenes += [(f"seed {s} walk", functools.partial(_seed_frames, s, out, log, 1.0 / 25.0, span=WALK_SPAN_S))
                   for s in seeds]
    rows = []
    for name, make in scenes:
        frames, boxes, fog, locate = make()
        cached = CullCache(frames[0][0], locate=locate) if cache and frames else None
        now = _cache_culling(cached) if cached is not None else exact
        log(f"bench portals: culling CPU, {name}, {len(frames)} frames x {repeats}")
        got: dict[str, dict[str, list[float]]] = {w: {"walk": [], "parts": [], "total": []} for w in ("now", "then")}
        visible = []
        parts_kept = {"now": 0, "then": 0}
        dropped = 0
        for culling in (now, then):
            # warm up (first calls, the packed boxes) untimed; not the cache: its first guard is timed
            if culling is not None and (cached is None or culling is not now):
                _time(culling, frames[0], boxes, proj, fog)
        pair = [("now", now), ("then", then)] if then is not None else [("now", now)]
        for r in range(repeats):
            for i, f in enumerate(frames):
                # the two take turns at going first: the one timed second may find the
                # frame's arrays in the cache (the same code read 0-6 % apart by column)
                kept: dict[str, dict[int, NDArray[np.bool_]]] = {}
                for who, culling in pair if (r + i) % 2 == 0 else pair[::-1]:
                    timer = _time_cached if who == "now" and cached is not None else _time
                    w, p, n, kept[who] = timer(culling, f, boxes, proj, fog)
                    got[who]["walk"].append(w)
                    got[who]["parts"].append(p)
                    got[who]["total"].append(w + p)
                    parts_kept[who] += sum(int(m.sum()) for m in kept[who].values())
                    if who == "now":
                        visible.append(n)
                # conservative: today's culling keeps every part the other keeps (a superset:
                # rectangles grown outward may keep a few more)
                if "then" in kept:
                    lost = sum(int(m.sum()) if c not in kept["now"] else int((m & ~kept["now"][c]).sum())
                               for c, m in kept["then"].items())
                    if lost and cached is None:
                        raise WalkstreamError(f"bench portals: {name}: the culling now drops parts the culling "
                                              f"{label} keeps")
                    # the cache's guard tests rays, not the frame's pixel grid: a part the frame's
                    # own rectangles keep by their rounding alone may be left out (the id truth
                    # decides: tests/test_cullcache.py); counted, not refused
                    dropped += lost
        row: dict[str, Any] = {"scene": name, "frames": len(frames) * repeats,
                               "visible_median": float(np.median(visible)), "visible_max": int(max(visible)),
                               "now": {k: _ms(v) for k, v in got["now"].items()}}
        if then is not None:
            row["then"] = {k: _ms(v) for k, v in got["then"].items()}
            row["against"] = label
        if cached is not None:
            row["misses"] = cached.misses
            row["dropped"] = dropped
        if then is not None:  # parts drawn, over every frame: what a looser answer costs the GPU
            row["kept"] = dict(parts_kept)
        rows.append(row)
    return rows


def cull_cpu_table(rows: Sequence[dict[str, Any]]) -> str:
    """The rows of :func:`cull_cpu_rows` as text: ms median / p99, then (``against``) the same
    at that revision and the ratio of the total medians."""
    against = next((r["against"] for r in rows if "against" in r), None)
    head = f"{'scene':<12}{'frames':>7}{'visible':>9}{'walk ms':>14}{'parts ms':>14}{'total ms':>14}"
    cached = any("misses" in r for r in rows)
    if cached:
        head += f"{'misses':>8}{'parts':>8}{'dropped':>8}"
    if against:
        head += f"  |{'before walk':>14}{'before parts':>14}{'before total':>14}{'speed-up':>9}"
    what = "each frame culled anew (today's)" if against == "anew" else f"the culling at {against}"
    out = ["culling CPU per frame (time.process_time; median / p99; 640x480)"
           + ("; now = reused frame to frame (shared/cullcache.py), its misses, the parts it keeps"
              " over those kept anew, and the parts kept anew it left out (all frames)" if cached else "")
           + (f"; before = {what}, timed alternately" if against else "") + ":", head]

    def mp(r: dict[str, float]) -> str:
        return f"{r['median']:.2f} / {r['p99']:.2f}"

    for r in rows:
        lo, hi = round(r["visible_median"]), r["visible_max"]
        line = (f"{r['scene']:<12}{r['frames']:>7}{f'{lo}-{hi}' if lo != hi else str(hi):>9}{mp(r['now']['walk']):>14}"
                f"{mp(r['now']['parts']):>14}{mp(r['now']['total']):>14}")
        if cached:
            kept = r.get("kept", {})
            more = kept["now"] / kept["then"] if kept.get("then") else math.nan
            line += f"{r.get('misses', 0):>8}{more:>7.2f}x{r.get('dropped', 0):>8}"
        if "then" in r:
            t = r["then"]
            line += (f"  |{mp(t['walk']):>14}{mp(t['parts']):>14}{mp(t['total']):>14}"
                     f"{t['total']['median'] / r['now']['total']['median']:>8.2f}x")
        out.append(line)
    return "\n".join(out)
