"""``--truth-every N``: note what the client drew on every N-th frame, compare with the truth after the walk.

One recorder for every scene kind.  During the walk the frame loop hands every N-th
frame to :meth:`TruthRecorder.record` with what it drew and what it lacked -- the
camera, the city objects drawn with their LOD, the objects its visible set named and
which of them had arrived and were built, the room parts drawn, the room cells
visible whose contents had not arrived, the fog in force -- which only *notes* them
(:class:`~walkstream.client.truth.notes.FrameNote`) and draws nothing, so the walk's
figures are the same with and without the truth.  After the walk,
:meth:`TruthRecorder.finish` does the work off the clock: it fetches what the scene
holds on an unshaped path (:mod:`walkstream.client.truth.scene`: every object, every
room cell's contents), draws every object at LOD2 and every room part
(:class:`~walkstream.client.truth.render.TruthRenderer`) and produces the scene's
figures:

- city objects only (a city walk): each frame drawn again through the client's
  renderer and compared in colour and id, missing pixels by cause, the worst frame as
  images (:mod:`walkstream.client.truth.missing`; the figures of
  :func:`~walkstream.client.report.truth.summarise_truth`); and its colour error: the
  client's picture (the coarser forms it drew are given to the truth renderer,
  :func:`~walkstream.client.truth.picture.forms_of`) against the full scene, with
  the frame of the largest error as images;
- room cells (an interior walk, and a crossing walk's streets and rooms): the culled
  pixels and the pinholes (:mod:`walkstream.client.truth.culled`), poses in solid
  geometry refused (:mod:`walkstream.client.truth.solid`), with the fog hidden and the
  tightness for an interior, the frames that knew no visible set yet and the worst
  frame for a crossing; the worst frame as images beside its truth, with a mask of its
  culled pixels by cell (:mod:`walkstream.client.truth.culledview`); and the colour
  error of what the client drew against the full scene without fog, causes ``fog``
  and ``culled`` among them, with the frame of the largest error as images
  (:mod:`walkstream.client.truth.roomcolour`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import httpx
import numpy as np
from numpy.typing import ArrayLike, NDArray

from walkstream.client.report.colour import ColourLog, summarise_colour
from walkstream.client.report.truth import TruthLog, summarise_truth
from walkstream.client.truth.antialias import POINT, Sampling
from walkstream.client.truth.culled import (
    CROSSING_FIGURES,
    INTERIOR_FIGURES,
    CulledRow,
    culled_figures,
)
from walkstream.client.truth.culledview import CulledFrame, culled_view, worst_row
from walkstream.client.truth.horizon import horizon_figures
from walkstream.client.truth.missing import (
    ColourWorst,
    ComparedFrame,
    WorstFrame,
    missing_figures,
    needed_objects,
)
from walkstream.client.truth.notes import FrameNote
from walkstream.client.truth.picture import Overlay, forms_of
from walkstream.client.truth.pop import PopMeter, summarise_pop
from walkstream.client.truth.render import TruthRenderer
from walkstream.client.truth.roomcolour import room_colour
from walkstream.client.truth.scene import TruthScene, fetch_contents
from walkstream.client.truth.seam import SEAM_KINDS, seam_figures
from walkstream.client.truth.solid import SolidProbe
from walkstream.client.truth.standin import impostor_overlay
from walkstream.shared.camera import perspective
from walkstream.shared.errors import InputError, WalkstreamError
from walkstream.shared.scene.placement import ContentsPlacement

__all__ = [
    "TRUTH_VIEW_DISTANCE",
    "INTERIOR_FAR_M",
    "interior_far_m",
    "TruthResult",
    "TruthRecorder",
]

#: The truth draws every object whose bounding box comes this close to the eye: the
#: bake's default view distance (the API does not carry a scene's own).
TRUTH_VIEW_DISTANCE = 800.0

#: The least far plane of an interior's truth (metres); a larger building's is its extent
#: (:func:`interior_far_m`).
INTERIOR_FAR_M = 100.0

#: Beyond the building's diagonal, metres (the near plane and rounding never clip a far corner).
_FAR_SLACK_M = 1.0


def interior_far_m(topology: Any) -> float:
    """The far plane of an interior's truth: the diagonal of the box holding every cell
    (outlines, floors and tops; the topology's), so that no point of the building is
    beyond it from any eye inside (the production hall's diagonal is 116 m), and at
    least :data:`INTERIOR_FAR_M`.

    ``topology`` is a :class:`~walkstream.shared.roomwire.Topology` (its ``cells``, each
    with an ``outline`` ``(n, 2)`` and ``zmin``/``zmax``)."""
    pts = [np.asarray(c.outline, np.float64).reshape(-1, 2) for c in topology.cells if len(c.outline)]
    if not pts:
        return INTERIOR_FAR_M
    xy = np.concatenate(pts)
    z = [v for c in topology.cells if len(c.outline) for v in (float(c.zmin), float(c.zmax))]
    span = np.array([*np.ptp(xy, axis=0), max(z) - min(z)])
    if not np.all(np.isfinite(span)):
        return INTERIOR_FAR_M
    return max(INTERIOR_FAR_M, float(np.linalg.norm(span)) + _FAR_SLACK_M)


@dataclass(frozen=True)
class TruthResult:
    """The scene's ``truth`` figures, the compared frames, and why there are none when the truth failed."""

    log: TruthLog
    """One row per frame compared in colour (a walk with rooms: against the full scene without fog,
    :mod:`walkstream.client.truth.roomcolour`)."""
    worst: WorstFrame | None = None
    error: str | None = None
    frames: list[ComparedFrame] = field(default_factory=list, repr=False)
    """Every frame compared in colour, in detail."""
    figures: dict[str, Any] | None = None
    """The ``truth`` object of ``report.json`` (None when a walk with rooms found no truth)."""
    colour_worst: ColourWorst | None = None
    """The compared frame with the largest colour error, as images."""
    culled: list[CulledRow] = field(default_factory=list, repr=False)
    """A walk with rooms: each noted frame's culled pixels and pinholes (or its refusal)."""
    culled_worst: CulledFrame | None = None
    """A walk with rooms: the frame with the most culled pixels as images (None: none culled any)."""


class TruthRecorder:
    """Notes every ``every``-th frame and compares them with the truth after the walk.

    Parameters
    ----------
    every : int
        Compare frames 0, N, 2N, ... (>= 1).
    size : (int, int)
        The client's frame size.
    fov_deg, near, far : float
        The truth's projection: the client's field of view and near plane (a city's
        0.5 m, rooms' and a crossing's 0.1 m), a far plane beyond what the walk sees.
    view_distance : float
        A city's objects within this distance of the eye are in its truth.
    ground_z : float, optional
        Height of the ground plane both frames draw (a scene with outdoor space:
        :data:`~walkstream.shared.ground.GROUND_Z`); None: none (an interior).
    viewer_ppd : float, optional
        The display's pixels per degree of a city's viewer-scale (S-CIELAB) colour
        figures (``--viewer-ppd``; the view's own is
        :func:`~walkstream.client.truth.picture.view_ppd`); None: not measured.
    truth_samples, picture_samples : Sampling
        How a city's colour error samples a pixel of the full scene (``--truth-samples``)
        and of the client's picture (``--picture-samples``)
        (:mod:`walkstream.client.truth.antialias`); one sample at the centre by default.
        The id comparison, and a walk with rooms, stay point-sampled.
    facade_filter : {"point", "anisotropic"}
        How the client read its facade pictures (``--facade-filter``): the picture the
        colour error redraws reads them so too.
    """

    def __init__(
        self,
        every: int,
        size: tuple[int, int],
        fov_deg: float,
        *,
        near: float,
        far: float,
        view_distance: float = TRUTH_VIEW_DISTANCE,
        ground_z: float | None = None,
        viewer_ppd: float | None = None,
        truth_samples: Sampling = POINT,
        picture_samples: Sampling = POINT,
        facade_filter: str = "point",
    ) -> None:
        if int(every) < 1:
            raise InputError(f"--truth-every {every}: expected a frame count >= 1")
        self.every = int(every)
        self.size = (int(size[0]), int(size[1]))
        self.fov_deg, self.near, self.far = float(fov_deg), float(near), float(far)
        self.proj = perspective(fov_deg, self.size[0] / self.size[1], near, far)
        self.view_distance = float(view_distance)
        self.ground_z = None if ground_z is None else float(ground_z)
        self.viewer_ppd = None if viewer_ppd is None else float(viewer_ppd)
        """The display's pixels per degree of the viewer-scale colour figures (None: not measured)."""
        self.truth_samples = truth_samples
        """How a city's colour error samples the full scene's pixels."""
        self.picture_samples = picture_samples
        """How a city's colour error samples the client picture's pixels."""
        self.facade_filter = facade_filter
        """How the redrawn picture reads facade pictures, as the client did."""
        self.notes: list[FrameNote] = []
        self.overlay: Overlay | None = None
        """The ``impostor`` hook of the colour error (:mod:`walkstream.client.truth.picture`):
        set by a part that draws images in place of objects; None: geometry only, or,
        when the notes carry impostors, their quads painted by the truth renderer
        (:func:`~walkstream.client.truth.standin.impostor_overlay`)."""

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
        cell: int | None = None,
        pvs: ArrayLike | None = (),
        received: Iterable[int] = (),
        built: Iterable[int] = (),
        geoms: Sequence[Any] = (),
        lods: ArrayLike = (),
        parts: Iterable[tuple[int, int]] = (),
        waiting: Iterable[int] = (),
        fog: float = math.inf,
        impostors: Iterable[tuple[int, Any]] = (),
        facades: Iterable[Any] = (),
        walls: Iterable[Any] = (),
        wall_quads: Iterable[Any] = (),
        seam_walls: Iterable[Any] = (),
    ) -> None:
        """Note one frame (cheap: ids and references to meshes already built).

        Parameters
        ----------
        frame, t : int, float
            The frame's index and time.
        eye, view : (3,), (4, 4)
            Its camera.
        cell : int, optional
            The client's current cell.
        pvs : ints or None
            The city objects its visible set names; None when it knew no visible set yet.
        received, built : ints
            Objects whose parameters had arrived, whose geometry was built.
        geoms, lods
            The :class:`~walkstream.client.rewrite.geometry.ObjectGeometry` the frame's
            allocation ran over and the LOD chosen for each (-1: not drawn).
        parts : (cell, part) pairs
            The room parts drawn.
        waiting : ints
            Room cells visible whose contents had not arrived.
        fog : float
            The fog distance in force (``inf``: none).
        impostors : (object id, quad) pairs
            The impostors drawn (:data:`~walkstream.client.draw.quads.Quad`).
        facades : quads
            The facade textures drawn over boxes (:data:`~walkstream.client.draw.quads.Quad`).
        walls : (4, 3) arrays
            The corners of each virtual wall drawn closed (its texture alone).
        wall_quads : quads
            Every virtual wall drawn (:data:`~walkstream.client.draw.quads.Quad`), painted
            into the colour truth's client picture.
        seam_walls : SeamWall
            The same walls for the seam measure (:class:`~walkstream.client.truth.seam.SeamWall`).
        """
        drawn = tuple(
            (int(g.id), int(lod), g.meshes[lod])
            for g, lod in zip(geoms, np.asarray(lods).tolist(), strict=True)
            if lod >= 0 and g.meshes[lod] is not None
        )
        self.notes.append(
            FrameNote(
                frame=int(frame),
                t=float(t),
                eye=np.array(eye, np.float64).reshape(3),
                view=np.array(view),
                cell=None if cell is None else int(cell),
                pvs=None if pvs is None else np.array(pvs, np.int64).reshape(-1),
                received=np.unique(np.fromiter((int(i) for i in received), np.int64)),
                built=np.unique(np.fromiter((int(i) for i in built), np.int64)),
                drawn=drawn,
                parts=tuple((int(c), int(k)) for c, k in parts),
                waiting=tuple(int(c) for c in waiting),
                fog=float(fog),
                impostors=tuple((int(i), q) for i, q in impostors),
                facades=tuple(facades),
                walls=tuple(np.asarray(c, np.float64) for c in walls),
                wall_quads=tuple(wall_quads),
                seam_walls=tuple(seam_walls),
            )
        )

    async def finish(
        self,
        transport: httpx.AsyncBaseTransport,
        base_url: str,
        scene: str,
        *,
        clock: Any,
        cells: Iterable[int] = (),
        leave_out: Iterable[int] = (),
        placements: Sequence[ContentsPlacement] = (),
        t_first_perfect: float | None = None,
        progress: Callable[[int, int], None] | None = None,
    ) -> TruthResult:
        """Compare every noted frame with its truth (after the walk; see the module docs).

        Parameters
        ----------
        transport, base_url, scene
            Where the scene is served: the inner transport, not the walk's link.
        clock : Clock
            The replay's clock (its requests are timed on it; run under ``clock.busy()``).
        cells : ints
            The scene's room cells (none: a city's figures).
        leave_out : ints
            Objects the truth does not draw (a crossing's entrance building: its
            parameters are a stand-in inside the rooms' shell, which stands for it).
        placements : ContentsPlacement
            Where a crossing's interior stands (its contents come in its own frame).
        t_first_perfect : float, optional
            ``t`` of the walk's first perfect frame (a city's worst frame is looked for after it first).

        A failure to reach the scene or to draw is returned as ``error``, not raised:
        the walk's own report still gets written.
        """
        cells = [int(c) for c in cells]
        if not cells and not self.notes:
            figures = summarise_truth(TruthLog.empty(), t_first_perfect) | {"below_horizon": horizon_figures(())}
            return TruthResult(TruthLog.empty(), figures=figures)
        try:
            ts = await TruthScene.fetch(transport, base_url, scene)
        except (WalkstreamError, httpx.HTTPError) as exc:
            return self._failed(exc, cells, t_first_perfect)
        truth: TruthRenderer | None = None
        try:
            if not cells:
                pvs_of = await self._pvs_of(ts)
                truth = TruthRenderer(
                    ts.lod2(needed_objects(ts, self.notes, self.view_distance)), self.size,
                    fov_deg=self.fov_deg, near=self.near, far=self.far, view_distance=self.view_distance,
                    forms=forms_of(self.notes),
                    ground_z=self.ground_z,
                    facade_filter=self.facade_filter,
                )
                overlay = self.overlay
                if overlay is None and any(st.impostors or st.wall_quads or st.facades for st in self.notes):
                    overlay = impostor_overlay(truth, self.proj)
                pop = PopMeter() if any(st.impostors for st in self.notes) else None
                log, worst, frames, cworst = missing_figures(
                    ts, truth, self.notes, pvs_of, self.proj, t_first_perfect, progress, overlay, pop, self.viewer_ppd,
                    self.truth_samples, self.picture_samples,
                )
                figures = summarise_truth(log, t_first_perfect)
                aa = not (self.truth_samples.point and self.picture_samples.point)
                if aa and isinstance(figures.get("colour"), dict):  # which sampling the colour figures are of
                    figures["colour"]["truth_samples"] = str(self.truth_samples)
                    figures["colour"]["picture_samples"] = str(self.picture_samples)
                if pop is not None:
                    figures["pop"] = summarise_pop(pop)
                figures["below_horizon"] = horizon_figures(f.below for f in frames)
                return TruthResult(log, worst, None, frames, figures, cworst)
            skip = {int(i) for i in leave_out}
            objects = ts.lod2([i for i in sorted(ts.params) if i not in skip])
            await ts.close()
            rooms = await fetch_contents(transport, base_url, scene, cells, clock, placements)
            truth = TruthRenderer(objects, self.size, rooms=rooms, fov_deg=self.fov_deg, near=self.near,
                                  far=self.far, two_sided=True, ground_z=self.ground_z,
                                  forms=forms_of(n for n in self.notes if n.pvs is not None))
            rows: list[CulledRow] = []
            solid = SolidProbe(rooms)
            figures = culled_figures(truth, self.notes, CROSSING_FIGURES if objects else INTERIOR_FIGURES, progress,
                                     solid=solid, rows=rows)
            top = worst_row(rows)
            view = None if top is None else culled_view(truth, next(n for n in self.notes if n.frame == top.frame))
            rc = room_colour(truth, self.notes, solid=solid, viewer_ppd=self.viewer_ppd)
            figures["colour"] = summarise_colour(rc.log.colour or ColourLog.empty())
            if rc.seam is not None:
                figures["seam"] = {**summarise_pop(rc.seam, SEAM_KINDS), **seam_figures(rc.seam)}
            return TruthResult(rc.log, figures=figures, culled=rows, culled_worst=view, colour_worst=rc.worst)
        except (WalkstreamError, httpx.HTTPError) as exc:
            return self._failed(exc, cells, t_first_perfect)
        finally:
            if truth is not None:
                truth.release()
            await ts.close()

    async def _pvs_of(self, ts: TruthScene) -> list[NDArray[np.int64] | None]:
        """Each note's PVS: the client's, or the service's where the client knew none."""
        out: list[NDArray[np.int64] | None] = []
        for st in self.notes:
            if st.pvs is not None:
                out.append(st.pvs)
                continue
            cid = st.cell if st.cell is not None else await ts.locate(st.eye[0], st.eye[1])
            out.append(await ts.cell_pvs(cid) if cid is not None else np.zeros(0, np.int64))
        return out

    @staticmethod
    def _failed(exc: BaseException, cells: list[int], t_first_perfect: float | None) -> TruthResult:
        error = str(exc) if isinstance(exc, WalkstreamError) else f"ground truth: {exc}"
        figures = None if cells else summarise_truth(TruthLog.empty(), t_first_perfect)
        return TruthResult(TruthLog.empty(), error=error, figures=figures)
