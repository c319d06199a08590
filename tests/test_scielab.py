"""The colour error at the viewer's scale (S-CIELAB), beside the per-pixel one (issue 27).

Both pictures are filtered in the opponent channels with the eye's spatial kernels at
the display's pixels per degree before CIEDE2000: detail finer than the eye resolves at
that scale stops counting, large differences keep counting, identical pictures give 0.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from walkstream.client.config import ReplayConfig
from walkstream.client.net.link import LinkProfile
from walkstream.client.report.colour import ColourLog, summarise_colour
from walkstream.client.report.truth import TruthLog, read_truth_csv, write_truth_csv
from walkstream.client.truth.colour import (
    COLOUR_CAUSES,
    SCIELAB_KERNELS,
    SCIELAB_VISIBLE_DE,
    compare_colour,
    pixels_per_degree,
    scielab_delta_e,
)
from walkstream.client.truth.compare import CAUSES
from walkstream.shared.errors import InputError

H, W = 96, 128


def _stripes_and_grey() -> tuple[np.ndarray, np.ndarray]:
    """Black and white one-pixel stripes, and the grey of their mean light (linear 0.5)."""
    stripes = np.zeros((H, W, 3), np.uint8)
    stripes[:, ::2] = 255
    grey = round(255 * (1.055 * 0.5 ** (1 / 2.4) - 0.055))
    return stripes, np.full((H, W, 3), grey, np.uint8)


def test_pixels_per_degree_of_a_view() -> None:
    # 120 rows under 60 degrees: a focal length of 103.9 pixels, 1.81 a degree at the centre
    assert pixels_per_degree(120, 60.0) == pytest.approx(60 / math.tan(math.radians(30)) * math.pi / 180)
    assert pixels_per_degree(480, 60.0) == pytest.approx(4 * pixels_per_degree(120, 60.0))
    for bad in ((0, 60.0), (120, 0.0), (120, 180.0)):
        with pytest.raises(InputError, match="pixels_per_degree"):
            pixels_per_degree(*bad)


def test_each_channel_passes_a_uniform_area_unchanged() -> None:
    for kernels in SCIELAB_KERNELS:
        assert sum(w for w, _ in kernels) == pytest.approx(1.0, abs=1e-6)
    flat = np.full((H, W, 3), (180, 120, 60), np.uint8)
    other = np.full((H, W, 3), (180, 120, 62), np.uint8)
    # a uniform difference is what CIELAB measures: the filter leaves it as it is
    per_pixel = compare_colour(flat, other).delta_e_mean
    assert scielab_delta_e(flat, other, 30.0) == pytest.approx(np.full((H, W), per_pixel), rel=1e-6)


def test_identical_pictures_have_no_error_at_any_scale() -> None:
    a, _ = _stripes_and_grey()
    assert not scielab_delta_e(a, a, 24.0).any()
    err = compare_colour(a, a, ppd=24.0)
    assert err.scielab_visible == 0 and err.scielab_delta_e_mean == 0.0 and err.ppd == 24.0


def test_one_pixel_stripes_are_invisible_at_a_viewers_scale_and_visible_magnified() -> None:
    stripes, grey = _stripes_and_grey()
    inner = (slice(8, H - 8), slice(8, W - 8))  # a mirrored edge puts two stripes side by side
    seen = scielab_delta_e(stripes, grey, 30.0)  # 15 cycles a degree of black and white
    assert np.percentile(seen[inner], 99) < SCIELAB_VISIBLE_DE
    magnified = scielab_delta_e(stripes, grey, 3.0)  # the same stripes at 1.5 cycles a degree
    assert (magnified[inner] > 5 * SCIELAB_VISIBLE_DE).all()
    # the per-pixel measure counts every pixel at any scale; the viewer-scale one beside it
    err = compare_colour(grey, stripes, ppd=30.0)
    assert err.visible == H * W
    assert err.scielab_visible_share < 0.1


def test_a_large_colour_patch_stays_visible() -> None:
    _, grey = _stripes_and_grey()
    patched = grey.copy()
    patched[24:72, 32:96] = (grey[0, 0, 0], grey[0, 0, 1] - 25, grey[0, 0, 2])
    d = scielab_delta_e(grey, patched, 30.0)
    assert (d[32:64, 40:88] > SCIELAB_VISIBLE_DE).all()
    assert d[0:8, 0:8].max() < SCIELAB_VISIBLE_DE  # far from the patch, nothing


def test_viewer_scale_causes_come_from_the_nearest_differing_pixel() -> None:
    grey = np.full((H, W, 3), 128, np.uint8)
    client = grey.copy()
    client[10:40, 10:40] = (200, 60, 60)  # an impostor's patch
    client[60:90, 80:120] = (60, 60, 200)  # a missing object's patch
    stand_in = np.zeros((H, W), bool)
    stand_in[10:40, 10:40] = True
    id_cause = np.full((H, W), -1, np.int64)
    id_cause[60:90, 80:120] = CAUSES.index("pvs")
    err = compare_colour(grey, client, id_cause=id_cause, stand_in=stand_in, ppd=12.0)
    assert err.scielab_causes is not None and err.scielab_delta_e is not None
    assert int(err.scielab_causes.sum()) == err.scielab_visible == int((err.scielab_delta_e > SCIELAB_VISIBLE_DE).sum())
    assert err.scielab_causes[COLOUR_CAUSES.index("impostor")] > 0.8 * 30 * 30
    assert err.scielab_causes[COLOUR_CAUSES.index("pvs")] > 0.8 * 30 * 40
    assert err.scielab_causes[COLOUR_CAUSES.index("other")] == 0
    # without a pixels-per-degree figure the viewer-scale figures are not measured
    plain = compare_colour(grey, client)
    assert plain.scielab_causes is None and plain.scielab_delta_e is None and plain.visible == err.visible


def test_report_keys_truth_csv_and_the_impostor_figure_at_the_viewers_scale(tmp_path: Path) -> None:
    n, k = 200, COLOUR_CAUSES.index("impostor")
    z = np.zeros(n)
    causes, errors, s_causes = np.zeros((n, len(COLOUR_CAUSES))), np.zeros((n, len(COLOUR_CAUSES))), np.zeros((n, len(COLOUR_CAUSES)))
    causes[:, k] = 0.02  # every frame over 0.5 % per pixel
    s_causes[:, k] = 0.001  # and within it at the viewer's scale
    s_causes[0, k] = 0.03
    log = ColourLog(np.arange(n), z, z, z, z + 0.02, z + 30.0, causes, errors,
                    delta_e_scielab_mean=z + 0.5, visible_scielab=s_causes[:, k], causes_scielab=s_causes, viewer_ppd=24.0)
    s = summarise_colour(log)
    assert s["viewer_ppd"] == 24.0 and s["visible_scielab_threshold"] == SCIELAB_VISIBLE_DE
    assert s["frames_over_visible_ratio"] == 1.0 and s["frames_over_visible_scielab_ratio"] == pytest.approx(1 / n)
    assert s["visible_pixels"]["median"] == pytest.approx(0.02)  # the per-pixel figure is kept
    assert s["visible_scielab_pixels"]["median"] == pytest.approx(0.001)
    imp = s["impostor"]
    assert imp["reached"] is False and imp["frames_within_ratio"] == 0.0
    assert imp["reached_scielab"] is True and imp["frames_within_scielab_ratio"] == pytest.approx(199 / 200)
    assert len(s["per_frame"]["visible_scielab"]) == n
    truth = TruthLog(np.arange(n), z, z, np.zeros((n, len(CAUSES))), log)
    back = read_truth_csv(write_truth_csv(tmp_path / "truth.csv", truth)).colour
    assert back is not None and back.causes_scielab is not None and back.visible_scielab is not None
    np.testing.assert_array_equal(back.causes_scielab, s_causes)
    np.testing.assert_array_equal(back.causes, causes)
    # a log without them (an older truth.csv) has no viewer-scale keys
    old = summarise_colour(ColourLog(np.arange(n), z, z, z, z, z + 30.0, causes, errors))
    assert "visible_scielab_pixels" not in old and "reached_scielab" not in old["impostor"]
    with pytest.raises(InputError, match="come together"):
        ColourLog(np.arange(n), z, z, z, z, z, causes, visible_scielab=z)


@pytest.mark.parametrize("bad", [0.0, -3.0, math.nan, 5000.0])
def test_a_bad_viewer_ppd_is_a_one_line_error(bad: float) -> None:
    with pytest.raises(InputError, match="--viewer-ppd"):
        ReplayConfig(link=LinkProfile(down_bps=56_000.0, up_bps=56_000.0, rtt_s=0.2), path="SE", device="pda", truth_every=1, viewer_ppd=bad)
