"""``--truth-every N``: note what the client had and drew on every N-th frame, compare after the walk.

During the walk the frame loop hands every N-th frame to :meth:`TruthRecorder.record`,
which only *notes* the client's state -- the camera, the current cell and its PVS as
the client knows it, which objects it had received and rebuilt, and which meshes it
drew at which LOD -- and draws nothing, so the walk's figures are the same with and
without the truth.  After the walk, :meth:`TruthRecorder.finish` does the work off
the clock: it fetches every object of the scene on an unshaped path
(:class:`~walkstream.client.truth.scene.TruthScene`), draws each noted frame twice --
the client's own choice of objects and LODs through the client's renderer
(:meth:`~walkstream.client.draw.frames.FrameRenderer.draw` and its separate id pass
:meth:`~walkstream.client.draw.frames.FrameRenderer.draw_ids`), and the truth through
:class:`~walkstream.client.truth.render.TruthRenderer` -- and compares them
(:func:`~walkstream.client.truth.compare.compare_frame`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import httpx
import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.report.truth import TruthLog
from walkstream.client.truth.compare import CAUSES, compare_frame, missing_mask
from walkstream.client.truth.render import TruthRenderer
from walkstream.client.truth.scene import TruthScene
from walkstream.shared.errors import InputError, WalkstreamError
from walkstream.shared.records import Mesh

__all__ = [
    "TRUTH_VIEW_DISTANCE",
    "FrameState",
    "ComparedFrame",
    "WorstFrame",
    "TruthResult",
    "TruthRecorder",
]

#: The truth draws every object whose bounding box comes this close to the eye: the
#: bake's default view distance (the API does not carry a scene's own).
TRUTH_VIEW_DISTANCE = 800.0


@dataclass(frozen=True)
class FrameState:
    """What the client had and drew on one compared frame (noted during the walk)."""

    frame: int
    t: float
    eye: NDArray[np.float64]
    view: NDArray[np.float32]
    cell: int | None
    """The client's current cell (None while it knows none)."""
    pvs: NDArray[np.int64] | None
    """That cell's PVS as the client has it; None when the cell record had not arrived."""
    received: NDArray[np.int64]
    built: NDArray[np.int64]
    drawn: tuple[tuple[int, int, Mesh], ...]
    """``(object id, lod, mesh)`` of each object drawn, in the client's draw order."""


@dataclass(frozen=True)
class ComparedFrame:
    """One compared frame: its camera, its cell, what the truth showed and what was missing."""

    frame: int
    t: float
    cell: int | None
    eye: NDArray[np.float64]
    view: NDArray[np.float32]
    pixels: int
    differing: int
    """Pixels whose colour differs from the truth."""
    missing_px: NDArray[np.int64]
    """(6,) missing pixels per cause (:data:`~walkstream.client.truth.compare.CAUSES` order)."""
    shown: dict[int, int]
    """Pixels of each object in the truth."""
    missing: dict[int, int]
    """Missing pixels of each object (whatever the cause)."""


@dataclass(frozen=True)
class WorstFrame:
    """The compared frame with the most missing pixels, as images (``(h, w, 3) uint8``)."""

    frame: int
    t: float
    missing: NDArray[np.float64]
    """(6,) shares of its pixels missing per cause."""
    differing: float
    client: NDArray[np.uint8]
    truth: NDArray[np.uint8]
    mask: NDArray[np.uint8]


@dataclass(frozen=True)
class TruthResult:
    """The compared frames, the worst one, and why there are none when the truth failed."""

    log: TruthLog
    worst: WorstFrame | None = None
    error: str | None = None
    frames: list[ComparedFrame] = field(default_factory=list, repr=False)
    """Every compared frame in detail."""


