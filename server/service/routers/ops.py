"""Operational routes outside the versioned API: Prometheus ``/metrics``."""


from __future__ import annotations

from typing import TYPE_CHECKING

from fastapi import APIRouter, Request, Response

if TYPE_CHECKING:
    from walkstream.server.service.metrics import Metrics


__all__ = ["router"]

router = APIRouter()


@router.get(
    "/metrics",
    response_class=Response,
    responses={200: {"content": {"text/plain": {}}, "description": "Prometheus text format"}},
    summary="Prometheus metrics",
)
async def metrics(request: Request) -> Response:
    """Requests by route and status, response bytes, latency histogram (this process)."""
    m: Metrics = request.app.state.metrics
    return Response(
        m.render(request.app.state.scenes),
        media_type="text/plain; version=0.0.4; charset=utf-8",
        headers={"Cache-Control": "no-store"},
    )
