"""What decides a bake's result: resolution, occluder LOD, sampling, cells, view distance, threshold.

Every field is part of the bake's settings record, so changing a default changes
the content hash (the scene version) of every new bake, and a bake resumes only
with the settings it started with.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from walkstream.shared.errors import InputError

__all__ = [
    "DEFAULT_RESOLUTION",
    "DEFAULT_OCCLUDER_LOD",
    "DEFAULT_SAMPLING",
    "DEFAULT_THIN_PASS",
    "DEFAULT_FAR_BAND",
    "DEFAULT_FAR_PIXELS",
    "DEFAULT_FIELD_SPACING",
    "DEFAULT_REDUNDANCY",
    "DEFAULT_MIN_SIZE",
    "SECTION_FIELDS",
    "SECTION_SHAPES",
    "SECTION_COVERS",
    "BakeSettings",
]

#: chosen with ``walkstream bench visibility`` against its dense reference (issue 12:
#: the first default, 64 px at the 8 box corners, missed single buildings covering
#: 0.1 % of a cell's reference pixels; the outline at 128 px left a street seen
#: edge-on 60 m away (0.037 %) that the outline, the inside and both eye heights of
#: ``"region"`` catch at the same number of points; see docs/benchmarks.md)
DEFAULT_RESOLUTION = 128
DEFAULT_OCCLUDER_LOD = 0
DEFAULT_SAMPLING = "region"
#: the thin pass (objects under a pixel tested again, lines and points against the
#: fill's depth), in pixels of a box's narrower screen extent; 0: off
DEFAULT_THIN_PASS = 0.0
#: the far field's band (``--far-band``): degrees above and below the horizon, 0: off;
#: its pixels across a 90-degree face (``--far-pixels``): a 640-pixel, 60-degree client
#: frame's pixels per degree at the centre (640 / tan 30 degrees)
DEFAULT_FAR_BAND = 0.0
DEFAULT_FAR_PIXELS = 1109

#: sections (Brosnan et al. sample every 2 m; see docs/benchmarks.md for the cost of
#: the field on the demo city at 2 and 4 m)
DEFAULT_FIELD_SPACING = 4.0
#: None: R derived from the scene's field, the smallest whose sections average
#: ``sectionsize.SECTION_AREA`` m² of the walkable cover (docs/benchmarks.md)
DEFAULT_REDUNDANCY: int | None = None
DEFAULT_MIN_SIZE = 64.0

#: the settings only a bake of sections stores (:meth:`BakeSettings.record`;
#: ``section_shape`` only when not the default)
SECTION_FIELDS = ("field_spacing", "redundancy", "min_size", "section_shape", "section_cover")
SECTION_SHAPES = ("axis", "aligned")
#: what sections cover: the walkable cells' field points (street cells, grid cells where
#: a scene has no streets) or every free field point (the paper's)
SECTION_COVERS = ("walkable", "free")


@dataclass(frozen=True, slots=True)
class BakeSettings:
    """Everything that decides a bake's result (and so whether a resume is valid)."""

    cells: str = "auto"
    cell_size: float = 40.0
    max_length: float = 40.0
    view_distance: float = 800.0
    bbox: tuple[float, float, float, float] | None = None
    bbox_crs: str = "local"
    network: str = "walk"
    resolution: int = DEFAULT_RESOLUTION
    occluder_lod: int = DEFAULT_OCCLUDER_LOD
    centre: bool = False
    threshold: int = 0
    """Hardly-visible threshold (m-LOMA): an object needs more than this many pixels
    over the cell's images to enter its PVS (0: any pixel at all)."""
    pvs_budget: float = 0.0
    """A share of each view's object pixels (a sample point's cube, a band point's band)
    that the objects a cell's PVS leaves out may cover together, the least-seen first
    (:mod:`~walkstream.server.bake.pvsbudget`; 0: off)."""
    margin: float = 0.3
    sampling: str = DEFAULT_SAMPLING
    """Where a cell is sampled: ``"region"`` (its outline and a grid inside, every
    ``spacing`` metres, alternating between both ends of the eye-height range),
    ``"boundary"`` (the outline at the top of the range), ``"corners"`` (the 8 box
    corners of the first bake) or ``"field"`` (the union of the dense visibility
    field's points in and around the cell, every ``field_spacing`` metres:
    :mod:`~walkstream.server.bake.fieldsampling`)."""
    spacing: float = 20.0
    """``region``/``boundary``: largest distance between points along an edge (and of
    the inside grid), metres."""
    height_step: float = 1.0
    """``region``/``boundary``: every point at one more height per this many metres of
    range (a shorter range: one height, or the two ends alternating for ``region``)."""
    split: float = 0.0
    """Adaptive sampling: add the midpoint of two sample points whose visible sets
    differ by more than this Jaccard distance (two rounds; 0: off)."""
    edge_pass: bool = False
    """Draw every triangle's edges as lines after the fill, adding the objects thinner
    than a pixel (:class:`~walkstream.server.bake.visibility.VisibilityRenderer`)."""
    thin_pass: float = DEFAULT_THIN_PASS
    """After the fill, test again the objects a face did not show whose box projects
    at most this many pixels across (narrower direction), as lines and points
    depth-tested against the fill: objects under a pixel that are not hidden enter the
    PVS (:mod:`~walkstream.server.bake.thinpass`; 0: off)."""
    thin_depth: bool = False
    """The thin pass tests against the fill's depth taken as the farthest over each
    pixel's 3 x 3 neighbours (occluders shrunk by a pixel for that test:
    :mod:`~walkstream.server.bake.thindepth`)."""
    far_band: float = DEFAULT_FAR_BAND
    """Render each sample point a second time as a horizon band this many degrees
    above and below the horizon at ``far_pixels`` across 90 degrees (the far field at
    the client's pixel size: :mod:`~walkstream.server.bake.farband`; 0: off)."""
    far_pixels: int = DEFAULT_FAR_PIXELS
    """The band's pixels across each of its four 90-degree faces."""
    far_axis: float = 0.0
    """With ``far_band``: the band is rendered also at points every this many metres
    along each cell's long axis (:func:`~walkstream.server.bake.samples.axis_points`:
    the middle of a street, where the cube's outline points are farthest; the band
    alone, not the cube); 0: only at the cube's points."""
    far_edges: bool = False
    """With ``far_band``: after the band's fill, its triangles' edges drawn again as
    one-pixel lines depth-tested against it (the renderer's ``edge_pass``, in the band
    only): a street piece hundreds of metres ahead, thinner than a band pixel, marks the
    pixels it crosses instead of falling between their centres."""
    field_spacing: float = DEFAULT_FIELD_SPACING
    """``cells="sections"`` or ``sampling="field"``: metres between the points of the dense visibility field."""
    redundancy: int | None = DEFAULT_REDUNDANCY
    """``cells="sections"``: objects a section may hold beyond what its seed point sees
    (None: derived from the field, :mod:`~walkstream.server.bake.sectionsize`)."""
    min_size: float = DEFAULT_MIN_SIZE
    """``cells="sections"``: smallest section (square metres) the first pass accepts."""
    section_shape: str = "axis"
    """``cells="sections"``: ``"axis"`` (rectangles along the x and y axes, as the paper's)
    or ``"aligned"`` (rectangles turned to the scene's prevailing street direction)."""
    section_cover: str = "walkable"
    """``cells="sections"``: ``"walkable"`` (sections over the field points whose square
    meets the scene's walkable cells: its street cells, or its grid cells where it has
    no streets) or ``"free"`` (over every free field point, as the paper's)."""

    def record(self) -> dict[str, Any]:
        """The settings as stored in a database's header (what identifies a bake).

        The section settings are stored only by a bake of sections (the field's
        spacing by a bake sampled from the field too), so that every other bake keeps
        the header (and the scene version) it had before they existed.
        """
        out = asdict(self)
        if not self.thin_pass:
            out.pop("thin_pass")  # bakes without it keep the header they had before it existed
        if not self.thin_depth:
            out.pop("thin_depth")
        if not self.far_band:
            out.pop("far_band")  # as the thin pass: bakes without it keep their header
            out.pop("far_pixels")
        if not self.far_axis:
            out.pop("far_axis")  # bakes without it keep their header
        if not self.far_edges:
            out.pop("far_edges")
        if not self.pvs_budget:
            out.pop("pvs_budget")  # bakes without it keep their header
        if self.cells != "sections":
            for name in SECTION_FIELDS:
                if name != "field_spacing" or self.sampling != "field":
                    out.pop(name)
        elif self.section_shape == "axis":
            out.pop("section_shape")
        return out

    def check(self) -> BakeSettings:
        """Raise InputError naming the first bad setting."""
        if self.cells not in ("auto", "street", "grid", "sections"):
            raise InputError(f"--cells: expected street, grid, sections or auto, got {self.cells!r}")
        if not (np.isfinite(self.field_spacing) and self.field_spacing > 0):
            raise InputError(f"--field-spacing: expected a positive number of metres, got {self.field_spacing}")
        if self.redundancy is not None and not (np.isfinite(self.redundancy) and self.redundancy >= 0):
            raise InputError(f"--redundancy: expected >= 0 objects, got {self.redundancy}")
        if self.section_shape not in SECTION_SHAPES:
            raise InputError(f"--section-shape: expected axis or aligned, got {self.section_shape!r}")
        if self.section_cover not in SECTION_COVERS:
            raise InputError(f"--section-cover: expected walkable or free, got {self.section_cover!r}")
        if not (np.isfinite(self.min_size) and self.min_size >= 0):
            raise InputError(f"--min-size: expected >= 0 square metres, got {self.min_size}")
        if self.sampling not in ("boundary", "corners", "region", "field"):
            raise InputError(f"--sampling: expected region, boundary, corners or field, got {self.sampling!r}")
        for name in ("cell_size", "max_length", "view_distance", "margin", "spacing", "height_step"):
            v = float(getattr(self, name))
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"{name.replace('_', '-')}: expected a positive number, got {v}")
        if self.resolution < 8 or self.resolution > 2048:
            raise InputError(f"resolution: expected 8..2048 pixels, got {self.resolution}")
        if self.occluder_lod not in (0, 1, 2):
            raise InputError(f"occluder LOD: expected 0, 1 or 2, got {self.occluder_lod}")
        if not 0.0 <= self.split < 1.0:
            raise InputError(f"--split: expected 0 <= split < 1 (a Jaccard distance; 0: off), got {self.split}")
        if not (np.isfinite(self.thin_pass) and 0.0 <= self.thin_pass <= 64.0):
            raise InputError(f"--thin-pass: expected 0..64 pixels (0: off), got {self.thin_pass}")
        if not (np.isfinite(self.far_band) and 0.0 <= self.far_band <= 30.0):
            raise InputError(f"--far-band: expected 0..30 degrees (0: off), got {self.far_band}")
        if not 8 <= self.far_pixels <= 4096:
            raise InputError(f"--far-pixels: expected 8..4096 pixels, got {self.far_pixels}")
        if not (np.isfinite(self.far_axis) and self.far_axis >= 0.0):
            raise InputError(f"--far-axis: expected a number of metres >= 0 (0: off), got {self.far_axis}")
        if self.far_edges and not self.far_band:
            raise InputError("--far-edges: give --far-band too (the edges are drawn in the band)")
        if self.far_axis and not self.far_band:
            raise InputError("--far-axis: give --far-band too (the axis points render the band only)")
        if self.far_band and (self.sampling == "field" or self.cells == "sections"):
            raise InputError("--far-band: works with the region, boundary and corners sampling, not with the field's")
        if self.thin_depth and not self.thin_pass:
            raise InputError("--thin-depth: give --thin-pass PX too (it sets how the thin pass tests depth)")
        if self.threshold < 0:
            raise InputError(f"threshold: expected >= 0 pixels, got {self.threshold}")
        if not (np.isfinite(self.pvs_budget) and 0.0 <= self.pvs_budget < 0.01):
            raise InputError(f"--pvs-budget: expected a share of each view's pixels in [0, 1 %), got {100 * self.pvs_budget:g} %")
        if self.pvs_budget and (self.split or self.sampling == "field" or self.cells == "sections"):
            raise InputError("--pvs-budget: works with the region, boundary and corners sampling, without --split")
        if self.bbox_crs not in ("local", "lonlat"):
            raise InputError(f"--bbox-crs: expected local or lonlat, got {self.bbox_crs!r}")
        if self.network not in ("walk", "drive"):
            raise InputError(f"--network: expected walk or drive, got {self.network!r}")
        if self.bbox is not None:
            x0, y0, x1, y1 = self.bbox
            if not (all(np.isfinite(self.bbox)) and x1 > x0 and y1 > y0):
                raise InputError(f"--bbox: expected MINX,MINY,MAXX,MAXY with MIN < MAX, got {self.bbox}")
        return self
