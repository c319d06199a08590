"""The settings ``walkstream bench visibility`` compares, and the targets they are held to.

A setting is a named way of sampling a cell for its PVS (:func:`parse_setting`);
:data:`TODAY` is the first bake's, :data:`PREVIOUS` the one before the current default.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from walkstream.server.bake.settings import BakeSettings
from walkstream.shared.errors import InputError

__all__ = ["TARGETS", "Setting", "parse_setting", "TODAY", "PREVIOUS", "DEFAULT_SETTINGS", "same_sampling"]


#: the issue's targets: misses by count, largest single miss, misses by pixels (shares),
#: bake time and PVS size as ratios to the first default
TARGETS = {
    "miss_count": 0.05,
    "miss_max": 0.0001,
    "miss_px": 0.0005,
    "time_ratio": 2.0,
    "pvs_ratio": 1.25,
}


@dataclass(frozen=True, slots=True)
class Setting:
    """A named way of baking a cell's PVS (only the sampling fields of ``bake`` matter)."""

    name: str
    bake: BakeSettings


_SPEC = re.compile(r"^(corners|(?:boundary|region)(\d+(?:\.\d+)?)?)-(\d+)((?:-[a-zA-Z]+\d*(?:\.\d+)?|\+[ce])*)$")


def parse_setting(spec: str) -> Setting:
    """A setting from its name: ``SAMPLING-RES[-tN][-LK][-hH][+c][+e]``.

    ``corners-64`` is the first bake (8 box corners, 64 px); ``boundary20-128`` samples
    the outline every 20 m at 128 px; ``region20-128`` the outline, a 20 m grid inside
    and both ends of the height range; ``-t2`` adds a hardly-visible threshold of 2
    pixels, ``-L2`` renders LOD2 occluders, ``-h0.25`` samples a height every 0.25 m
    of the cell's range, ``+c`` the centre too, ``+e`` the edge pass (objects thinner
    than a pixel).

    >>> s = parse_setting("boundary10-256-t4+c").bake
    >>> (s.sampling, s.spacing, s.resolution, s.threshold, s.centre, s.edge_pass)
    ('boundary', 10.0, 256, 4, True, False)
    >>> s = parse_setting("region20-128+e").bake
    >>> (s.sampling, s.spacing, s.edge_pass)
    ('region', 20.0, True)
    """
    m = _SPEC.match(spec.strip())
    if m is None:
        raise InputError(
            f"setting {spec!r}: expected SAMPLING-RES[-tN][-LK][-hH][+c], e.g. corners-64, "
            "boundary20-128-t2"
        )
    kw: dict[str, Any] = {"resolution": int(m.group(3))}
    if m.group(1) == "corners":
        kw["sampling"] = "corners"
    else:
        kw["sampling"] = "region" if m.group(1).startswith("region") else "boundary"
        if m.group(2):
            kw["spacing"] = float(m.group(2))
    for part in re.findall(r"-([a-zA-Z]+)(\d+(?:\.\d+)?)|\+([ce])", m.group(4)):
        key, value, flag = part
        if flag == "c":
            kw["centre"] = True
        elif flag == "e":
            kw["edge_pass"] = True
        elif key == "s":
            kw["split"] = float(value)
        elif key == "t":
            kw["threshold"] = int(float(value))
        elif key == "L":
            kw["occluder_lod"] = int(value)
        elif key == "h":
            kw["height_step"] = float(value)
        else:
            raise InputError(f"setting {spec!r}: unknown part -{key}{value} (t, L, h, s, +c or +e)")
    return Setting(spec.strip(), BakeSettings(**kw).check())


#: the first bake's default, the yardstick of every ratio
TODAY = parse_setting("corners-64")


#: the bake's default before region sampling (issue 12 item 2): the second yardstick
PREVIOUS = parse_setting("boundary20-128")


#: the rows ``bench visibility`` runs by default
DEFAULT_SETTINGS: tuple[str, ...] = (
    "corners-64",
    "corners-64+c",
    "corners-128",
    "corners-256",
    "boundary20-64",
    "boundary10-64",
    "boundary20-128",
    "boundary10-128",
    "boundary20-128-t1",
    "boundary20-128-t4",
    "boundary20-256",
    "boundary20-256-t4",
    "region20-128",
    "region10-128",
    "region20-128-t1",
    "region20-128-t4",
    "region20-128+e",
    "region20-128-s0.5",
)


def same_sampling(a: BakeSettings, b: BakeSettings) -> bool:
    """Whether two bake settings sample a cell alike (every field that changes its PVS)."""
    keys = ("sampling", "spacing", "height_step", "centre", "resolution", "occluder_lod", "threshold", "edge_pass", "split")
    return all(getattr(a, k) == getattr(b, k) for k in keys)
