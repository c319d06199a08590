"""The pop at an impostor's switch (issue 27, "no pop at the switch"): the frame-to-frame change of a
switching building's pixels against plain motion, drawn by the client's own renderer; a hard switch
(no blend) pops where the blend does not.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest
import trimesh

from walkstream.client.draw.impostors import impostor_alpha
from walkstream.client.truth.pop import (
    PopMeter,
    held_impostors,
    held_objects,
    object_change,
    own_change,
    pop_frame,
    summarise_pop,
)
from walkstream.client.walk.impostors import quad_corners, toward_eye
from walkstream.shared.camera import look_at, perspective
from walkstream.shared.impostors import bin_of, directions
from walkstream.shared.records import Mesh


def test_object_change_counts_the_pixels_of_either_frame_once() -> None:
    a_rgb = np.zeros((2, 3, 3), np.uint8)
    b_rgb = a_rgb.copy()
    b_rgb[0, 0] = 255  # object 1's pixel turns white
    a_ids = np.array([[2, 2, 0], [0, 0, 0]], np.uint32)  # object 1 (id + 1 = 2) on two pixels
    b_ids = np.array([[2, 0, 2], [0, 0, 0]], np.uint32)  # ... moved: one kept, one left, one new
    change, count = object_change(a_rgb, a_ids, b_rgb, b_ids)
    assert count[2] == 3  # the union, the shared pixel once
    assert change[2] == pytest.approx(1.0 / 3.0)
    assert np.isnan(change[1])


def test_only_pairs_with_a_switch_count_and_an_unchanged_form_is_plain_motion() -> None:
    rgb, ids = np.zeros((4, 4, 3), np.uint8), np.zeros((4, 4), np.uint32)
    ids[:2], ids[2:] = 8, 9  # objects 7 and 8
    quad = (np.zeros((4, 3)), 3, np.zeros((1, 1, 4), np.uint8), 0.5)
    m = PopMeter()
    m.add(pop_frame(0, rgb, ids, [(7, 2), (8, 2)], []))
    m.add(pop_frame(1, rgb, ids, [(7, 2), (8, 2)], []))  # nothing switches: plain motion only
    assert m.pairs == 0 and not m.switching and len(m.plain) == 2
    lit = rgb.copy()
    lit[:2] = 255
    m.add(pop_frame(2, lit, ids, [(7, 2), (8, 2)], [(7, quad)]))  # 7 fades in its image, 8 stays
    s = summarise_pop(m)
    assert (s["pairs"], s["switching"], s["plain"]) == (1, 1, 3)
    assert s["switching_change_mean"] == pytest.approx(1.0) and s["plain_change_mean"] == 0.0
    assert s["ratio"] is None  # nothing moved: no plain motion to compare with
    assert s["kinds"]["blend"]["switching"] == 1 and s["kinds"]["image"]["switching"] == 0
    other = (quad[0], 4, quad[2], 0.5)
    m.add(pop_frame(3, lit, ids, [(7, 2), (8, 2)], [(7, other)]))  # another image, the same opacity
    assert m.kinds == ["blend", "image"] and m.pairs == 2


def test_a_negative_blend_is_one_clear_line() -> None:
    from walkstream.client.config import ReplayConfig
    from walkstream.client.net.link import LinkProfile
    from walkstream.shared.errors import InputError

    link = LinkProfile(56_000.0, 56_000.0, 0.2)
    with pytest.raises(InputError, match="--impostor-blend -1.0"):
        ReplayConfig(link=link, impostor_blend_m=-1.0)
    assert ReplayConfig(link=link, impostor_blend_m=0.0).impostor_blend_m == 0.0  # 0: a hard switch


def _box(cx: float, cy: float, half: float = 5.0, h: float = 20.0) -> tuple[tuple[float, ...], Mesh]:
    box = (cx - half, cy - half, 0.0, cx + half, cy + half, h)
    tm = trimesh.creation.box(bounds=np.reshape(box, (2, 3)))
    faces = np.asarray(tm.faces)
    normals = np.repeat(np.asarray(tm.face_normals), 3, axis=0)  # flat: three vertices a face
    return box, Mesh(np.asarray(tm.vertices)[faces.ravel()], normals, np.arange(faces.size).reshape(-1, 3))


def _measure(
    r: Any, meter: PopMeter, k: int, keys: list[Any], quads: list[Any], view: Any, proj: Any,
    prev: list[Any] | None = None,
) -> None:
    """Draw frame ``k`` with ``quads`` as the impostors and feed it to ``meter``; where the
    image painted, the ids show object 1 (drawn again without it to find those pixels);
    with ``prev`` (the quads of the frame before) the held frame too, as the replay draws it."""
    r.impostors = quads
    r.draw(keys, view, proj)
    rgb = r.snapshot()
    ids = r.draw_ids(keys, view, proj)
    if quads:
        r.impostors = []
        r.draw(keys, view, proj)
        ids = ids.copy()
        ids[np.any(r.snapshot() != rgb, axis=2)] = 2
    pf = pop_frame(k, rgb, ids, keys, [(1, q) for q in quads])
    held = None
    if prev is not None and meter.last is not None:
        held, objs = rgb, held_objects(meter.last, pf)
        if objs:
            r.impostors = [q for _, q in held_impostors([(1, q) for q in prev], [(1, q) for q in quads], objs)]
            r.draw(keys, view, proj)
            held = r.snapshot()
    meter.add(pf, held)


def _walk(gl: Any, blend_m: float) -> dict[str, Any]:
    """A viewer walking 30 m towards two buildings 100 m ahead; the left one (object 1) goes from
    its image (a flat red) to its geometry across ``D`` = 70 m over ``blend_m``, the right one
    (object 2) is geometry throughout; each frame drawn by the client's renderer and measured."""
    from walkstream.client.draw.frames import FrameRenderer

    (box_a, mesh_a), (_, mesh_b) = _box(-8.0, 100.0), _box(8.0, 100.0)
    image = np.zeros((8, 8, 4), np.uint8)
    image[...] = (230, 40, 30, 255)
    size = (96, 72)
    proj = perspective(50.0, size[0] / size[1], 0.5, 400.0)
    r = FrameRenderer(size=size, fov_deg=50.0, ctx=gl)
    meter = PopMeter()
    quads: list[Any] = []
    try:
        r.upload((1, 2), mesh_a)
        r.upload((2, 2), mesh_b)
        for k, y in enumerate(np.linspace(0.0, 30.0, 61)):
            prev = quads
            eye = np.array([0.0, y, 1.7])
            view = look_at(eye, np.array([0.0, 100.0, 8.0]))
            alpha = float(impostor_alpha(box_a[1] - y, 0.0, 70.0, 1.0, blend_m))
            lo, hi = np.asarray(box_a[:3]), np.asarray(box_a[3:])
            ia, ie = bin_of(2, *directions(eye, (lo + hi) / 2.0))
            quads = [(quad_corners(box_a, 2, int(ia), int(ie)), 1, image, alpha)] if alpha > 0 else []
            keys = [(1, 2), (2, 2)] if alpha < 1 else [(2, 2)]
            _measure(r, meter, k, keys, quads, view, proj, prev)
    finally:
        r.release()
    return summarise_pop(meter)


