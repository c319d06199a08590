"""What a scene source (generated city or GeoJSON footprints) hands to the bake."""

from __future__ import annotations

from dataclasses import dataclass

from walkstream.shared.records import AreaParams, BuildingParams, StreetParams

__all__ = ["FeatureIssue", "SourceScene"]


@dataclass(frozen=True, slots=True)
class FeatureIssue:
    """A problem found in one input feature and what was done about it.

    ``action`` is ``"repaired"`` (the feature was kept after a documented fix) or
    ``"skipped"`` (the feature was left out).
    """

    feature_id: str
    problem: str
    action: str


@dataclass(frozen=True, slots=True)
class SourceScene:
    """Buildings, street pieces and typed areas in scene-local metres, plus where that frame sits.

    ``origin`` is the position of local (0, 0) in ``crs`` (projected metres, float64);
    local coordinates = projected coordinates - origin.  Object ids are unique over
    buildings, streets and areas together (buildings first, areas last).  ``passages`` are the ids of
    street pieces that pass under buildings (``tunnel=building_passage``): their
    cells are not clipped by footprints.  ``notes`` are one-line remarks for the
    summary (what a reader left out on purpose, and how much).
    """

    name: str
    crs: str
    origin: tuple[float, float]
    buildings: tuple[BuildingParams, ...]
    streets: tuple[StreetParams, ...]
    issues: tuple[FeatureIssue, ...] = ()
    passages: frozenset[int] = frozenset()
    notes: tuple[str, ...] = ()
    areas: tuple[AreaParams, ...] = ()
