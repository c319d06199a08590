"""The parts kept by their boxes, tested again by their triangles (shared/trianglecull.py).

The refinement must only ever drop a part none of whose triangles can draw a pixel centre
inside its cell's visible screen areas: checked here against a plain rasteriser of pixel
centres (numpy, no GL) on random triangles and rectangles; the GL truth checks it on whole
interiors through :mod:`portalscene` (every door of the generated office, FZK-Haus and the
duplex, the traps and the hypothesis-drawn interiors cull as the client does).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from walkstream.shared.camera import camera, perspective
from walkstream.shared.codec.cellhead import stand_in
from walkstream.shared.codec.cellmesh import CellMesh, CellPart
from walkstream.shared.partcull import cull_parts
from walkstream.shared.trianglecull import cell_triangles, refine_parts

SIZE = (160, 120)
PROJ = perspective(60.0, SIZE[0] / SIZE[1], 0.1, 60.0).astype(np.float64)
# at the origin looking along +x (yaw 0), eye height 0
VIEW = camera(np.zeros(3), 0.0, 0.0).astype(np.float64)


def _mesh(parts: list[CellPart], missing: tuple[int, ...] = ()) -> CellMesh:
    return CellMesh(tuple(parts), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0), missing=missing)


def _part(tris: np.ndarray) -> CellPart:
    t = np.asarray(tris, np.float64).reshape(-1, 3, 3)
    return CellPart(1, 0, t.reshape(-1, 3), np.arange(3 * len(t)).reshape(-1, 3))


def _boxes(m: CellMesh) -> tuple[np.ndarray, np.ndarray]:
    b = [p.bbox for p in m.parts]
    return np.array([x[0] for x in b]).reshape(-1, 3), np.array([x[1] for x in b]).reshape(-1, 3)


def _pixel(p: np.ndarray) -> np.ndarray:
    """World points (n, 3) to window coordinates (n, 2) (pixel i's centre at i + 0.5)."""
    h = np.c_[p, np.ones(len(p))] @ (PROJ @ VIEW).T
    ndc = h[:, :2] / h[:, 3:4]
    return (ndc + 1.0) / 2.0 * np.array(SIZE, np.float64)


def _covers(tri: np.ndarray, vsa: tuple[int, int, int, int]) -> bool:
    """Whether the triangle (3, 3), clipped at the near plane as GL clips it, covers a
    pixel centre of ``vsa`` (a plain rasteriser: every centre against every side)."""
    depth = -(np.c_[tri, np.ones(3)] @ VIEW.T)[:, 2] - 0.1
    poly = []
    for i in range(3):  # Sutherland-Hodgman against the near plane
        j = (i + 1) % 3
        if depth[i] >= 0:
            poly.append(tri[i])
        if (depth[i] >= 0) != (depth[j] >= 0):
            poly.append(tri[i] + (tri[j] - tri[i]) * depth[i] / (depth[i] - depth[j]))
    if len(poly) < 3:
        return False
    p = _pixel(np.array(poly))
    x0, y0, x1, y1 = vsa
    gx, gy = np.meshgrid(np.arange(x0, x1 + 1) + 0.5, np.arange(y0, y1 + 1) + 0.5)
    e = np.stack([(b[0] - a[0]) * (gy - a[1]) - (b[1] - a[1]) * (gx - a[0])
                  for a, b in zip(p, np.roll(p, -1, axis=0), strict=True)])
    return bool(np.any(np.all(e >= 0, axis=0) | np.all(e <= 0, axis=0)))


def test_a_part_whose_box_meets_the_area_but_none_of_its_triangles_is_dropped() -> None:
    # a narrow door rectangle in the middle of the view; part 0: two slivers left and
    # right of it, 5 m away (its box spans the door); part 1: a triangle in the door
    left = [[5.0, 1.5, -0.2], [5.0, 1.4, 0.2], [5.0, 1.5, 0.2]]
    right = [[5.0, -1.5, -0.2], [5.0, -1.4, 0.2], [5.0, -1.5, 0.2]]
    inside = [[5.0, 0.05, -0.05], [5.0, -0.05, -0.05], [5.0, 0.0, 0.05]]
    m = _mesh([_part(np.array([left, right])), _part(np.array([inside]))])
    vsas = {7: [(75, 50, 85, 70)]}
    masks = cull_parts("portals", [7], {7: _boxes(m)}, np.zeros(3), VIEW, PROJ, SIZE, vsas=vsas)
    assert masks[7].tolist() == [True, True]  # both boxes meet the door
    dropped = refine_parts(masks, {7: m}, vsas, VIEW, PROJ, SIZE, min_triangles=1)
    assert dropped == 1 and masks[7].tolist() == [False, True]
    # a triangle beside the door's corner: its screen box reaches into the door, its
    # hypotenuse passes 2 pixels outside the corner (x + y = 158 at pixels (83, 75),
    # (95, 75), (95, 63); the door's corner (85, 70))
    s = 2.0 * 5.0 * math.tan(math.radians(30.0)) / SIZE[1]  # a pixel at 5 m
    corner = np.array([[5.0, -(px + 0.5 - 80.0) * s, (py + 0.5 - 60.0) * s] for px, py in ((83, 75), (95, 75), (95, 63))])
    m = _mesh([_part(np.array([corner])), _part(np.array([inside]))])
    masks = cull_parts("portals", [7], {7: _boxes(m)}, np.zeros(3), VIEW, PROJ, SIZE, vsas=vsas)
    assert masks[7].tolist() == [True, True]
    assert refine_parts(masks, {7: m}, vsas, VIEW, PROJ, SIZE, min_triangles=1) == 1
    assert masks[7].tolist() == [False, True]
    # the default leaves parts of a few triangles as their boxes decided
    masks = {7: np.ones(2, bool)}
    assert refine_parts(masks, {7: m}, vsas, VIEW, PROJ, SIZE) == 0 and masks[7].all()


def test_a_sliver_under_a_pixel_is_dropped_and_a_triangle_round_the_eye_kept() -> None:
    # a baluster seen edge on 20 m away: 1 mm wide, between two pixel centres' columns
    # (a pixel is about 0.19 m wide there; the view's centre line is the boundary
    # between the two middle columns of pixel centres)
    sliver = [[20.0, 0.0005, -0.5], [20.0, -0.0005, -0.5], [20.0, 0.0, 0.5]]
    # a floor under the eye that reaches behind it (crosses the clip plane)
    floor = [[-3.0, -3.0, -1.0], [6.0, -3.0, -1.0], [6.0, 6.0, -1.0]]
    m = _mesh([_part(np.array([sliver])), _part(np.array([floor]))])
    masks = {1: np.ones(2, bool)}
    refine_parts(masks, {1: m}, {1: [(0, 0, SIZE[0] - 1, SIZE[1] - 1)]}, VIEW, PROJ, SIZE, min_triangles=1)
    assert masks[1].tolist() == [False, True]


def test_stand_ins_and_cells_without_areas_are_left_alone() -> None:
    far_off = [[5.0, 3.0, 2.0], [5.0, 3.1, 2.0], [5.0, 3.0, 2.1]]  # outside the area below
    m = _mesh([_part(np.array([far_off])), stand_in([4.0, -1.0, -1.0], [6.0, 1.0, 1.0])], missing=(1,))
    masks = {1: np.ones(2, bool), 2: np.ones(2, bool)}
    refine_parts(masks, {1: m, 2: m}, {1: [(70, 50, 90, 70)]}, VIEW, PROJ, SIZE, min_triangles=1)
    assert masks[1].tolist() == [False, True]  # the stand-in stays: its triangles are still to come
    assert masks[2].all()  # no visible screen areas: not the portal walk's to refine
    tri, start = cell_triangles(m)
    assert tri.shape == (3, 3, 1) and start.tolist() == [0, 1, 1]
    assert cell_triangles(m)[0] is tri  # packed once per mesh


def test_never_drops_a_part_that_covers_a_pixel_centre_of_its_area() -> None:
    rng = np.random.default_rng(24)
    kept_drawn = dropped = 0
    for _ in range(20):
        cells, meshes, vsas, covered = [], {}, {}, {}
        for c in range(4):
            parts, cov = [], []
            x0, y0 = int(rng.integers(0, SIZE[0] - 8)), int(rng.integers(0, SIZE[1] - 8))
            vsa = (x0, y0, min(SIZE[0] - 1, x0 + int(rng.integers(0, 60))), min(SIZE[1] - 1, y0 + int(rng.integers(0, 60))))
            for _p in range(6):
                n = int(rng.integers(1, 4))
                centre = np.array([rng.uniform(1.0, 12.0), 0.0, 0.0])
                centre[1:] = rng.uniform(-0.7, 0.7, 2) * centre[0]
                size = rng.choice([0.01, 0.1, 1.0])
                t = centre + rng.normal(0.0, size, (n, 3, 3))
                if rng.random() < 0.7:
                    t[..., 0] = np.maximum(t[..., 0], 0.2)  # beyond the near plane
                else:  # long triangles past the eye's side, across the clip plane
                    t[:, int(rng.integers(3)), 0] = rng.uniform(-3.0, 0.05, n)
                parts.append(_part(t))
                cov.append(any(_covers(tri, vsa) for tri in t))
            cells.append(c)
            meshes[c] = _mesh(parts)
            vsas[c] = [vsa]
            covered[c] = np.array(cov)
        masks = {c: np.ones(6, bool) for c in cells}
        refine_parts(masks, meshes, vsas, VIEW, PROJ, SIZE, min_triangles=1)
        for c in cells:
            assert not np.any(covered[c] & ~masks[c]), (c, vsas[c])
            kept_drawn += int(covered[c].sum())
            dropped += int((~masks[c]).sum())
    assert kept_drawn > 25 and dropped > 250  # both sides were exercised



def test_the_cli_turns_it_off_and_benches_it(office_db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import argparse

    from walkstream.cli import main
    from walkstream.cmd_replay import add_replay_arguments, config_from_args

    parser = argparse.ArgumentParser()
    add_replay_arguments(parser)
    parser.add_argument("--report", default="report")
    assert config_from_args(parser.parse_args([])).triangle_cull
    assert not config_from_args(parser.parse_args(["--no-triangle-cull"])).triangle_cull
    # the bench: parts and triangles the boxes keep, those the triangles keep (never more)
    assert main(["bench", "portals", "--triangles", str(office_db), "--step", "10", "--out", str(tmp_path), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["triangles"]
    assert [r["size"] for r in rows] == ["160x120", "640x480"] and rows[0]["poses"] >= 3
    for r in rows:
        assert 0 < r["tris_triangles"] < r["tris_boxes"] and r["parts_triangles"] < r["parts_boxes"]
        assert set(r["ms"]) == {"walk", "boxes", "triangles"}
    # a bad source is named in one line
    assert main(["bench", "portals", "--triangles", str(tmp_path / "nope.db"), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "nope.db" in err and "Traceback" not in err


def test_triangles_wholly_in_front_skip_the_clip_and_each_is_tested_as_alone() -> None:
    from trianglereference import _SIDE_ENDS, _clipped_ends, _shows

    from walkstream.shared.partcull import near_far

    rng = np.random.default_rng(7)
    n = 300
    centre = np.c_[rng.uniform(-2.0, 10.0, n), rng.uniform(-4.0, 4.0, n), rng.uniform(-2.0, 2.0, n)]
    tri = centre[:, None, :] + rng.normal(0.0, rng.choice([0.05, 0.5, 3.0], n)[:, None, None], (n, 3, 3))
    pts = np.ascontiguousarray(tri.transpose(2, 1, 0))  # (3, 3, n) coordinate-major
    m = (PROJ @ VIEW)[[0, 1, 3]]
    h = (m[:, :3] @ pts.reshape(3, -1) + m[:, 3:]).reshape(3, 3, n)
    d = h[2] - 0.03
    whole = (d >= 0).all(axis=0)
    assert 50 < whole.sum() < n - 50  # in front, across the plane and behind, all drawn
    # the exactness of the shortcut: a triangle wholly in front ends at its own vertices
    ex, ey = _clipped_ends(h[:, :, whole], d[:, whole], SIZE)
    q = h[:, _SIDE_ENDS][:, :, whole]
    assert np.array_equal(ex, np.clip((q[0] / q[2] + 1.0) * (0.5 * SIZE[0]) - 0.5, -1e9, 1e9))
    assert np.array_equal(ey, np.clip((q[1] / q[2] + 1.0) * (0.5 * SIZE[1]) - 0.5, -1e9, 1e9))
    # (4, k, n): each triangle's two VSAs, the second an empty pad
    vsa = np.ascontiguousarray(np.tile(np.array([[30, 20, 120, 90], [1, 1, 0, 0]], np.int64), (n, 1, 1)).transpose(2, 1, 0))
    planes = near_far(PROJ)
    assert planes is not None
    batch = _shows(pts, vsa, VIEW, PROJ, SIZE, 0.03, planes)
    alone = [bool(_shows(pts[:, :, i:i + 1], vsa[:, :, i:i + 1], VIEW, PROJ, SIZE, 0.03, planes)[0]) for i in range(n)]
    assert batch.tolist() == alone and 0 < batch.sum() < n


def test_the_plain_float_clip_and_the_two_rounds_keep_what_one_batch_keeps(monkeypatch: pytest.MonkeyPatch) -> None:
    import trianglereference as ref

    import walkstream.shared.trianglecull as tc

    rng = np.random.default_rng(11)
    n = 400
    centre = np.c_[rng.uniform(-1.0, 8.0, n), rng.uniform(-4.0, 4.0, n), rng.uniform(-2.0, 2.0, n)]
    tri = centre[:, None, :] + rng.normal(0.0, rng.choice([0.05, 0.5, 3.0], n)[:, None, None], (n, 3, 3))
    pts = np.ascontiguousarray(tri.transpose(2, 1, 0))
    m = (PROJ @ VIEW)[[0, 1, 3]]
    h = (m[:, :3] @ pts.reshape(3, -1) + m[:, 3:]).reshape(3, 3, n)
    d = h[2] - 0.03
    cut = np.flatnonzero(~(d >= 0).all(axis=0) & (d >= 0).any(axis=0))
    assert len(cut) > ref._FEW_CUT
    # the few triangles across the clip plane in plain floats: numpy's figures, bit for bit
    sx, sy = 0.5 * SIZE[0], 0.5 * SIZE[1]
    for a in range(0, len(cut), ref._FEW_CUT):
        few = cut[a:a + ref._FEW_CUT]
        got = ref._clipped_ends(h[:, :, few], d[:, few], SIZE)
        want = ref._clipped_ends_np(h[:, :, few], d[:, few], sx, sy)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
    # parts of many triangles, tested in two rounds (their first triangles, then the rest
    # of the parts none of whose first showed) or all in one batch: the same parts kept
    parts = [_part(tri[i:i + k]) for i, k in zip(range(0, n, 50), rng.integers(16, 50, n // 50), strict=False)]
    # slivers beside the area on both sides (the box spans it, no triangle meets it), and
    # the same with one triangle in the middle after the first round's
    side = np.array([[0.0, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]])
    beside = np.array([side + (5.0, -3.0 if i % 2 else 3.0, 0.05 * i - 1.0) for i in range(40)])
    middle = 50.0 * side + (5.0, 0.0, 0.0)
    parts += [_part(beside), _part(np.concatenate([beside, middle[None]])), _part(beside[::-1])]
    mesh = _mesh(parts)
    lo, hi = _boxes(mesh)
    vsas = {0: [(30, 20, 120, 90), (0, 0, 20, 10)]}
    kept = cull_parts("portals", [0], {0: (lo, hi)}, np.zeros(3), VIEW, PROJ, SIZE, vsas=vsas)
    assert kept[0].sum() >= 4 and kept[0][-3:].all()
    masks = {}
    for one_round in (10**9, 0):
        monkeypatch.setattr(tc, "_ONE_ROUND", one_round)
        masks[one_round] = {0: kept[0].copy()}
        refine_parts(masks[one_round], {0: mesh}, vsas, VIEW, PROJ, SIZE, min_triangles=1)
    assert np.array_equal(masks[0][0], masks[10**9][0])
    assert masks[0][0][-3:].tolist() == [False, True, False]  # kept by a triangle of the second round


def test_witnesses_the_table_and_the_shared_rectangles_keep_each_frames_parts(monkeypatch: pytest.MonkeyPatch) -> None:
    """A walk's frames, refined as the client does (the parts culling's rectangles shared,
    one triangle table whose witnesses carry from frame to frame, a table made anew when it
    would hold too much), keep frame for frame what each part's triangles decide alone."""
    import trianglereference as ref

    import walkstream.shared.trianglecull as tc
    import walkstream.shared.tritable as tt
    from walkstream.shared.partcull import PartRects, near_far
    from walkstream.shared.screenrects import box_rects

    rng = np.random.default_rng(5)
    cells: dict[int, CellMesh] = {}
    for c in range(3):  # clusters of small triangles round the view, some across the clip plane
        parts = []
        for _ in range(12):
            centre = np.array([rng.uniform(-0.5, 9.0), rng.uniform(-4.0, 4.0), rng.uniform(-2.0, 2.0)])
            k = int(rng.integers(16, 40))
            parts.append(_part(centre + rng.normal(0.0, rng.choice([0.02, 0.3, 1.5]), (k, 3, 3))))
        cells[c] = _mesh(parts)
    # a part of two clusters, seen left and right of the view: its witness fails each frame
    # the door's area moves from one half to the other, while the other cluster shows
    two = [np.array([5.0, y, 0.0]) + rng.normal(0.0, 0.05, (10, 3, 3)) for y in (1.5, -1.5)]
    cells[3] = _mesh([_part(np.concatenate(two))])
    boxes = {c: _boxes(m) for c, m in cells.items()}
    planes = near_far(PROJ)
    assert planes is not None
    table = tt.TriangleTable()
    monkeypatch.setattr(tc, "thread_table", lambda: table)
    dropped = witnessed = crossing = 0
    for i in range(10):  # turning and stepping a little each frame, the doors' areas moving
        eye = np.array([0.04 * i, 0.0, 0.0])
        view = camera(eye, 0.03 * i, 0.01 * i).astype(np.float64)
        s = 7 * (i % 3)
        vsas = {0: [(0, 0, SIZE[0] - 1, SIZE[1] - 1)], 1: [(40 + s, 30, 90 + s, 80), (100, 10 + s, 150, 40 + s)],
                2: [(60 - s, 50, 75 - s, 62)], 3: [(0, 0, 79, SIZE[1] - 1) if i % 2 else (80, 0, SIZE[0] - 1, SIZE[1] - 1)]}
        rects = PartRects()
        masks = cull_parts("portals", list(cells), boxes, eye, view, PROJ, SIZE, vsas=vsas, rects=rects)
        # the kept parts' shared rectangles are box_rects' own, those across the clip plane too
        order = list(cells)
        kept = np.concatenate([masks[c] for c in order])
        owner = np.concatenate([np.full(len(masks[c]), k) for k, c in enumerate(order)])[kept]
        local = np.concatenate([np.arange(len(masks[c])) for c in order])[kept]
        lo = np.concatenate([boxes[c][0] for c in order])[kept]
        hi = np.concatenate([boxes[c][1] for c in order])[kept]
        shared = tc._box_rects(rects, order, owner, local, lo, hi, view, PROJ, SIZE, 0.03)
        assert np.array_equal(shared.T, box_rects(lo, hi, view, PROJ, SIZE)[0])
        crossing += int((~rects.exact[np.asarray([rects.first[c] for c in order])[owner] + local]).sum())
        # the reference: every candidate part's triangles (each one's test its own)
        want = {}
        for c, m in masks.items():
            keep = m.copy()
            lo, hi = boxes[c]
            rect, _front = box_rects(lo, hi, view, PROJ, SIZE)
            tri, start = cell_triangles(cells[c])
            for p in np.flatnonzero(m):
                r = rect[p]
                inside = any(r[0] >= v[0] and r[1] >= v[1] and r[2] <= v[2] and r[3] <= v[3]
                             and r[2] - r[0] >= tc.WIDE_PX - 1 and r[3] - r[1] >= tc.WIDE_PX - 1 for v in vsas[c])
                if inside:
                    continue
                a, b = int(start[p]), int(start[p + 1])  # the part's triangles, all of them
                v4 = np.repeat(np.array(vsas[c], np.int64).T[:, :, None], b - a, axis=2)
                keep[p] = bool(ref._shows(tri[:, :, a:b], v4, view, PROJ, SIZE, 0.03, planes).any())
            want[c] = keep
        witnessed += int((table.witness >= 0).sum())
        if i == 5:  # a table that must be made anew: it holds other cells (a walk's past)
            table.used = table.tri.shape[2]
            table._slot = {}
        dropped += refine_parts(masks, cells, vsas, view, PROJ, SIZE, rects=rects)
        assert {c: m.tolist() for c, m in masks.items()} == {c: m.tolist() for c, m in want.items()}, i
    assert dropped > 0 and witnessed > 0 and crossing > 0


def test_the_compiled_test_keeps_what_the_numpy_reference_keeps() -> None:
    """Each triangle a part of its own, tested by the compiled kernel and by the numpy
    reference (``_shows``): the same triangles shown, in front of, across and behind the
    clip plane, against two VSAs and a pad."""
    import trianglereference as ref

    import walkstream.shared.trianglecull as tc
    from walkstream.shared.partcull import near_far
    from walkstream.shared.trianglekernels import test_parts

    rng = np.random.default_rng(23)
    n = 400
    centre = np.c_[rng.uniform(-1.0, 9.0, n), rng.uniform(-4.0, 4.0, n), rng.uniform(-2.0, 2.0, n)]
    tri = centre[:, None, :] + rng.normal(0.0, rng.choice([0.02, 0.3, 2.0], n)[:, None, None], (n, 3, 3))
    pts = np.ascontiguousarray(tri.transpose(2, 1, 0))
    areas = [(30, 20, 120, 90), (0, 0, 20, 10), (1, 1, 0, 0)]
    vsa = np.ascontiguousarray(np.tile(np.array(areas, np.int64), (n, 1, 1)).transpose(2, 1, 0))
    planes = near_far(PROJ)
    assert planes is not None
    want = ref._shows(pts, vsa, VIEW, PROJ, SIZE, 0.03, planes)
    one = np.ones(n, np.int64)
    witness = np.full(n, -1, np.int64)
    brect = np.tile(np.array([[0], [0], [-1], [-1]], np.int64), (1, n))  # no box inside a VSA: all tested
    gone = test_parts(pts, np.arange(n), one, witness, np.arange(n), np.zeros(n, np.int64), brect,
                      np.array([areas], np.int64), np.array([2], np.int64), (PROJ @ VIEW)[[0, 1, 3]],
                      0.5 * SIZE[0], 0.5 * SIZE[1], 0.03, planes[0], planes[1], 0.125, tc.WIDE_PX, 10**9, 32)
    got = np.ones(n, bool)
    got[gone] = False
    assert got.tolist() == want.tolist() and 50 < want.sum() < n - 50
    assert ((witness == 0) == want).all()  # a triangle shown is its part's witness