@pytest.mark.gl
def test_a_hard_switch_pops_where_the_blend_does_not(gl: Any) -> None:
    blended, hard = _walk(gl, 20.0), _walk(gl, 0.0)
    assert hard["pairs"] == 1 and blended["pairs"] > 10  # the blend spreads the switch over its frames
    assert blended["ratio"] is not None and hard["ratio"] is not None
    assert hard["ratio"] > 10.0 * blended["ratio"]  # here 68 against 2.5 (a saturated image over grey)
    assert hard["kinds"]["hard"]["switching"] == 1 and blended["kinds"]["hard"]["switching"] == 0
    assert hard["switching_change_mean"] > 5.0 * blended["switching_change_mean"]
    # against its own motion on the same frames (the held frame): the blend adds less than the
    # motion does; the hard switch has no held frame (geometry to image alone), so no own figure
    assert blended["own"]["switching"] > 10 and blended["ratio_own"] is not None
    assert blended["own"]["switch_change_mean"] < blended["switching_change_mean"]
    assert hard["ratio_own"] is None and hard["own"]["switching"] == 0


def test_the_own_change_splits_a_frame_into_the_switch_and_the_motion() -> None:
    prev, cur = np.zeros((1, 4, 3), np.uint8), np.zeros((1, 4, 3), np.uint8)
    ids = np.array([[8, 8, 0, 0]], np.uint32)  # object 7 on two pixels
    held = prev.copy()
    held[0, 0] = 255  # the motion alone: one pixel turns white
    cur[0, 0], cur[0, 1] = 255, 255  # the switch turns the other white too
    switch, motion, count = own_change(prev, ids, held, cur, ids)
    assert count[8] == 2 and switch[8] == pytest.approx(0.5) and motion[8] == pytest.approx(0.5)
    quad = (np.zeros((4, 3)), 3, np.zeros((1, 1, 4), np.uint8), 0.5)
    m = PopMeter()
    m.add(pop_frame(0, prev, ids, [(7, 2), (9, 2)], [(7, quad)]))
    m.add(pop_frame(1, cur, ids, [(7, 2), (9, 1)], [(7, (*quad[:3], 0.6)), (9, quad)]), held)
    s = summarise_pop(m)
    assert s["ratio_own"] == pytest.approx(1.0) and s["own"]["switching"] == 1
    # object 9 fades in with its geometry's LOD changing (2 to 1): the held frame draws this
    # frame's LOD, so it cannot hold it: counted apart, left out of the own figure
    assert s["own"]["lod_changed"] == 1
    m.add(pop_frame(2, cur, ids, [(7, 2), (9, 2)], [(7, (*quad[:3], 0.6)), (9, (*quad[:3], 0.7))]), cur)
    assert summarise_pop(m)["own"]["lod_changed"] == 2 and summarise_pop(m)["own"]["switching"] == 1
    assert held_impostors([(7, "old"), (9, "b")], [(7, "new"), (9, "c")], [7]) == [(9, "c"), (7, "old")]


