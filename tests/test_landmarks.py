"""Landmarks (issue 27, item 6): a tower and a spire from the building grammar, as parameters.

The grammar builds a landmark's crown from its kind; only the kind travels (a twelfth
field of the building record, absent for ordinary buildings, whose bytes do not change).
"""

from __future__ import annotations

import json
from pathlib import Path

import msgpack
import numpy as np
import pytest

from walkstream.shared.buildings import build_lods, build_lods_batch, predict_triangles
from walkstream.shared.codec import decode_building, encode_building
from walkstream.shared.errors import CodecError, InputError
from walkstream.shared.landmarks import SPIRE, TOWER, crown_top, landmark_kind
from walkstream.shared.records import BuildingParams


def _square(side: float, kind: int, floors: int, x: float = 0.0) -> BuildingParams:
    ring = np.array([[0, 0], [side, 0], [side, side], [0, side]], np.float64) + [x, 0.0]
    return BuildingParams(id=7, rings=(ring,), neighbour_heights=(np.zeros(4),), floors=floors,
                          floor_height=3.4, style=11, kind=kind)


def test_kinds_are_named_and_a_bad_one_is_refused() -> None:
    assert (landmark_kind(None), landmark_kind("tower"), landmark_kind("spire")) == (0, TOWER, SPIRE)
    with pytest.raises(InputError, match="landmark"):
        landmark_kind("castle")
    with pytest.raises(InputError, match="kind"):
        _square(20.0, 5, 10)


@pytest.mark.parametrize("kind", [TOWER, SPIRE])
def test_the_crown_reaches_its_top_and_stays_over_the_footprint(kind: int) -> None:
    b = _square(20.0, kind, 20)
    plain = _square(20.0, 0, 20)
    assert b.top == crown_top(kind, b.height, 20.0) > b.height == plain.top
    lods = build_lods(b)
    for m in lods:
        # every LOD reaches the crown's top (LOD0 as one pillar) and no higher
        assert m.positions[:, 2].max() == pytest.approx(b.top, abs=1e-3)
        above = m.positions[m.positions[:, 2] > b.height + 1.0]
        # the crown stands inside the footprint (ledges reach 0.15 m past a stage's face)
        assert above[:, :2].min() >= 0.0 and above[:, :2].max() <= 20.0
    t = predict_triangles(b)
    assert t == tuple(m.triangles for m in lods)
    assert t[0] < t[1] < t[2]
    # a landmark is far more detailed than a plain building of the same floors
    assert t[2] > 1.5 * predict_triangles(plain)[2]
    # the batch rebuild gives the same meshes as one by one
    for one, many in zip(lods, build_lods_batch([plain, b])[1], strict=True):
        assert np.array_equal(one.indices, many.indices)
        assert np.allclose(one.positions, many.positions)


def test_plain_buildings_keep_their_record_bytes_and_a_landmark_adds_its_kind() -> None:
    plain = _square(20.0, 0, 5)
    rec = msgpack.unpackb(encode_building(plain))
    assert len(rec) == 11
    tower = _square(20.0, TOWER, 30)
    data = encode_building(tower)
    assert len(msgpack.unpackb(data)) == 12 and len(data) == len(encode_building(_square(20.0, 0, 30))) + 1
    back = decode_building(data)
    assert back.kind == TOWER and back.top == pytest.approx(tower.top)
    assert decode_building(encode_building(plain)).kind == 0
    for bad in (0, 3, "tower", -1):
        forged = msgpack.packb(msgpack.unpackb(data)[:11] + [bad])
        with pytest.raises(CodecError, match="kind"):
            decode_building(forged)


def test_a_footprint_file_names_its_landmarks_and_a_bad_one_is_repaired(tmp_path: Path) -> None:
    from walkstream.server.sources.geojson import load_geojson

    def feature(fid: str, x: float, **props: object) -> dict:
        x0, y0 = 600000.0 + x, 5340000.0
        ring = [[x0, y0], [x0 + 20, y0], [x0 + 20, y0 + 20], [x0, y0 + 20], [x0, y0]]
        return {"type": "Feature", "id": fid, "geometry": {"type": "Polygon", "coordinates": [ring]},
                "properties": {"floors": 20, **props}}

    crs = {"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::32633"}}
    fc = {"type": "FeatureCollection", "crs": crs, "features": [
        feature("a", 0, landmark="spire"), feature("b", 50, landmark="pagoda"), feature("c", 100)]}
    path = tmp_path / "marks.geojson"
    path.write_text(json.dumps(fc))
    scene = load_geojson(path)
    kinds = {b.source_id: b.kind for b in scene.buildings}
    assert kinds == {"a": SPIRE, "b": 0, "c": 0}
    (issue,) = [i for i in scene.issues if i.feature_id == "b"]
    assert issue.action == "repaired" and "landmark" in issue.problem


def test_the_manifest_carries_the_whole_grammar_text() -> None:
    # the grammar grew past 4 kB with the crowns; a manifest bound below its length
    # refused every manifest and the client silently never rebuilt a building
    from walkstream.shared.buildings import default_grammar_text
    from walkstream.shared.wire import MAX_GRAMMAR_TEXT, decode_manifest

    text = default_grammar_text()
    assert len(text) > 4096 and len(text) * 4 < MAX_GRAMMAR_TEXT
    body = msgpack.packb({
        "name": "c", "version": "1", "crs": "EPSG:32633", "origin": [0.0, 0.0], "bounds": [0, 0, 1, 1],
        "features": [], "grammar": {"id": "building@2+x", "text": text}, "paths": ["SE"], "objects": 1,
        "cells": 1, "limits": {"objects_per_request": 64},
    })
    assert decode_manifest(body, "manifest").grammar_text == text
    too_long = msgpack.packb({"grammar": {"id": "g", "text": "x" * (MAX_GRAMMAR_TEXT + 1)}})
    with pytest.raises(CodecError):
        decode_manifest(too_long, "manifest")


def test_the_default_city_of_an_older_generator_is_made_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from walkstream.cmd_bake import default_city_source
    from walkstream.server.sources import citygen

    monkeypatch.setattr(citygen, "DEFAULT_SIZE", 150.0)  # small and quick; the rule is the same
    old = tmp_path / "city.geojson"
    old.write_text(json.dumps({"type": "FeatureCollection", "walkstream": {"version": 1}, "features": []}))
    assert default_city_source(tmp_path) == old
    assert "older city generator" in capsys.readouterr().out
    made = json.loads(old.read_text())
    assert made["walkstream"]["version"] == citygen.GENERATOR_VERSION and made["features"]
    before = old.stat().st_mtime_ns
    default_city_source(tmp_path)  # current: kept as it is
    assert old.stat().st_mtime_ns == before
