"""The seam at a virtual wall's zone border (issue 28, "no visible seam at a zone border"): the
two zones' textures blend around the border, the frame-to-frame change of the wall's pixels
across it is measured against plain motion on the client's own renderer, and a hard swap
shows a seam where the blend does not.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from walkstream.client.config import ReplayConfig
from walkstream.client.draw.quads import warped
from walkstream.client.net.link import LinkProfile
from walkstream.client.truth.pop import summarise_pop
from walkstream.client.truth.seam import (
    SEAM_KINDS,
    SeamMeter,
    SeamWall,
    seam_figures,
    still_quads,
    wall_pixels,
)
from walkstream.client.walk.walls import DrawnWall, wall_quads
from walkstream.shared.camera import look_at, perspective
from walkstream.shared.errors import InputError
from walkstream.shared.walls import EYE_HEIGHT, WallSide, WallTable, zone_mix, zone_slide, zone_warp

_SIDE = WallSide(0, 0, (-6.0, 5.0), (6.0, 5.0), 0.0, 3.0, 0.0, 1.0, 1.0, 3.0, float(np.radians(10.0)), 4,
                 (10, 11, 12, 13))
"""A wall 12 m long, 5 m ahead of a viewer on the x axis, in four zones 3 m wide."""


def _picture(along: float, band: float) -> dict[int, float]:
    """The share of each zone's texture a viewer ``along`` metres from ``p0`` sees."""
    zone = _SIDE.view([along - 6.0, 0.0, EYE_HEIGHT]).zone
    nb, share = zone_mix(along, _SIDE.length / _SIDE.zones, _SIDE.zones, band)
    out = {zone: 1.0 - float(share)}
    if int(nb) >= 0:
        out[int(nb)] = out.get(int(nb), 0.0) + float(share)
    return out


def test_the_zone_blend_is_continuous_across_a_border_and_off_away_from_it() -> None:
    for border in (3.0, 6.0, 9.0):
        left, right = _picture(border - 1e-6, 0.5), _picture(border + 1e-6, 0.5)
        assert left.keys() == right.keys() and all(abs(left[k] - right[k]) < 1e-5 for k in left)
        assert abs(left[int(border / 3.0) - 1] - 0.5) < 1e-5  # both zones weigh the same on the border
    assert _picture(4.5, 0.5) == {1: 1.0}  # a zone's middle: its own texture alone
    assert _picture(3.0 + 0.75 + 1e-6, 0.5) == {1: 1.0}  # the band ends a quarter zone from the border
    assert _picture(0.2, 0.5) == {0: 1.0} and _picture(11.8, 0.5) == {3: 1.0}  # the wall's ends: no neighbour
    assert _picture(3.0 - 1e-6, 0.0) == {0: 1.0} and _picture(3.0 + 1e-6, 0.0) == {1: 1.0}  # 0: a hard swap
    # the table's foot on the wall is the side's
    assert np.allclose(WallTable([_SIDE]).along_of([[-1.5, 0.0, EYE_HEIGHT]]), [[4.5]])
    link = LinkProfile(56_000.0, 56_000.0, 0.2)
    with pytest.raises(InputError, match="--wall-zone-blend 1.5"):
        ReplayConfig(link=link, wall_zone_blend=1.5)


def test_slid_textures_agree_on_the_border_for_points_as_deep_as_the_viewer_stands() -> None:
    w, x = 3.0, 5.0  # zone width, the viewer's distance from the wall
    # on the sampling line nothing slides; on a border the two zones slide apart by w share
    assert float(zone_slide(4.5, 1, w, 0.5)) == 0.0
    left, right = zone_slide(6.0, np.array([1, 2]), w, 0.5)
    assert left == pytest.approx(0.75) and right == pytest.approx(-0.75)
    assert float(zone_slide(6.0, -1, w, 0.5)) == 0.0  # no neighbour: nothing
    # a point P at depth p = x behind the wall: each zone's texture shows it where the ray
    # from its sampling point meets the wall; slid, both agree with where the viewer sees it
    p, px, viewer = x, 7.3, 6.0
    seen = viewer + (px - viewer) * x / (x + p)
    for zone, slide in ((1, left), (2, right)):
        c = (zone + 0.5) * w
        assert c + (px - c) * x / (x + p) + slide == pytest.approx(seen)
    # the quad's texture coordinates: slid right by a quarter of a 12 m wall
    corners = _SIDE.corners()
    uv = warped(corners, (1.0, -3.0, 0.0))  # slid by 3 m: scale 1, the texture 3 m on
    assert uv.shape == (4, 5) and np.allclose(uv[:, :3], corners)
    assert np.allclose(uv[:, 3], [-0.25, 0.75, 0.75, -0.25]) and warped(corners, (1.0, -0.0, 0.0)) is corners
    link = LinkProfile(56_000.0, 56_000.0, 0.2)
    with pytest.raises(InputError, match="--wall-parallax 1.5"):
        ReplayConfig(link=link, wall_parallax=1.5)