def test_the_fade_moves_the_opacity_at_most_its_rate_fades_a_leaving_building_out_and_cross_fades_images() -> None:
    from types import SimpleNamespace

    from walkstream.client.draw.impostors import FADE_S, fade_towards
    from walkstream.client.walk.impostors import DrawnImpostor, _faded

    assert fade_towards(0.0, 1.0, 0.04, 1.0) == pytest.approx(0.04)  # an image arriving: one frame's step
    assert fade_towards(0.5, 0.52, 0.04, 1.0) == 0.52  # the distance blend, slower than the rate: as it is
    assert fade_towards(1.0, 0.0, 0.04, 0.0) == 0.0  # no fade: a hard switch
    held = {7}
    lane = SimpleNamespace(held=lambda image: image in held)
    w: Any = SimpleNamespace(scene=SimpleNamespace(images=lane), config=SimpleNamespace(impostor_fade_s=None),
                             impostors_shown={}, impostors_old={}, impostors_wt=-math.inf)
    d = DrawnImpostor(3, 7, 1.0, np.zeros((4, 3)), 256)
    first = _faded(w, SimpleNamespace(wt=0.0), {3: d})
    assert [x.alpha for x in first] == [1.0]  # the first frame: nothing to fade from
    # the next cell does not list building 3: it fades out on image 7, not off in one frame
    frames = [_faded(w, SimpleNamespace(wt=0.04 * k), {}) for k in range(1, int(FADE_S / 0.04) + 5)]
    alphas = [f[0].alpha if f else 0.0 for f in frames]
    assert all(f[0].image == 7 for f in frames if f)
    assert alphas[0] == pytest.approx(1.0 - 0.04 / FADE_S) and alphas[-1] == 0.0
    assert max(-np.diff([1.0, *alphas])) <= 0.04 / FADE_S + 1e-9
    # the viewer crosses into another bin: image 8 cross-fades over image 7
    held.add(8)
    w.impostors_shown, w.impostors_old, w.impostors_wt = {3: d}, {}, 5.0
    new = dataclasses.replace(d, image=8)
    cross = [_faded(w, SimpleNamespace(wt=5.0 + 0.04 * k), {3: new}) for k in range(1, int(FADE_S / 0.04) + 3)]
    assert [q.image for q in cross[0]] == [7, 8] and cross[0][0].alpha == 1.0  # the old under, whole
    assert cross[0][1].alpha == pytest.approx(0.04 / FADE_S)  # the new over it, rising
    assert [q.image for q in cross[-1]] == [8] and cross[-1][0].alpha == 1.0
    # at a partial opacity the geometry keeps 1 - a, the old image a (1 - t), the new a t
    w.impostors_shown, w.impostors_old, w.impostors_wt = {3: dataclasses.replace(d, alpha=0.5)}, {}, 9.0
    under, over = _faded(w, SimpleNamespace(wt=9.0 + FADE_S / 4), {3: dataclasses.replace(new, alpha=0.5)})
    t = 0.25
    assert over.alpha == pytest.approx(0.5 * t) and under.alpha * (1 - over.alpha) == pytest.approx(0.5 * (1 - t))
    w.impostors_shown, w.impostors_old = {3: d}, {}
    held.clear()  # an image the lane no longer holds cannot fade out: geometry at once
    assert _faded(w, SimpleNamespace(wt=10.0), {}) == []


