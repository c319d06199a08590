"""Rewriting: object geometry rebuilt from parameters, highest priority first."""

from walkstream.client.rewrite.pool import ObjectGeometry, RewritePool, geometry_of, rebuild

__all__ = ["RewritePool", "ObjectGeometry", "geometry_of", "rebuild"]
