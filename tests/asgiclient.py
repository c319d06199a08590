"""A synchronous face on ``httpx.AsyncClient`` over an ASGI app, for tests of the service in process."""

from __future__ import annotations

import asyncio

import httpx

__all__ = ["Http"]


class Http:
    """A synchronous face on ``httpx.AsyncClient`` over the ASGI app (one event loop)."""

    def __init__(self, app: object) -> None:
        self.loop = asyncio.new_event_loop()
        self.client = httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://testserver")  # type: ignore[arg-type]

    def get(self, url: str, **kw: object) -> httpx.Response:
        return self.loop.run_until_complete(self.client.get(url, **kw))  # type: ignore[arg-type]

    def post(self, url: str, **kw: object) -> httpx.Response:
        return self.loop.run_until_complete(self.client.post(url, **kw))  # type: ignore[arg-type]

    def close(self) -> None:
        self.loop.run_until_complete(self.client.aclose())
        self.loop.close()