def _arrival(gl: Any, fade_s: float) -> tuple[dict[str, Any], PopMeter]:
    """A viewer walking 10 m in 2.4 s at 25 fps towards a building 100 m ahead (object 1) that is
    beyond ``D`` plus the blend throughout; its image arrives at frame 10 (before: geometry only)
    and is drawn at the opacity :func:`fade_towards` gives.  Object 2, a building 25 m ahead to the
    right, is geometry throughout (plain motion).  The image is the bake's own (its renderer, from
    the bin's direction), a tenth darker: a facade's windows, as a baked image differs from a box."""
    from walkstream.client.draw.frames import FrameRenderer
    from walkstream.client.draw.impostors import fade_towards
    from walkstream.server.bake.impostorrender import ImpostorRenderer
    from walkstream.shared.impostors import bin_direction

    (box_a, mesh_a), (_, mesh_b) = _box(-3.0, 100.0), _box(12.0, 25.0)
    lo, hi = np.asarray(box_a[:3]), np.asarray(box_a[3:])
    ia, ie = (int(v) for v in bin_of(2, *directions(np.array([0.0, 0.0, 1.7]), (lo + hi) / 2.0)))
    bake = ImpostorRenderer([mesh_a], [1], [box_a], ctx=gl)
    try:
        image = bake.render(1, bin_direction(2, ia, ie), 64)
    finally:
        bake.release()
    image[..., :3] = np.round(0.9 * image[..., :3])
    size = (96, 72)
    proj = perspective(50.0, size[0] / size[1], 0.5, 400.0)
    r = FrameRenderer(size=size, fov_deg=50.0, ctx=gl)
    meter, shown, dt = PopMeter(), 0.0, 1.0 / 25.0
    try:
        r.upload((1, 2), mesh_a)
        r.upload((2, 2), mesh_b)
        for k, y in enumerate(np.linspace(0.0, 10.0, 61)):
            eye = np.array([0.0, y, 1.7])
            assert (ia, ie) == tuple(int(v) for v in bin_of(2, *directions(eye, (lo + hi) / 2.0)))
            view = look_at(eye, np.array([0.0, 100.0, 8.0]))
            shown = fade_towards(shown, 1.0 if k >= 10 else 0.0, dt, fade_s)
            quads = [(toward_eye(quad_corners(box_a, 2, ia, ie), eye, box_a), 1, image, shown)] if shown > 0 else []
            keys = [(1, 2), (2, 2)] if shown < 1 else [(2, 2)]
            _measure(r, meter, k, keys, quads, view, proj)
    finally:
        r.release()
    return summarise_pop(meter), meter


