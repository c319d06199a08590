"""The colour error of the truth comparison (issue 27 item 4): CIEDE2000, PSNR, the client's picture, the figures."""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from walkstream.client.draw.meshes import AMBIENT, BACKGROUND_RGB
from walkstream.client.report.colour import ColourLog, summarise_colour
from walkstream.client.report.truth import (
    TruthLog,
    read_truth_csv,
    summarise_truth,
    write_truth_csv,
)
from walkstream.client.truth.colour import (
    COLOUR_CAUSES,
    PSNR_CAP_DB,
    VISIBLE_DE,
    compare_colour,
    delta_e_2000,
    psnr,
    srgb_to_lab,
)
from walkstream.client.truth.compare import CAUSES, compare_frame
from walkstream.client.truth.notes import FrameNote
from walkstream.client.truth.picture import client_picture, colour_error, forms_of
from walkstream.client.truth.render import TruthRenderer
from walkstream.server.sources.citygen import generate_city
from walkstream.server.sources.geojson import load_geojson_dict
from walkstream.shared.buildings import build_lods
from walkstream.shared.camera import camera
from walkstream.shared.errors import InputError
from walkstream.shared.palette import MATERIALS
from walkstream.shared.streets import build_street

# Sharma, Wu and Dalal (2005), "The CIEDE2000 color-difference formula: implementation
# notes, supplementary test data, and mathematical observations", Table 1: L1 a1 b1 L2 a2 b2 dE00
SHARMA = np.array([
    [50.0000, 2.6772, -79.7751, 50.0000, 0.0000, -82.7485, 2.0425],
    [50.0000, 3.1571, -77.2803, 50.0000, 0.0000, -82.7485, 2.8615],
    [50.0000, 2.8361, -74.0200, 50.0000, 0.0000, -82.7485, 3.4412],
    [50.0000, -1.3802, -84.2814, 50.0000, 0.0000, -82.7485, 1.0000],
    [50.0000, -1.1848, -84.8006, 50.0000, 0.0000, -82.7485, 1.0000],
    [50.0000, -0.9009, -85.5211, 50.0000, 0.0000, -82.7485, 1.0000],
    [50.0000, 0.0000, 0.0000, 50.0000, -1.0000, 2.0000, 2.3669],
    [50.0000, -1.0000, 2.0000, 50.0000, 0.0000, 0.0000, 2.3669],
    [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0009, 7.1792],
    [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0010, 7.1792],
    [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0011, 7.2195],
    [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0012, 7.2195],
    [50.0000, -0.0010, 2.4900, 50.0000, 0.0009, -2.4900, 4.8045],
    [50.0000, -0.0010, 2.4900, 50.0000, 0.0010, -2.4900, 4.8045],
    [50.0000, -0.0010, 2.4900, 50.0000, 0.0011, -2.4900, 4.7461],
    [50.0000, 2.5000, 0.0000, 50.0000, 0.0000, -2.5000, 4.3065],
    [50.0000, 2.5000, 0.0000, 73.0000, 25.0000, -18.0000, 27.1492],
    [50.0000, 2.5000, 0.0000, 61.0000, -5.0000, 29.0000, 22.8977],
    [50.0000, 2.5000, 0.0000, 56.0000, -27.0000, -3.0000, 31.9030],
    [50.0000, 2.5000, 0.0000, 58.0000, 24.0000, 15.0000, 19.4535],
    [50.0000, 2.5000, 0.0000, 50.0000, 3.1736, 0.5854, 1.0000],
    [50.0000, 2.5000, 0.0000, 50.0000, 3.2972, 0.0000, 1.0000],
    [50.0000, 2.5000, 0.0000, 50.0000, 1.8634, 0.5757, 1.0000],
    [50.0000, 2.5000, 0.0000, 50.0000, 3.2592, 0.3350, 1.0000],
    [60.2574, -34.0099, 36.2677, 60.4626, -34.1751, 39.4387, 1.2644],
    [63.0109, -31.0961, -5.8663, 62.8187, -29.7946, -4.0864, 1.2630],
    [61.2901, 3.7196, -5.3901, 61.4292, 2.2480, -4.9620, 1.8731],
    [35.0831, -44.1164, 3.7933, 35.0232, -40.0716, 1.5901, 1.8645],
    [22.7233, 20.0904, -46.6940, 23.0331, 14.9730, -42.5619, 2.0373],
    [36.4612, 47.8580, 18.3852, 36.2715, 50.5065, 21.2231, 1.4146],
    [90.8027, -2.0831, 1.4410, 91.1528, -1.6435, 0.0447, 1.4441],
    [90.9257, -0.5406, -0.9208, 88.6381, -0.8985, -0.7239, 1.5381],
    [6.7747, -0.2908, -2.4247, 5.8714, -0.0985, -2.2286, 0.6377],
    [2.0776, 0.0795, -1.1350, 0.9033, -0.0636, -0.5514, 0.9082],
])  # fmt: skip


