"""The scene databases a service serves, by name, each reopened when its file is replaced.

:class:`SceneRegistry` opens every database once, answers the scene listing, and at
most every :data:`RECHECK_S` seconds checks whether a served file was replaced by a
new version (its inode or modification time changed); it then reopens it and serves
the new version, with new ETags, from then on.  What one open scene serves is
:class:`~walkstream.server.service.scenes.Scene`.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Sequence

from walkstream.server.service.http import Encoded, Rep, content_digest, dump_json, encode
from walkstream.server.service.scenes import Scene
from walkstream.shared.errors import ApiError, StoreError

__all__ = ["RECHECK_S", "SceneRegistry"]

log = logging.getLogger(__name__)

RECHECK_S = 1.0
"""Seconds between checks whether a served database file was replaced by a new version."""


class SceneRegistry:
    """The scenes a service serves, by name."""

    def __init__(self, scenes: Sequence[Scene]) -> None:
        """Private: use :meth:`open`."""
        self.scenes: dict[str, Scene] = {s.name: s for s in sorted(scenes, key=lambda s: s.name)}
        self._stamps: dict[str, tuple[int, int] | None] = {
            n: _file_stamp(sc.reader.path) for n, sc in self.scenes.items()
        }
        self._checked: dict[str, float] = dict.fromkeys(self.scenes, time.monotonic())
        self._reload_lock = threading.Lock()
        self.listing: dict[Rep, Encoded] = {}
        self._encode_listing()

    def _encode_listing(self) -> None:
        listing = [{"name": s.name, "version": s.version} for s in self.scenes.values()]
        # the list changes when a file is replaced by a new version: validated with
        # the ETag on every use rather than cached for a year
        tag = content_digest(dump_json(listing))
        self.listing = {rep: encode(listing, rep, tag, "scenes") for rep in ("msgpack", "json")}

    @classmethod
    def open(cls, paths: Sequence[str | os.PathLike[str]]) -> SceneRegistry:
        """Open and validate every database; all or nothing.

        Raises
        ------
        StoreError
            No path, a database that cannot be served (see :meth:`Scene.load`), or
            two databases with the same scene name.
        """
        if not paths:
            raise StoreError("no scene database given")
        scenes: list[Scene] = []
        where: dict[str, str] = {}
        try:
            for p in paths:
                s = Scene.load(p)
                scenes.append(s)
                if s.name in where:
                    raise StoreError(
                        f"{os.fspath(p)}: scene name {s.name!r} is already served from "
                        f"{where[s.name]}; each scene needs its own name"
                    )
                where[s.name] = os.fspath(p)
        except BaseException:
            for s in scenes:
                s.close()
            raise
        return cls(scenes)

    def get(self, name: str) -> Scene:
        """The scene called ``name``.

        Raises
        ------
        ApiError
            404 naming the scene and listing the known ones.
        """
        scene = self.scenes.get(name)
        if scene is None:
            raise ApiError(
                f"unknown scene {name!r:.80}",
                status=404,
                detail={"scene": name, "known": list(self.scenes)},
            )
        now = time.monotonic()
        if now - self._checked[name] >= RECHECK_S:
            self._checked[name] = now
            if _file_stamp(scene.reader.path) != self._stamps[name]:
                scene = self._reload(scene)
        return scene

    def _reload(self, old: Scene) -> Scene:
        """Serve the new version of ``old``'s file; the old one when it cannot be loaded.

        The old scene is not closed: requests still running may be reading it (its
        connections close when the last of them lets go).
        """
        with self._reload_lock:
            current = self.scenes[old.name]
            if current is not old:  # another request reloaded it meanwhile
                return current
            path = old.reader.path
            stamp = _file_stamp(path)
            try:
                new = Scene.load(path)
            except StoreError as exc:
                log.warning("%s changed but cannot be served (%s); still serving version %s", path, exc, old.version)
                self._stamps[old.name] = stamp  # do not retry until it changes again
                return old
            if new.name != old.name:
                new.close()
                log.warning("%s now holds scene %r, not %r; still serving version %s", path, new.name, old.name, old.version)
                self._stamps[old.name] = stamp
                return old
            self.scenes[old.name] = new
            self._stamps[old.name] = stamp
            self._encode_listing()
            log.info("%s: now serving version %s (was %s)", path, new.version, old.version)
            return new

    def close(self) -> None:
        """Close every database."""
        for s in self.scenes.values():
            s.close()


def _file_stamp(path: str) -> tuple[int, int] | None:
    """What tells a file replaced by a rename from the one opened: inode and mtime."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_ino, st.st_mtime_ns)