@pytest.mark.gl
def test_an_image_arriving_beyond_the_blend_fades_in_rather_than_pops(gl: Any) -> None:
    from walkstream.client.draw.impostors import FADE_S

    (faded, meter), (hard, _) = _arrival(gl, FADE_S), _arrival(gl, 0.0)
    assert hard["kinds"]["hard"]["switching"] == 1 and faded["kinds"]["hard"]["switching"] == 0
    assert hard["ratio"] > 2.0, hard  # without the fade: the image appears in one frame
    assert faded["ratio"] <= 1.0, faded  # with it: no more change a frame than plain motion
    # no frame of the fade holds most of the switch either: with the quad through the building's
    # centre its own faces hid the image until the geometry went (the last frame then changed
    # 0.10, three quarters of the hard switch's 0.13; here at most a fifth, its edges moving)
    assert max(meter.switching) <= 0.3 * hard["switching_change_mean"], meter.switching


def test_the_quad_stands_in_front_of_its_own_building_on_the_same_pixels() -> None:
    box = (-5.0, 95.0, 0.0, 5.0, 105.0, 20.0)
    eye = np.array([3.0, 0.0, 1.7])
    lo, hi = np.asarray(box[:3]), np.asarray(box[3:])
    ia, ie = (int(v) for v in bin_of(2, *directions(eye, (lo + hi) / 2.0)))
    at, front = quad_corners(box, 2, ia, ie), toward_eye(quad_corners(box, 2, ia, ie), eye, box)
    rays_at, rays_front = at - eye, front - eye
    # the same rays from the eye (the same pixels), nearer than every corner of the box
    assert np.allclose(rays_at / np.linalg.norm(rays_at, axis=1)[:, None],
                       rays_front / np.linalg.norm(rays_front, axis=1)[:, None])
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    assert (front - eye)[:, 1].max() <= (corners - eye)[:, 1].min() + 1e-9  # in front along the view
    assert (at - eye)[:, 1].min() > (corners - eye)[:, 1].min()  # the quad through the centre was not


