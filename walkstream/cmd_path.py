"""``walkstream path``: record, import, list and export the recorded paths of a scene.

::

    walkstream path record DB NAME --from X,Y --to X,Y [--via X,Y ...] --speed KMH [--replace]
    walkstream path record INTERIOR.db NAME --from-room NAME --to-room NAME [--via-room NAME] [--speed KMH]
    walkstream path record INTERIOR.db NAME --from X,Y,Z --to X,Y,Z [--speed KMH]
    walkstream path record CROSSING.db NAME --from X,Y --to-room NAME [--speed KMH]   (and --from-room NAME --to X,Y)
    walkstream path import DB NAME FILE.geojson|FILE.gpx --speed KMH [--clip] [--replace]
    walkstream path list DB [--json]
    walkstream path export DB NAME -o FILE.json

``record`` and ``import`` write the path into the database atomically; that makes a
new scene version, which they print.  The file format is documented in
:mod:`walkstream.shared.paths`.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
from contextlib import suppress
from pathlib import Path
from typing import Any

from walkstream.shared.errors import WalkstreamError

__all__ = [
    "add_path_parser",
    "cmd_path_record",
    "cmd_path_import",
    "cmd_path_list",
    "cmd_path_export",
]


def _point(text: str, option: str) -> tuple[float, float]:
    try:
        parts = tuple(float(v) for v in text.split(","))
    except ValueError:
        parts = ()
    if len(parts) != 2 or not all(math.isfinite(v) for v in parts):
        raise WalkstreamError(f"{option}: expected X,Y in scene-local metres, got {text!r}")
    return parts[0], parts[1]


def _place(text: str, option: str) -> tuple[float, ...]:
    try:
        parts = tuple(float(v) for v in text.split(","))
    except ValueError:
        parts = ()
    if len(parts) not in (2, 3) or not all(math.isfinite(v) for v in parts):
        raise WalkstreamError(f"{option}: expected X,Y or X,Y,Z in scene-local metres, got {text!r}")
    return parts


#: The fastest path speed taken (km/h): an aircraft's; beyond it a speed is a mistake
#: (a path of 1e308 km/h lasted 0.0 s and replayed as no frame).
MAX_SPEED_KMH = 1000.0


def _speed(value: float) -> float:
    if not (math.isfinite(value) and 0 < value <= MAX_SPEED_KMH):
        raise WalkstreamError(f"--speed: expected a number of km/h above 0 and at most {MAX_SPEED_KMH:g}, got {value:g}")
    return value


def _summary(path: Any) -> str:
    return f"{path.duration:.1f} s, {path.length_m():.0f} m, {len(path)} key points"


def cmd_path_record(args: argparse.Namespace) -> int:
    """Handler of ``walkstream path record``."""
    from walkstream.server.paths.record import record_path, record_walk
    from walkstream.server.store import SceneReader

    with SceneReader.open(args.db) as reader:
        kind = reader.meta.kind
    if kind in ("interior", "crossing"):
        from walkstream.server.bake.roomnav import INDOOR_SPEED_KMH

        ends: list[Any] = []
        for room, xy, flag in ((args.from_room, args.from_xy, "--from"), (args.to_room, args.to_xy, "--to")):
            if (room is None) == (xy is None):
                raise WalkstreamError(f"give {flag}-room NAME or {flag} X,Y[,Z] (one of them)")
            ends.append(room if room is not None else _place(xy, flag))
        via_places: list[Any] = [*(args.via_room or []), *(_place(v, "--via") for v in args.via or [])]
        speed = INDOOR_SPEED_KMH if args.speed is None else _speed(args.speed)
        path, version = record_walk(args.db, args.name, ends[0], ends[1], speed, via_places, replace=args.replace)
    else:
        if args.from_room or args.to_room or args.via_room:
            raise WalkstreamError(f"{args.db}: a city scene has no rooms: use --from X,Y --to X,Y")
        if args.from_xy is None or args.to_xy is None:
            raise WalkstreamError("give --from X,Y and --to X,Y")
        if args.speed is None:
            raise WalkstreamError("--speed KMH: a city path needs a speed")
        start = _point(args.from_xy, "--from")
        end = _point(args.to_xy, "--to")
        via = [_point(v, "--via") for v in args.via or []]
        path, version = record_path(
            args.db, args.name, start, end, _speed(args.speed), via, replace=args.replace
        )
    print(f"recorded path {args.name!r} in {args.db}: {_summary(path)}; scene version {version}")
    return 0


def cmd_path_import(args: argparse.Namespace) -> int:
    """Handler of ``walkstream path import``."""
    from walkstream.server.paths.importline import import_path

    path, version, inside = import_path(
        args.db, args.name, args.file, _speed(args.speed), args.clip, replace=args.replace
    )
    print(
        f"imported path {args.name!r} into {args.db}: {_summary(path)}, "
        f"{inside:.0f} m of the line inside the cells; scene version {version}"
    )
    return 0


def _read_all(db: str | os.PathLike[str]) -> tuple[str, list[Any]]:
    from walkstream.server.store import SceneReader
    from walkstream.shared.paths import RecordedPath

    reader = SceneReader.open(db)
    try:
        paths = [
            RecordedPath.from_msgpack(reader.path_blob(n), f"{db}: path {n!r}")
            for n in reader.path_names()
        ]
        return reader.version, paths
    finally:
        reader.close()


def cmd_path_list(args: argparse.Namespace) -> int:
    """Handler of ``walkstream path list``."""
    version, paths = _read_all(args.db)
    rows = [
        {
            "name": p.name,
            "duration_s": round(p.duration, 2),
            "length_m": round(p.length_m(), 1),
            "speed_kmh": p.speed_kmh,
            "key_points": len(p),
            "bytes": len(p.to_msgpack()),
        }
        for p in paths
    ]
    if args.json:
        print(json.dumps({"version": version, "paths": rows}))
        return 0
    if not rows:
        print(f"{args.db}: no recorded paths")
        return 0
    width = max(4, *(len(r["name"]) for r in rows))
    print(f"{'name':<{width}}  {'duration':>9}  {'length':>8}  {'speed':>9}  {'key points':>10}")
    for r in rows:
        speed = "-" if r["speed_kmh"] is None else f"{r['speed_kmh']:g} km/h"
        print(
            f"{r['name']:<{width}}  {r['duration_s']:>7.1f} s  {r['length_m']:>6.0f} m  "
            f"{speed:>9}  {r['key_points']:>10}"
        )
    return 0


def cmd_path_export(args: argparse.Namespace) -> int:
    """Handler of ``walkstream path export``."""
    from walkstream.server.store import SceneReader
    from walkstream.shared.paths import RecordedPath

    reader = SceneReader.open(args.db)
    try:
        path = RecordedPath.from_msgpack(
            reader.path_blob(args.name), f"{args.db}: path {args.name!r}"
        )
    finally:
        reader.close()
    out = Path(args.output)
    tmp = out.with_name(out.name + ".tmp")
    try:
        tmp.write_text(path.to_json(), encoding="utf-8")
        os.replace(tmp, out)
    except OSError as exc:
        with suppress(OSError):
            tmp.unlink()
        raise WalkstreamError(f"{out}: cannot write ({exc.strerror or exc})") from exc
    print(f"exported path {args.name!r} to {out}: {_summary(path)}")
    return 0


def add_path_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``walkstream path`` and its subcommands on the top-level subparsers."""
    p = sub.add_parser("path", help="recorded paths of a scene: record, import, list, export")
    psub = p.add_subparsers(dest="what", metavar="WHAT", required=True)

    r = psub.add_parser(
        "record",
        help="record a path along the street graph or through an interior's rooms (new scene version)",
        description="Record a path along the street graph, or in an interior from room to room "
        "through doors and up stairs. X,Y are scene-local metres (in an interior X,Y,Z, Z the eye "
        "height, which picks the storey); a negative X may be written --from -120.5,30 or --from=-120.5,30.",
    )
    if hasattr(r, "_negative_number_matcher"):
        # argparse takes "-120.5,30" for an option (its negative-number test knows no
        # commas); this parser has no option that looks like a number, so widen it
        r._negative_number_matcher = re.compile(r"^-\d+$|^-\d*\.\d+$|^-[\d.]+(e-?\d+)?,")
    r.add_argument("db", help="scene database")
    r.add_argument("name", help="path name")
    r.add_argument(
        "--from", dest="from_xy", metavar="X,Y[,Z]", help="start, scene-local metres"
    )
    r.add_argument(
        "--to", dest="to_xy", metavar="X,Y[,Z]", help="end, scene-local metres"
    )
    r.add_argument(
        "--via", action="append", metavar="X,Y[,Z]", help="a point to pass on the way (repeatable)"
    )
    r.add_argument("--from-room", metavar="NAME", help="interiors and crossing scenes: start in this room (its name, or "
                   "part of it); in a crossing scene X,Y in a street cell is on the street")
    r.add_argument("--to-room", metavar="NAME", help="interiors and crossing scenes: end in this room")
    r.add_argument("--via-room", action="append", metavar="NAME", help="interiors: a room to pass (repeatable)")
    r.add_argument(
        "--speed", type=float, metavar="KMH",
        help="speed in km/h (needed for a city; interiors default to 4 km/h)",
    )
    r.add_argument("--replace", action="store_true", help="overwrite a path of the same name")
    r.set_defaults(func=cmd_path_record)

    i = psub.add_parser("import", help="turn a GeoJSON LineString or a GPX track into a path (new scene version)")
    i.add_argument("db", help="scene database")
    i.add_argument("name", help="path name")
    i.add_argument(
        "file",
        help="GeoJSON LineString / Feature / FeatureCollection with one line (lon/lat or its 'crs'), "
        "or a GPX file (its tracks, else routes, else waypoints)",
    )
    i.add_argument("--speed", type=float, required=True, metavar="KMH", help="speed in km/h")
    i.add_argument(
        "--clip", action="store_true", help="keep only the longest stretch inside the scene's cells"
    )
    i.add_argument("--replace", action="store_true", help="overwrite a path of the same name")
    i.set_defaults(func=cmd_path_import)

    ls = psub.add_parser("list", help="the recorded paths: duration, length, speed, key points")
    ls.add_argument("db", help="scene database")
    ls.add_argument("--json", action="store_true", help="print one JSON object")
    ls.set_defaults(func=cmd_path_list)

    e = psub.add_parser("export", help="write a path as JSON (the walkstream-path format)")
    e.add_argument("db", help="scene database")
    e.add_argument("name", help="path name")
    e.add_argument("-o", "--output", required=True, metavar="FILE.json", help="file to write")
    e.set_defaults(func=cmd_path_export)