def test_ciede2000_matches_the_published_test_data() -> None:
    for a, b in ((SHARMA[:, :3], SHARMA[:, 3:6]), (SHARMA[:, 3:6], SHARMA[:, :3])):
        np.testing.assert_allclose(delta_e_2000(a, b), SHARMA[:, 6], atol=1e-4)
    # sRGB red in CIELAB (D65): the usual reference (53.24, 80.09, 67.20)
    np.testing.assert_allclose(srgb_to_lab(np.array([255, 0, 0], np.uint8)), [53.24, 80.09, 67.20], atol=0.01)
    with pytest.raises(InputError, match="Lab"):
        delta_e_2000(np.zeros((2, 3)), np.zeros((3, 3)))


def test_one_level_of_rounding_stays_under_the_visible_threshold() -> None:
    """Every palette colour at every shade, and the sky, each channel one level off in any direction."""
    shades = np.linspace(AMBIENT, 1.0, 14)
    cols = np.array([np.round(np.array(rgb) * s) for _, _, rgb in MATERIALS for s in shades] + [BACKGROUND_RGB])
    worst = 0.0
    for step in itertools.product((-1, 0, 1), repeat=3):
        a = cols.astype(np.uint8)
        b = np.clip(cols + step, 0, 255).astype(np.uint8)
        worst = max(worst, float(delta_e_2000(srgb_to_lab(a), srgb_to_lab(b)).max()))
    assert 1.0 < worst <= VISIBLE_DE