def test_a_building_the_next_cell_does_not_list_blends_on_by_its_distance() -> None:
    """Walking towards a building at D 100 m (blend 20 m, 2 m/s, 25 fps), the cell changes at 108 m
    to one that does not list it (a point of the new cell is within D of it): its opacity keeps
    following the blend by the eye's distance to 0 at D, on the row of the cell that listed it,
    rather than falling at the 2 s fade's rate (three times the blend's steepest here)."""
    from types import SimpleNamespace

    from walkstream.client.draw.impostors import FADE_S
    from walkstream.client.walk.impostors import frame_impostors
    from walkstream.shared.impostorwire import CellImpostors, ImpostorRow

    d, blend, bound = 100.0, 20.0, 0.5  # a wide bound: the error blend stays 1 throughout
    row = ImpostorRow(5, 0, 0, 8, 0, 4, (-5.0, -5.0, 0.0, 5.0, 5.0, 20.0), tuple(range(100, 132)))  # every bin
    cells = {1: SimpleNamespace(impostors=CellImpostors(d, bound, (row,))),
             2: SimpleNamespace(impostors=CellImpostors(d, bound, ()))}
    wanted: list[int] = []
    lane = SimpleNamespace(started=True, held=lambda i: True, image=lambda i: SimpleNamespace(nbytes=1024),
                           want=lambda wants: wanted.extend(wants))
    # the building is 7 degrees across at 100 m: no size limit here, the distance's blend alone is tested
    cfg = SimpleNamespace(impostor_blend_m=blend, impostor_perspective=False, prefetch=False,
                          texture_budget_bytes=1 << 30, impostor_fade_s=None, impostor_max_size_deg=math.inf)
    w: Any = SimpleNamespace(scene=SimpleNamespace(streets=SimpleNamespace(cells=cells), images=lane), config=cfg,
                             impostors_shown={}, impostors_old={}, impostors_wt=-math.inf, impostor_rows={},
                             objects=SimpleNamespace(pvs=[5]))
    alphas, expected = [], []
    for k in range(int(25 / 0.08)):  # 117 m to 92 m from the box
        dist = 117.0 - 0.08 * k - 5.0
        f = SimpleNamespace(street=1 if dist > 108.0 else 2, eye=np.array([dist + 5.0, 0.0, 1.7]), wt=0.04 * k)
        wanted.clear()
        drawn = frame_impostors(w, f)
        assert len(drawn) <= 1 and (f.street == 1 or not wanted)  # a kept building wants no image
        alphas.append(drawn[0].alpha if drawn else 0.0)
        expected.append(float(impostor_alpha(dist, 0.0, d, bound, blend)))
    assert alphas == pytest.approx(expected, abs=1e-9)  # the blend by distance, on both sides of the border
    assert max(-np.diff(alphas)) < 0.5 * 0.04 / FADE_S  # never the fade's rate
    assert alphas[-1] == 0.0 and w.impostor_rows == {}  # at D: geometry, the row let go
    # a building the new cell's PVS does not hold is not kept: it fades out on its image as before
    w.impostors_shown, w.impostor_rows, w.impostors_wt, w.objects.pvs = {}, {}, -math.inf, []
    alphas = []
    for k in range(40):
        f = SimpleNamespace(street=1 if k < 10 else 2, eye=np.array([122.0 - 0.08 * k, 0.0, 1.7]), wt=0.04 * k)
        alphas.append(max((q.alpha for q in frame_impostors(w, f)), default=0.0))
    assert alphas[9] > 0.8 and alphas[10] == pytest.approx(alphas[9] - 0.04 / FADE_S)


def test_a_building_under_its_blending_image_keeps_its_lod() -> None:
    from types import SimpleNamespace

    from walkstream.client.draw.allocate import Allocation
    from walkstream.client.walk.impostors import DrawnImpostor, hold_blend_lods

    geoms = [SimpleNamespace(id=i) for i in (3, 4, 5)]
    tri = np.array([[12, 100, 900]] * 3, np.int64)
    avail = np.array([[True, True, False], [True, True, True], [True, True, True]])
    w: Any = SimpleNamespace(objects=SimpleNamespace(geoms=geoms, tri=tri, avail=avail), blend_lods={})

    def frame(lods: list[int], alphas: dict[int, float]) -> Any:
        lod = np.array(lods, np.int8)
        f = SimpleNamespace(alloc=Allocation(lod, int(tri[np.arange(3), lod].sum()), False, False),
                            impostors=[DrawnImpostor(o, 9, a, np.zeros((4, 3)), 64) for o, a in alphas.items()])
        hold_blend_lods(w, f)
        return f.alloc

    frame([1, 1, 1], {3: 0.5, 5: 1.0})  # 3 blends at LOD 1; 5 is its image alone
    a = frame([0, 0, 2], {3: 0.49, 5: 1.0})  # the budget moves 3 to LOD 0: down, taken
    assert a.lod.tolist() == [0, 0, 2] and a.triangles == 12 + 12 + 900
    a = frame([1, 1, 2], {3: 0.48})  # and back to 1: kept at 0, its triangles counted
    assert a.lod.tolist() == [0, 1, 2] and a.triangles == 12 + 100 + 900
    a = frame([1, 0, 2], {})  # the blend over: the allocation's LOD again
    assert a.lod.tolist() == [1, 0, 2] and w.blend_lods == {}
