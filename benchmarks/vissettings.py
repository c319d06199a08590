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

__all__ = [
    "TARGETS",
    "Setting",
    "parse_setting",
    "TODAY",
    "PREVIOUS",
    "DEFAULT_SETTINGS",
    "bake_default",
    "same_sampling",
]


#: the targets a default is held to: misses by pixels (pooled share of the reference's
#: pixels), the largest single miss (share of one cell's reference pixels), the PVS
#: size against the first default's (``corners-64``) and the bake time against the
#: bake's default's, both measured in the same run; the count of missed objects is
#: reported, not a goal (what remains is mostly below a pixel)
TARGETS = {
    "miss_px": 0.0001,
    "miss_max": 0.00005,
    "pvs_ratio": 1.3,
    "time_ratio_default": 3.0,
}


@dataclass(frozen=True, slots=True)
class Setting:
    """A named way of baking a cell's PVS (only the sampling fields of ``bake`` matter)."""

    name: str
    bake: BakeSettings


_SPEC = re.compile(r"^(corners|(?:boundary|region|field)(\d+(?:\.\d+)?)?)-(\d+)((?:-[a-zA-Z]+\d*(?:\.\d+)?|\+[ced])*)$")


def parse_setting(spec: str) -> Setting:
    """A setting from its name: ``SAMPLING-RES[-tN][-pP][-LK][-hH][+c][+e]``.

    ``corners-64`` is the first bake (8 box corners, 64 px); ``boundary20-128`` samples
    the outline every 20 m at 128 px; ``region20-128`` the outline, a 20 m grid inside
    and both ends of the height range; ``-t2`` adds a hardly-visible threshold of 2
    pixels, ``-p0.003`` a pixel budget of 0.003 % of each view's pixels (``--pvs-budget``: the
    least-seen objects left out while every view's loss fits it), ``-L2`` renders LOD2 occluders, ``-h0.25`` samples a height every 0.25 m
    of the cell's range, ``+c`` the centre too, ``+e`` the edge pass (objects thinner
    than a pixel), ``-thin2`` the thin pass for boxes at most 2 px across
    (``--thin-pass 2``), ``+d`` its conservative depth (``--thin-depth``).  ``field4-128`` samples the cell from the dense visibility field
    every 4 m (``--sampling field --field-spacing 4``).

    >>> s = parse_setting("boundary10-256-t4+c").bake
    >>> (s.sampling, s.spacing, s.resolution, s.threshold, s.centre, s.edge_pass)
    ('boundary', 10.0, 256, 4, True, False)
    >>> s = parse_setting("region20-128+e").bake
    >>> (s.sampling, s.spacing, s.edge_pass)
    ('region', 20.0, True)
    >>> parse_setting("region20-128-thin2").bake.thin_pass
    2.0
    >>> s = parse_setting("field2-128").bake
    >>> (s.sampling, s.field_spacing)
    ('field', 2.0)
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
    elif m.group(1).startswith("field"):
        kw["sampling"] = "field"
        if m.group(2):
            kw["field_spacing"] = float(m.group(2))
    else:
        kw["sampling"] = "region" if m.group(1).startswith("region") else "boundary"
        if m.group(2):
            kw["spacing"] = float(m.group(2))
    for part in re.findall(r"-([a-zA-Z]+)(\d+(?:\.\d+)?)|\+([ced])", m.group(4)):
        key, value, flag = part
        if flag == "c":
            kw["centre"] = True
        elif flag == "d":
            kw["thin_depth"] = True
        elif flag == "e":
            kw["edge_pass"] = True
        elif key == "thin":
            kw["thin_pass"] = float(value)
        elif key == "s":
            kw["split"] = float(value)
        elif key == "t":
            kw["threshold"] = int(float(value))
        elif key == "p":
            kw["pvs_budget"] = float(value) / 100.0
        elif key == "L":
            kw["occluder_lod"] = int(value)
        elif key == "h":
            kw["height_step"] = float(value)
        else:
            raise InputError(f"setting {spec!r}: unknown part -{key}{value} (t, p, L, h, s, thin, +c or +e)")
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
    "field4-128",
)


def same_sampling(a: BakeSettings, b: BakeSettings) -> bool:
    """Whether two bake settings sample a cell alike (every field that changes its PVS)."""
    keys: tuple[str, ...] = (
        "sampling", "spacing", "height_step", "centre", "resolution", "occluder_lod", "threshold", "edge_pass", "thin_pass", "thin_depth", "split",
    )
    if a.sampling == "field" or b.sampling == "field":
        keys = ("sampling", "field_spacing", "resolution", "occluder_lod", "threshold", "edge_pass", "thin_pass", "thin_depth")
    return all(getattr(a, k) == getattr(b, k) for k in keys)


def bake_default() -> Setting:
    """The bake's default sampling as a named setting (the yardstick of ``time x dflt``)."""
    st = BakeSettings()
    if st.sampling == "corners":
        name = f"corners-{st.resolution}"
    elif st.sampling == "field":
        name = f"field{st.field_spacing:g}-{st.resolution}"
    else:
        name = f"{st.sampling}{st.spacing:g}-{st.resolution}"
    if st.thin_pass:
        name += f"-thin{st.thin_pass:g}" + ("+d" if st.thin_depth else "")
    return Setting(name, st)