class TruthRecorder:
    """Notes every ``every``-th frame and compares them with the truth after the walk.

    Parameters
    ----------
    every : int
        Compare frames 0, N, 2N, ... (>= 1).
    size : (int, int)
        The client's frame size.
    proj : (4, 4) float
        The client's projection.
    view_distance : float
        Objects within this distance of the eye are in the truth.
    fog_distance : float, optional
        The fog distance in force (None: the scene has no fog).
    """

    def __init__(
        self,
        every: int,
        size: tuple[int, int],
        proj: ArrayLike,
        *,
        view_distance: float = TRUTH_VIEW_DISTANCE,
        fog_distance: float | None = None,
    ) -> None:
        if int(every) < 1:
            raise InputError(f"--truth-every {every}: expected a frame count >= 1")
        self.every = int(every)
        self.size = (int(size[0]), int(size[1]))
        self.proj = np.asarray(proj, np.float32)
        self.view_distance = float(view_distance)
        self.fog_distance = fog_distance
        self.states: list[FrameState] = []

    def due(self, frame: int) -> bool:
        """Whether frame ``frame`` is one to compare."""
        return frame % self.every == 0

    def record(
        self,
        *,
        frame: int,
        t: float,
        eye: ArrayLike,
        view: ArrayLike,
        cell: int | None,
        pvs: ArrayLike | None,
        received: Sequence[int],
        built: Sequence[int],
        geoms: Sequence[Any],
        lods: ArrayLike,
    ) -> None:
        """Note one frame's state (cheap: ids and references to meshes already built).

        ``geoms`` are the :class:`~walkstream.client.rewrite.geometry.ObjectGeometry` the
        frame's allocation ran over and ``lods`` the LOD chosen for each (-1: not drawn).
        """
        drawn = tuple(
            (int(g.id), int(lod), g.meshes[lod])
            for g, lod in zip(geoms, np.asarray(lods).tolist(), strict=True)
            if lod >= 0 and g.meshes[lod] is not None
        )
        self.states.append(
            FrameState(
                frame=int(frame),
                t=float(t),
                eye=np.array(eye, np.float64).reshape(3),
                view=np.array(view, np.float32),
                cell=None if cell is None else int(cell),
                pvs=None if pvs is None else np.array(pvs, np.int64),
                received=np.unique(np.asarray(received, np.int64)),
                built=np.unique(np.asarray(built, np.int64)),
                drawn=drawn,
            )
        )

    async def finish(
        self,
        transport: httpx.AsyncBaseTransport,
        base_url: str,
        scene: str,
        *,
        t_first_perfect: float | None,
        progress: Callable[[int, int], None] | None = None,
    ) -> TruthResult:
        """Compare every noted frame with its truth (after the walk; see the module docs).

        A failure to reach the scene or to draw is returned as ``error``, not raised:
        the walk's own report still gets written.
        """
        if not self.states:
            return TruthResult(TruthLog.empty())
        try:
            ts = await TruthScene.fetch(transport, base_url, scene)
        except WalkstreamError as exc:
            return TruthResult(TruthLog.empty(), error=str(exc))
        except httpx.HTTPError as exc:
            return TruthResult(TruthLog.empty(), error=f"ground truth: {exc}")
        try:
            pvs_of: list[NDArray[np.int64] | None] = []
            for st in self.states:
                if st.pvs is not None:
                    pvs_of.append(st.pvs)
                    continue
                cid = st.cell if st.cell is not None else await ts.locate(st.eye[0], st.eye[1])
                pvs_of.append(await ts.cell_pvs(cid) if cid is not None else np.zeros(0, np.int64))
            return self._compare(ts, pvs_of, t_first_perfect, progress)
        except WalkstreamError as exc:
            return TruthResult(TruthLog.empty(), error=str(exc))
        finally:
            await ts.close()

    def _needed(self, ts: TruthScene) -> list[int]:
        """Objects any compared frame may show: within the view distance of its eye, or drawn."""
        ids, lo, hi = ts.boxes()
        need = np.zeros(len(ids), bool)
        for st in self.states:
            gap = np.maximum(np.maximum(lo - st.eye, st.eye - hi), 0.0)
            need |= np.einsum("nk,nk->n", gap, gap) <= self.view_distance**2
        drawn = {i for st in self.states for i, _, _ in st.drawn}
        return sorted(set(ids[need].tolist()) | (drawn & set(ts.params)))

    def _compare(
        self,
        ts: TruthScene,
        pvs_of: list[NDArray[np.int64] | None],
        t_first_perfect: float | None,
        progress: Callable[[int, int], None] | None,
    ) -> TruthResult:
        from walkstream.client.draw.frames import FrameRenderer

        fov = _fov_deg(self.proj)
        truth = TruthRenderer(
            ts.lod2(self._needed(ts)), self.size, fov_deg=fov, view_distance=self.view_distance
        )
        client = FrameRenderer(self.size, fov_deg=fov, ctx=truth.ctx)
        rows: list[tuple[int, float, float, NDArray[np.float64]]] = []
        compared: list[ComparedFrame] = []
        worst: WorstFrame | None = None
        worst_key = (-1, -1.0)
        n = len(self.states)
        try:
            for k, (st, pvs) in enumerate(zip(self.states, pvs_of, strict=True)):
                keys = [(i, lod) for i, lod, _ in st.drawn]
                wanted = set(keys)
                for key in client.keys():
                    if key not in wanted:
                        client.forget(key)
                for i, lod, mesh in st.drawn:
                    client.upload((i, lod), mesh)
                client.draw(keys, st.view, self.proj)
                c_rgb = client.snapshot()
                c_ids = client.draw_ids(keys, st.view, self.proj)
                t_rgb, t_ids = truth.render(st.eye, st.view, self.proj, also=[i for i, _, _ in st.drawn])
                knows = st.pvs is not None
                fogged: list[int] = []
                if self.fog_distance is not None:
                    fogged = _beyond(ts, st.eye, self.fog_distance)
                err = compare_frame(
                    t_ids,
                    t_rgb,
                    c_ids,
                    c_rgb,
                    pvs=pvs,
                    # without the cell record the client knows no PVS: nothing of it is
                    # usable yet, whatever happens to be in its cache
                    received=st.received if knows else (),
                    built=st.built if knows else (),
                    drawn={i: lod for i, lod, _ in st.drawn},
                    fogged=fogged,
                )
                tid = t_ids.astype(np.int64) - 1
                compared.append(
                    ComparedFrame(
                        st.frame, st.t, st.cell, st.eye, st.view, err.pixels, err.differing,
                        err.missing, _counts(tid[tid >= 0]), _counts(tid[err.cause >= 0]),
                    )
                )
                share = err.missing_share
                rows.append((st.frame, st.t, err.differing / err.pixels, share))
                after = t_first_perfect is not None and st.t >= t_first_perfect
                key = (int(after), err.missed / err.pixels)
                if key > worst_key:
                    worst_key = key
                    worst = WorstFrame(
                        st.frame, st.t, share, err.differing / err.pixels, c_rgb, t_rgb,
                        missing_mask(t_rgb, err.cause),
                    )
                if progress is not None:
                    progress(k + 1, n)
        finally:
            client.release()
            truth.release()
        log = TruthLog(
            np.array([r[0] for r in rows], np.int64),
            np.array([r[1] for r in rows]),
            np.array([r[2] for r in rows]),
            np.array([r[3] for r in rows]).reshape(-1, len(CAUSES)),
        )
        return TruthResult(log, worst, None, compared)


def _counts(ids: NDArray[np.int64]) -> dict[int, int]:
    u, n = np.unique(ids, return_counts=True)
    return dict(zip(u.tolist(), n.tolist(), strict=True))


def _fov_deg(proj: NDArray[np.float32]) -> float:
    """The vertical field of view of a perspective matrix (``proj[1, 1] = 1 / tan(fov / 2)``)."""
    return float(np.degrees(2.0 * np.arctan(1.0 / float(proj[1, 1]))))


def _beyond(ts: TruthScene, eye: NDArray[np.float64], distance: float) -> list[int]:
    ids, lo, hi = ts.boxes()
    gap = np.maximum(np.maximum(lo - eye, eye - hi), 0.0)
    out: list[int] = ids[np.einsum("nk,nk->n", gap, gap) > distance**2].tolist()
    return out
