"""Navigation shared by every kind of cell: one shortest-path search for streets and rooms."""

from walkstream.shared.nav.dijkstra import shortest_paths

__all__ = ["shortest_paths"]
