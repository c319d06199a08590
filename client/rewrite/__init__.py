"""Rewriting: object geometry rebuilt from parameters, highest priority first."""

from walkstream.client.rewrite.pool import BATCH, RewritePool
from walkstream.client.rewrite.rebuild import ObjectGeometry, geometry_of, rebuild, rebuild_batch

__all__ = ["RewritePool", "ObjectGeometry", "geometry_of", "rebuild", "rebuild_batch", "BATCH"]