def test_psnr_of_identical_pictures_is_infinite_and_capped_in_the_figures() -> None:
    a = np.full((4, 5, 3), 100, np.uint8)
    assert psnr(a, a) == math.inf
    b = a.copy()
    b[0, 0, 0] = 110  # MSE = 100 / 60
    assert psnr(a, b) == pytest.approx(10 * math.log10(255.0**2 * 60 / 100))
    err = compare_colour(a, a)
    assert err.psnr_db == math.inf and err.mean_error == 0.0 and err.visible == 0 and err.delta_e_mean == 0.0
    log = ColourLog([0, 1], [0.0, 1.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [math.inf, 30.0], np.zeros((2, len(COLOUR_CAUSES))))
    s = summarise_colour(log)
    assert s["psnr_db"]["median"] == pytest.approx((PSNR_CAP_DB + 30.0) / 2) and s["psnr_db"]["min"] == 30.0
    with pytest.raises(InputError, match="uint8"):
        psnr(a, a.astype(np.float32))


def test_colour_causes_take_the_id_cause_then_the_stand_in_then_the_lod() -> None:
    t = np.zeros((1, 5, 3), np.uint8)
    c = np.full((1, 5, 3), 200, np.uint8)  # every pixel visibly wrong
    c[0, 4] = 0  # but the last
    ids = np.array([[CAUSES.index("not_received"), -1, -1, -1, -1]])
    coarse = np.array([[True, True, True, False, False]])
    stand = np.array([[False, False, True, False, False]])
    err = compare_colour(t, c, id_cause=ids, coarse=coarse, stand_in=stand)
    want = dict.fromkeys(COLOUR_CAUSES, 0) | {"not_received": 1, "lod_colour": 1, "impostor": 1, "other": 1}
    assert dict(zip(COLOUR_CAUSES, err.causes.tolist(), strict=True)) == want
    lin200 = ((200 / 255 + 0.055) / 1.055) ** 2.4  # sRGB 200 in linear light
    assert err.visible == 4 == err.causes.sum() and err.mean_error == pytest.approx(0.8 * lin200)
    # the error split by cause: the same attribution, weighted by each pixel's error; one
    # pixel of half the error of the others, so the split is by error, not by count
    c[0, 3] = 128
    err = compare_colour(t, c, id_cause=ids, coarse=coarse, stand_in=stand)
    lin128 = ((128 / 255 + 0.055) / 1.055) ** 2.4
    by = dict(zip(COLOUR_CAUSES, err.error_shares.tolist(), strict=True))
    assert by["not_received"] == by["lod_colour"] == by["impostor"] == pytest.approx(lin200 / 5)
    assert by["other"] == pytest.approx(lin128 / 5) and by["fog"] == by["lod"] == 0.0
    assert sum(by.values()) == pytest.approx(err.mean_error)
    log = ColourLog([0], [0.0], [err.mean_error], [0.0], [0.0], [30.0], err.cause_shares[None], err.error_shares[None])
    assert summarise_colour(log)["error_causes"]["other"] == pytest.approx(lin128 / 5)
    assert "error_causes" not in summarise_colour(ColourLog.empty())
    with pytest.raises(InputError, match="coarse"):
        compare_colour(t, c, coarse=np.zeros((2, 2), bool))


# --------------------------------------------------------------------------- pictures


def _note(eye: np.ndarray, view: np.ndarray, drawn: list[tuple[int, int, Any]]) -> FrameNote:
    z = np.zeros(0, np.int64)
    return FrameNote(0, 0.0, eye, view, None, None, z, z, tuple(drawn), (), (), math.inf)


def test_lod2_everywhere_has_no_colour_error_and_boxes_err_on_the_buildings(gl: Any) -> None:
    scene = load_geojson_dict(generate_city(120, 3))
    lods = {b.id: build_lods(b) for b in scene.buildings}
    streets = {s.id: build_street(s) for s in scene.streets}
    lod2 = {i: m[2] for i, m in lods.items()} | streets
    eye = np.array([*scene.streets[0].ring.mean(axis=0), 1.7])
    view = camera(eye, 0.7)
    full = _note(eye, view, [(i, 2, m) for i, m in lod2.items()])
    boxes = _note(eye, view, [(i, 0, m[0]) for i, m in lods.items()] + [(i, 2, m) for i, m in streets.items()])
    with TruthRenderer(lod2, (160, 120), ctx=gl, forms=forms_of([full, boxes])) as tr:
        t_rgb, t_ids = tr.colour_frame(eye, view)
        same, _ = colour_error(tr, full, t_rgb, np.full(t_ids.shape, -1))
        pic = client_picture(tr, boxes)
    everything = list(lod2)
    drawn = {i: lod for i, lod, _ in boxes.drawn}
    ids = compare_frame(t_ids, t_rgb, pic.ids, pic.rgb, pvs=everything, received=everything, built=everything, drawn=drawn)
    err = compare_colour(t_rgb, pic.rgb, id_cause=ids.cause, coarse=pic.coarse)
    assert same.mean_error == 0.0 and same.visible == 0 and same.psnr_db == math.inf
    assert not pic.coarse[np.isin(t_ids.astype(np.int64) - 1, list(streets))].any()
    assert err.visible > 0.01 * err.pixels and 0.0 < err.mean_error < 0.2 and err.psnr_db < 40.0
    # the boxes' colour: most of it; the rest is id-based (a box in front of what the truth shows)
    by = dict(zip(COLOUR_CAUSES, err.causes.tolist(), strict=True))
    assert by["lod_colour"] > 0.9 * err.visible and by["lod_colour"] + by["lod"] == err.visible
    # where the error is: on the buildings the client drew as boxes, never on a street
    vis = err.delta_e > VISIBLE_DE
    building = np.isin(t_ids.astype(np.int64) - 1, list(lods))
    assert vis.any() and not (vis & ~(building | pic.coarse)).any()


# --------------------------------------------------------------------------- figures


def test_report_keys_and_truth_csv_with_colour(tmp_path: Path) -> None:
    k = len(COLOUR_CAUSES)
    causes = np.zeros((3, k))
    causes[:, COLOUR_CAUSES.index("lod_colour")] = [0.1, 0.2, 0.001]
    colour = ColourLog([0, 25, 50], [0.0, 1.0, 2.0], [0.02, 0.03, 0.0], [3.0, 4.0, 0.1], [0.1, 0.2, 0.001],
                       [20.0, 19.0, math.inf], causes)
    log = TruthLog([0, 25, 50], [0.0, 1.0, 2.0], [0.1, 0.2, 0.0], np.zeros((3, len(CAUSES))), colour)
    s = summarise_truth(log, 0.5)["colour"]
    assert set(s) == {"metric", "visible_threshold", "frames", "mean_error", "delta_e_mean", "visible_pixels",
                      "frames_over_visible_ratio", "psnr_db", "causes", "impostor", "per_frame"}
    assert s["metric"] == "CIEDE2000" and s["visible_threshold"] == VISIBLE_DE and s["frames"] == 3
    assert s["mean_error"]["median"] == pytest.approx(0.02) and set(s["mean_error"]) == {"median", "p95", "max", "mean"}
    assert s["frames_over_visible_ratio"] == pytest.approx(2 / 3) and s["psnr_db"]["median"] == 20.0
    assert set(s["causes"]) == set(COLOUR_CAUSES)
    assert s["per_frame"]["frame"] == [0, 25, 50] and s["per_frame"]["psnr_db"] == [20.0, 19.0, PSNR_CAP_DB]
    back = read_truth_csv(write_truth_csv(tmp_path / "truth.csv", log))
    assert back.colour is not None
    np.testing.assert_array_equal(back.colour.psnr_db, colour.psnr_db)
    np.testing.assert_array_equal(back.colour.causes, colour.causes)
    assert "colour" not in summarise_truth(TruthLog.empty(), None)
    assert read_truth_csv(write_truth_csv(tmp_path / "plain.csv", TruthLog.empty())).colour is None


def test_the_impostors_error_frame_by_frame_against_the_figure() -> None:
    from walkstream.client.report.colour import IMPOSTOR_ERROR_MAX

    k = COLOUR_CAUSES.index("impostor")
    n = 200
    causes, errors = np.zeros((n, len(COLOUR_CAUSES))), np.zeros((n, len(COLOUR_CAUSES)))
    causes[:, k], errors[:, k] = 0.001, 0.002
    z = np.zeros(n)
    log = ColourLog(np.arange(n), z, z, z, z, z + 30.0, causes, errors)
    imp = summarise_colour(log)["impostor"]
    assert imp["frames_within_ratio"] == 1.0 and imp["reached"] is True
    assert imp["error"]["p99"] == pytest.approx(0.002) and imp["visible"]["max"] == pytest.approx(0.001)
    # three frames in 200 over a limit (1.5 %): the 99 % of the figure is not reached
    causes[0, k], errors[1, k], errors[2, k] = 0.006, 1.5 * IMPOSTOR_ERROR_MAX, 0.02
    imp = summarise_colour(ColourLog(np.arange(n), z, z, z, z, z + 30.0, causes, errors))
    imp = imp["impostor"]
    assert imp["frames_within_ratio"] == pytest.approx(197 / 200) and imp["reached"] is False
    assert imp["error"]["max"] == pytest.approx(0.02)
    # a log read back without the error split: the pixels alone decide
    only = summarise_colour(ColourLog(np.arange(n), z, z, z, z, z + 30.0, causes))["impostor"]
    assert "error" not in only and only["frames_within_ratio"] == pytest.approx(199 / 200)