def test_a_blended_wall_is_two_quads_that_compose_the_cross_fade() -> None:
    a_rgb, b_rgb, bg = np.array([0.9, 0.2, 0.1]), np.array([0.1, 0.3, 0.8]), np.array([0.4, 0.4, 0.4])
    images = {10: a_rgb, 11: b_rgb}
    for alpha, mix in ((1.0, 0.5), (1.0, 0.2), (0.6, 0.4), (0.3, 0.0)):
        d = DrawnWall(0, 0, 0, 10, alpha, _SIDE.corners(), 0, (0, 1), 11, mix)
        out = bg.copy()
        quads = wall_quads([d], images.get)
        assert len(quads) == (2 if mix > 0 else 1)
        for _c, key, rgb, a in quads:  # premultiplied "over", as the quad renderer blends
            assert images[-1 - key] is rgb
            out = a * rgb + (1.0 - a) * out
        assert np.allclose(out, alpha * ((1.0 - mix) * a_rgb + mix * b_rgb) + (1.0 - alpha) * bg)


def _texture(zone: int) -> np.ndarray:
    """Zone ``zone``'s picture: stripes shifted a fifth of a period a zone (as the parallax
    of what lies behind shifts it from one sampling point to the next)."""
    x = np.arange(48) / 48.0
    v = 0.5 + 0.4 * np.sin(2.0 * np.pi * (4.0 * x - 0.2 * zone))
    img = np.zeros((16, 48, 4), np.uint8)
    img[..., 0] = (255 * v)[None, :]
    img[..., 1] = (255 * (1.0 - v))[None, :]
    img[..., 2] = 90
    img[..., 3] = 255
    return img


def _walk(gl: Any, band: float, parallax: float = 0.0) -> dict[str, Any]:
    """A viewer walking 9 m along the wall, 5 m from it, looking at it, across three zone
    borders; each frame drawn by the client's renderer (the walls as the frame loop hands
    them over) and measured."""
    from walkstream.client.draw.frames import FrameRenderer

    images = {10 + k: _texture(k) for k in range(4)}
    size = (96, 72)
    proj = perspective(60.0, size[0] / size[1], 0.3, 100.0)
    r = FrameRenderer(size=size, fov_deg=60.0, ctx=gl)
    meter = SeamMeter()
    table = WallTable([_SIDE])
    try:
        for x in np.linspace(-4.5, 4.5, 91):
            eye = np.array([x, 0.0, EYE_HEIGHT])
            view = look_at(eye, np.array([x, 5.0, EYE_HEIGHT]))
            zones, dist, weights = table.views(eye[None])
            nb, share = zone_mix(table.along_of(eye)[0], table.width, table.zones, band)
            zone, alpha = int(zones[0, 0]), float(weights[0, 0])
            mix_image = _SIDE.textures[int(nb[0])] if nb[0] >= 0 else -1
            foot = float(table.along_of(eye)[0, 0])
            got = zone_warp(foot, EYE_HEIGHT, dist[0, 0], np.array([zone, max(int(nb[0]), 0)]), table.width[0],
                            table.depth[0], table.eye_z[0], parallax)
            warps = tuple((float(g[0]), float(g[1]), float(g[2])) for g in got)
            d = DrawnWall(0, 0, zone, _SIDE.textures[zone], alpha, _SIDE.corners(), 0, (0, 1), mix_image,
                          float(share[0]) if mix_image >= 0 else 0.0, (warps[0], warps[1]))
            walls = [SeamWall(d.portal, d.side, d.image, d.mix_image, d.mix, d.alpha, d.corners, d.warps)]
            still = None
            earlier = meter.earlier(walls)
            if earlier[0] is not None:  # the frame held still: the wall as the frame before showed it
                r.impostors = still_quads(walls, earlier, {k: images[k] for k in images})
                r.draw([], view, proj)
                still = r.snapshot()
            r.impostors = wall_quads([d], images.get)
            r.draw([], view, proj)
            rgb = r.snapshot()
            pixels = wall_pixels(walls, view, proj, np.full(size[::-1], np.inf))
            meter.add(rgb, walls, pixels, still)
    finally:
        r.release()
    return {**summarise_pop(meter, SEAM_KINDS), **seam_figures(meter)}


@pytest.mark.gl
def test_a_hard_swap_at_a_zone_border_shows_a_seam_where_the_blend_does_not(gl: Any) -> None:
    blended, hard = _walk(gl, 0.5), _walk(gl, 0.0)
    assert hard["pairs"] == 3 and hard["kinds"]["hard"]["switching"] == 3  # one frame per border
    assert blended["pairs"] > 3 * 10 and blended["kinds"]["hard"]["switching"] == 0  # spread over the band
    assert hard["plain"] > 0 and blended["plain"] > 0
    assert hard["ratio"] is not None and blended["ratio"] is not None
    assert blended["ratio"] <= 1.5 < 3.0 < hard["ratio"]
    assert hard["switching_change_mean"] > 3.0 * blended["switching_change_mean"]
    # held still, a switching wall's change splits into the camera's motion and the look's:
    # a hard swap is nearly all look, the blend's look is a fraction of its motion
    assert hard["split"] == 3 and blended["split"] == blended["switching"]
    assert hard["look_mean"] > 2.0 * hard["motion_mean"]
    assert blended["look_mean"] < blended["motion_mean"]
    # zone k's stripes are shifted 0.2 period (0.6 m) a zone as parallax shifts what stands
    # behind: slid by 0.2 of the offset (0.6 m over the 3 m between sampling lines) two
    # zones' textures meet on the border showing the same stripes, and the look's part
    # of the change there falls (0.0070 against 0.0118), as does the wall's plain motion
    # (the stripes move on the screen less than the wall); the ratio to plain motion does
    # not fall, as plain motion falls as much
    slid = _walk(gl, 0.5, 0.2)
    assert slid["look_mean"] < 0.75 * blended["look_mean"]
    assert slid["plain_change_mean"] < blended["plain_change_mean"]


