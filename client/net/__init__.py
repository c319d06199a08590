"""The client's network: typed, bounded access to the API, over a shaped (or real) link."""

from walkstream.client.net.api import SceneClient
from walkstream.client.net.link import LinkProfile, LinkStats, ShapedTransport
from walkstream.client.net.transferstats import TransferStats

__all__ = ["SceneClient", "TransferStats", "LinkProfile", "LinkStats", "ShapedTransport"]
