"""``--pvs-budget``: the least-seen objects left out while every view's loss fits the budget."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

from walkstream.server.bake.pvsbudget import budget_drops, pool_views, within_budget
from walkstream.server.bake.settings import BakeSettings
from walkstream.shared.errors import InputError

if TYPE_CHECKING:
    import moderngl


def _v(ids: list[int], px: list[int]) -> tuple[np.ndarray, np.ndarray]:
    return np.array(ids, np.int64), np.array(px, np.int64)


def test_an_object_seen_well_from_one_view_is_kept_however_little_the_others_see_it() -> None:
    # object 5 covers 1 pixel of 10,000 in nine views and 30 % of the tenth
    views = [_v([1, 5], [9_999, 1])] * 9 + [_v([1, 5], [700, 300])]
    # pooled it is 300 + 9 of 100,990 pixels (0.3 %), but a view would lose 30 %
    assert budget_drops(views, 0.01).tolist() == []
    # where no view sees it well, it goes
    assert budget_drops(views[:9], 0.001).tolist() == [5]


def test_the_budget_holds_in_every_view_together() -> None:
    a = _v([1, 2, 3, 4], [9_900, 50, 30, 20])  # 10,000 pixels: 2, 3, 4 are 0.5, 0.3, 0.2 %
    b = _v([1, 3, 4], [990, 4, 6])  # 1,000 pixels: 3 and 4 are 0.4 and 0.6 %
    # by their largest share: 3 (0.4 %), 2 (0.5 %), 4 (0.6 %)
    assert budget_drops([a, b], 0.02).tolist() == [2, 3, 4]
    # at 0.9 %: 3 and 2 leave a with 0.8 %; 4 would take a to 1.0 %
    assert budget_drops([a, b], 0.009).tolist() == [2, 3]
    # at 0.6 %: 3 alone; 2 would take a to 0.8 %
    assert budget_drops([a, b], 0.006).tolist() == [3]
    assert budget_drops([a, b], 0.0).tolist() == []
    assert budget_drops([], 0.5).tolist() == []
    # a view that sees nothing holds no budget back
    assert budget_drops([a, b, _v([], [])], 0.009).tolist() == [2, 3]


def test_pooled_counts_less_the_left_out_with_the_band_scaled() -> None:
    cube = [_v([1, 2], [100, 1]), _v([1, 3], [50, 2])]
    assert [x.tolist() for x in pool_views(cube)] == [[1, 2, 3], [150, 1, 2]]
    s = BakeSettings(resolution=128, far_band=3.0, far_pixels=1280, pvs_budget=0.05)
    band = [_v([1, 7], [9_000, 1_000])]  # 7: only the band sees it, 10 % of its pixels
    ids, px = within_budget(cube, band, s)
    # 2 (1 % of the first view) and 3 (3.8 % of the second) go; 7 is kept with its band pixels scaled (1,000 / 100)
    assert ids.tolist() == [1, 7] and px.tolist() == [150 + 90, 10]
    assert [x.tolist() for x in within_budget(cube, [], BakeSettings())] == [[1, 2, 3], [150, 1, 2]]


def test_the_budget_is_checked_and_refused_where_it_does_not_apply() -> None:
    for bad in ({"pvs_budget": 0.01}, {"pvs_budget": -1e-6}, {"pvs_budget": float("inf")}):
        with pytest.raises(InputError, match="--pvs-budget"):
            BakeSettings(**bad).check()  # type: ignore[arg-type]
    for other in ({"sampling": "field"}, {"split": 0.3}, {"cells": "sections"}):
        with pytest.raises(InputError, match="--pvs-budget"):
            BakeSettings(pvs_budget=3e-5, **other).check()  # type: ignore[arg-type]
    assert BakeSettings(pvs_budget=3e-5).check().pvs_budget == 3e-5


@pytest.mark.gl
def test_a_budgeted_bake_holds_a_subset_every_point_sees_within_the_budget(tmp_path: Path, gl: moderngl.Context) -> None:
    import json

    import shapely

    from walkstream.benchmarks.visinput import scene_from_database
    from walkstream.server.bake import bake
    from walkstream.server.bake.idpack import meshes_for_scene
    from walkstream.server.bake.visibility import VisibilityRenderer
    from walkstream.server.bake.workers import cell_points
    from walkstream.server.sources.citygen import generate_city

    src = tmp_path / "c.geojson"
    src.write_text(json.dumps(generate_city(180.0, seed=4)))
    plain, tight = BakeSettings(resolution=48), BakeSettings(resolution=48, pvs_budget=0.002)
    for st, name in ((plain, "a.db"), (tight, "b.db")):
        bake(src, tmp_path / name, settings=st)
    gl.__enter__()  # each bake made its own context current and released it
    _, _, before, _ = scene_from_database(tmp_path / "a.db")
    scene, cells, after, header = scene_from_database(tmp_path / "b.db")
    assert header["pvs_budget"] == 0.002 and "pvs_budget" not in scene_from_database(tmp_path / "a.db")[3]
    assert before.keys() == after.keys()
    assert all(set(after[c].tolist()) <= set(before[c].tolist()) for c in before)
    assert sum(map(len, after.values())) < sum(map(len, before.values()))
    # what the budget left out, every sample point of the cell sees within the budget
    meshes, ids = meshes_for_scene(scene, tight.occluder_lod)
    fp = shapely.STRtree([shapely.Polygon(b.rings[0], b.rings[1:]) for b in scene.buildings])
    r = VisibilityRenderer(meshes, ids, resolution=48, view_distance=tight.view_distance, ctx=gl)
    try:
        for c in cells[:8]:
            gone = np.setdiff1d(before[c.id], after[c.id])
            for vid, px in r.each_point_counts(cell_points(tight, np.asarray(c.polygon), c.zmin, c.zmax, fp)):
                assert px[np.isin(vid, gone)].sum() <= tight.pvs_budget * px.sum()
    finally:
        r.release()
