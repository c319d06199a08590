"""The working records of a source loader: polygons and lines being loaded, and the issue log."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from walkstream.server.sources.scene import FeatureIssue
from walkstream.shared.arrays import F64

__all__ = ["PolyFeature", "LineFeature", "CleanPart", "IssueLog"]


# ------------------------------------------------------------------ records


@dataclass
class PolyFeature:
    """One polygon (a Polygon feature or one MultiPolygon part) being loaded."""

    index: int  # feature index in the file, for ordering issues
    fid: str  # feature id
    uid: str  # fid, or "fid#k" for MultiPolygon part k
    is_part: bool  # True for a MultiPolygon part
    kind: str | None  # None for a building, else street|crossroad|square|area:<kind>
    props: dict[str, Any]
    raw: list[F64]  # rings, source CRS, (n, 2)
    local: list[F64] | None = None  # rings, scene-local metres, once projected


@dataclass
class LineFeature:
    """One street line (a LineString or one MultiLineString part)."""

    index: int
    fid: str
    uid: str
    props: dict[str, Any]
    raw: F64
    local: F64 | None = None


@dataclass
class CleanPart:
    """A cleaned, valid polygon ready to become a building or street piece."""

    poly: PolyFeature
    source_id: str
    rings: list[F64]  # exterior CCW, holes CW, scene-local metres


@dataclass
class IssueLog:
    """Issues in feature order (then in the order they were found)."""

    items: list[tuple[int, int, FeatureIssue]] = field(default_factory=list)

    def add(self, index: int, feature_id: str, problem: str, action: str) -> None:
        self.items.append((index, len(self.items), FeatureIssue(feature_id, problem, action)))

    def sorted(self) -> list[FeatureIssue]:
        return [i for _, _, i in sorted(self.items, key=lambda t: (t[0], t[1]))]
