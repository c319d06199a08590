"""Rewriting: object geometry rebuilt from parameters, highest priority first."""

from walkstream.client.rewrite.geometry import ObjectGeometry, geometry_of, rebuild, rebuild_batch
from walkstream.client.rewrite.pool import BATCH, RewritePool

__all__ = ["RewritePool", "ObjectGeometry", "geometry_of", "rebuild", "rebuild_batch", "BATCH"]
