"""Streaming: which cell the viewer is in, where it goes, what to fetch next, and the caches."""

from walkstream.client.stream.cache import Cache
from walkstream.client.stream.cellmap import CellMap
from walkstream.client.stream.diskcache import DiskCache
from walkstream.client.stream.predict import MotionPredictor
from walkstream.client.stream.streamer import Streamer, StreamerConfig

__all__ = ["Cache", "DiskCache", "CellMap", "MotionPredictor", "Streamer", "StreamerConfig"]
