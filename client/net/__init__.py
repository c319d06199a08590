"""The client's network: typed, bounded access to the API, over a shaped (or real) link."""

from walkstream.client.net.api import SceneClient, TransferStats
from walkstream.client.net.link import LinkProfile, LinkStats, ShapedTransport

__all__ = ["SceneClient", "TransferStats", "LinkProfile", "LinkStats", "ShapedTransport"]
