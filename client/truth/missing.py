"""Missing pixels by cause: a city walk's frames drawn again, each beside its truth, compared in colour and id.

The figures of a walk over city objects only.  Each noted frame is drawn twice -- the
client's own choice of objects and LODs through the client's renderer
(:meth:`~walkstream.client.draw.frames.FrameRenderer.draw` and its separate id pass
:meth:`~walkstream.client.draw.frames.FrameRenderer.draw_ids`), and the truth
(:meth:`~walkstream.client.truth.render.TruthRenderer.colour_frame`: every object
within the view distance at LOD2, and whatever the client drew) -- and compared
(:func:`~walkstream.client.truth.compare.compare_frame`): differing pixels, and missing
pixels attributed to a cause, (a) the PVS to (f) the fog.  A PVS object not received or
not built is late (causes (b), (c)); one drawn at a coarser LOD is the budget's (d);
what is left is culled (e).  Impostors the frame drew are drawn over its meshes; a
building drawn as its image counts as shown where the image painted
(:func:`~walkstream.client.truth.standin.stand_in_ids`).

Each frame's colour error (:mod:`walkstream.client.truth.colour`) compares the full
scene with the client's picture drawn by the same truth renderer
(:func:`~walkstream.client.truth.picture.colour_error`: the objects the client drew at
the LOD it drew them; the renderer must hold their coarser forms,
:func:`~walkstream.client.truth.picture.forms_of`); the frame with the largest mean
error (from the first perfect frame on first) is kept as images
(:class:`ColourWorst`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from walkstream.client.report.colour import ColourLog
from walkstream.client.report.truth import TruthLog
from walkstream.client.truth.antialias import POINT, Sampling
from walkstream.client.truth.colour import COLOUR_CAUSES
from walkstream.client.truth.compare import CAUSES, compare_frame, missing_mask
from walkstream.client.truth.horizon import below_horizon, horizon_shares
from walkstream.client.truth.notes import FrameNote
from walkstream.client.truth.picture import Overlay, colour_error
from walkstream.client.truth.pop import PopMeter, held_impostors, held_objects, pop_frame
from walkstream.client.truth.render import TruthRenderer
from walkstream.client.truth.scene import TruthScene
from walkstream.client.truth.standin import stand_in_ids

__all__ = ["ComparedFrame", "WorstFrame", "ColourWorst", "needed_objects", "missing_figures"]


@dataclass(frozen=True)
class ComparedFrame:
    """One compared frame: its camera, its cell, what the truth showed and what was missing."""

    frame: int
    t: float
    cell: int | None
    eye: NDArray[np.float64]
    view: NDArray[np.floating[Any]]
    pixels: int
    differing: int
    """Pixels whose colour differs from the truth."""
    missing_px: NDArray[np.int64]
    """(6,) missing pixels per cause (:data:`~walkstream.client.truth.compare.CAUSES` order)."""
    shown: dict[int, int]
    """Pixels of each object in the truth."""
    missing: dict[int, int]
    """Missing pixels of each object (whatever the cause)."""
    below: tuple[float, float] = (0.0, 0.0)
    """The client's frame below the horizon: shares in the sky's colour and with no object
    (:func:`~walkstream.client.truth.horizon.horizon_shares`)."""


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
class ColourWorst:
    """The compared frame with the largest colour error, as images."""

    frame: int
    t: float
    mean_error: float
    """Mean absolute linear-RGB error per pixel and channel, 0..1."""
    visible: float
    """Share of its pixels over the visible threshold."""
    psnr_db: float
    client: NDArray[np.uint8]
    """``(h, w, 3)`` the client's picture (drawn by the truth renderer)."""
    truth: NDArray[np.uint8]
    """``(h, w, 3)`` the full scene."""
    delta_e: NDArray[np.float32]
    """``(h, w)`` ΔE00 per pixel."""
    visible_scielab: float | None = None
    """Share of its pixels over the visible threshold at the viewer's scale (S-CIELAB)."""
    delta_e_scielab: NDArray[np.float32] | None = None
    """``(h, w)`` ΔE00 per pixel of the S-CIELAB-filtered pictures."""
    viewer_ppd: float | None = None
    """The display's pixels per degree of the S-CIELAB figures."""


def needed_objects(ts: TruthScene, notes: Sequence[FrameNote], view_distance: float) -> list[int]:
    """Objects any noted frame may show: within the view distance of its eye, or drawn."""
    ids, lo, hi = ts.boxes()
    need = np.zeros(len(ids), bool)
    for st in notes:
        gap = np.maximum(np.maximum(lo - st.eye, st.eye - hi), 0.0)
        need |= np.einsum("nk,nk->n", gap, gap) <= view_distance**2
    drawn = {i for st in notes for i, _, _ in st.drawn}
    return sorted(set(ids[need].tolist()) | (drawn & set(ts.params)))


def missing_figures(
    ts: TruthScene,
    truth: TruthRenderer,
    notes: Sequence[FrameNote],
    pvs_of: Sequence[NDArray[np.int64] | None],
    proj: NDArray[np.float32],
    t_first_perfect: float | None,
    progress: Callable[[int, int], None] | None = None,
    overlay: Overlay | None = None,
    pop: PopMeter | None = None,
    viewer_ppd: float | None = None,
    truth_samples: Sampling = POINT,
    picture_samples: Sampling = POINT,
) -> tuple[TruthLog, WorstFrame | None, list[ComparedFrame], ColourWorst | None]:
    """Compare every noted frame with its truth (see the module docstring).

    ``truth`` holds the objects :func:`needed_objects` names and the coarser forms
    the frames drew; ``pvs_of`` is each frame's PVS (the service's where the client
    knew none); ``proj`` the client's projection; ``overlay`` the ``impostor`` hook of
    :mod:`walkstream.client.truth.picture`; ``pop`` is fed each frame as the client
    drew it (:mod:`walkstream.client.truth.pop`); ``viewer_ppd`` the display's pixels
    per degree for the viewer-scale (S-CIELAB) colour figures (None: not measured);
    ``truth_samples`` and ``picture_samples`` how the colour error's full scene and
    client picture sample a pixel (:mod:`walkstream.client.truth.antialias`; the id
    comparison stays point-sampled either way).  Returns one row per frame (with its
    colour figures), the worst frame by missing pixels (from the first perfect frame
    on first) as images, every frame in detail, and the worst frame by colour error.
    """
    from walkstream.client.draw.frames import FrameRenderer

    fov = float(np.degrees(2.0 * np.arctan(1.0 / float(proj[1, 1]))))
    client = FrameRenderer(truth.size, fov_deg=fov, ctx=truth.ctx)
    client.ground_z = truth.ground_z  # the same plane under both frames
    rows: list[tuple[int, float, float, NDArray[np.float64]]] = []
    compared: list[ComparedFrame] = []
    worst: WorstFrame | None = None
    worst_key = (-1, -1.0)
    colour_rows: list[tuple[float, float, float, float, NDArray[np.float64], NDArray[np.float64], float, float,
                            NDArray[np.float64]]] = []
    ppd = None if viewer_ppd is None else float(viewer_ppd)
    cworst: ColourWorst | None = None
    cworst_key = (-1, -1.0)
    n = len(notes)
    prev: FrameNote | None = None  # the note compared before (the pop's held frame draws its impostors)
    try:
        for k, (st, pvs) in enumerate(zip(notes, pvs_of, strict=True)):
            keys = [(i, lod) for i, lod, _ in st.drawn]
            wanted = set(keys)
            for key in client.keys():
                if key not in wanted:
                    client.forget(key)
            for i, lod, mesh in st.drawn:
                client.upload((i, lod), mesh)
            client.impostors = [*st.facades, *(q for _, q in st.impostors), *st.wall_quads]
            client.draw(keys, st.view, proj)
            c_rgb = client.snapshot()
            c_ids = client.draw_ids(keys, st.view, proj)
            t_rgb, t_ids = truth.colour_frame(st.eye, st.view, proj, also=[i for i, _, _ in st.drawn],
                                              samples=truth_samples)
            t_point = t_rgb if truth_samples.point else truth.colour(smooth=False)  # the id comparison's
            if st.impostors or st.wall_quads:  # a building drawn as its image shows where the image painted
                client.impostors = list(st.facades)
                client.draw(keys, st.view, proj)
                painted = np.any(client.snapshot() != c_rgb, axis=2)
                c_ids = stand_in_ids(c_ids, t_ids, painted, [i for i, _ in st.impostors])
                if st.wall_quads:  # a ring wall's texture stands in for whatever lies behind it
                    c_ids = np.where(painted, t_ids, c_ids).astype(c_ids.dtype)
            if pop is not None:
                pf = pop_frame(st.frame, c_rgb, c_ids, keys, st.impostors)
                held = c_rgb  # nothing held: no switch of its own to measure
                objs = [] if pop.last is None or prev is None else held_objects(pop.last, pf)
                if objs and prev is not None:  # the frame again, the switching objects as the frame before drew them
                    client.impostors = [*st.facades, *(q for _, q in held_impostors(prev.impostors, st.impostors, objs)),
                                        *st.wall_quads]
                    client.draw(keys, st.view, proj)
                    held = client.snapshot()
                pop.add(pf, held)
            prev = st
            knows = st.pvs is not None
            fogged: list[int] = []
            if np.isfinite(st.fog):
                fogged = _beyond(ts, st.eye, st.fog)
            err = compare_frame(
                t_ids,
                t_point,
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
                    horizon_shares(c_rgb, c_ids, below_horizon(st.view, proj, truth.size)),
                )
            )
            share = err.missing_share
            rows.append((st.frame, st.t, err.differing / err.pixels, share))
            after = t_first_perfect is not None and st.t >= t_first_perfect
            key = (int(after), err.missed / err.pixels)
            if key > worst_key:
                worst_key = key
                worst = WorstFrame(
                    st.frame, st.t, share, err.differing / err.pixels, c_rgb, t_point,
                    missing_mask(t_point, err.cause),
                )
            cerr, pic = colour_error(truth, st, t_rgb, err.cause, proj, overlay, ppd, picture_samples)
            colour_rows.append((cerr.mean_error, cerr.delta_e_mean, cerr.visible_share, cerr.psnr_db, cerr.cause_shares,
                                cerr.error_shares, cerr.scielab_delta_e_mean, cerr.scielab_visible_share,
                                cerr.scielab_cause_shares))
            ckey = (int(after), cerr.mean_error)
            if ckey > cworst_key:
                cworst_key = ckey
                cworst = ColourWorst(
                    st.frame, st.t, cerr.mean_error, cerr.visible_share, cerr.psnr_db, pic.rgb, t_rgb, cerr.delta_e,
                    None if ppd is None else cerr.scielab_visible_share, cerr.scielab_delta_e, ppd,
                )
            if progress is not None:
                progress(k + 1, n)
    finally:
        client.release()
    frames = np.array([r[0] for r in rows], np.int64)
    times = np.array([r[1] for r in rows])
    def col(j: int) -> NDArray[np.float64]:
        return np.array([r[j] for r in colour_rows], np.float64)

    colour = ColourLog(
        frames, times, col(0), col(1), col(2), col(3),
        np.array([r[4] for r in colour_rows]).reshape(-1, len(COLOUR_CAUSES)),
        np.array([r[5] for r in colour_rows]).reshape(-1, len(COLOUR_CAUSES)),
        # not asked for (ppd None): the columns stay out, as in a log read from an older truth.csv
        delta_e_scielab_mean=None if ppd is None else col(6),
        visible_scielab=None if ppd is None else col(7),
        causes_scielab=None if ppd is None else np.array([r[8] for r in colour_rows]).reshape(-1, len(COLOUR_CAUSES)),
        viewer_ppd=ppd,
    )
    log = TruthLog(
        frames,
        times,
        np.array([r[2] for r in rows]),
        np.array([r[3] for r in rows]).reshape(-1, len(CAUSES)),
        colour,
    )
    return log, worst, compared, cworst


def _counts(ids: NDArray[np.int64]) -> dict[int, int]:
    u, n = np.unique(ids, return_counts=True)
    return dict(zip(u.tolist(), n.tolist(), strict=True))


def _beyond(ts: TruthScene, eye: NDArray[np.float64], distance: float) -> list[int]:
    ids, lo, hi = ts.boxes()
    gap = np.maximum(np.maximum(lo - eye, eye - hi), 0.0)
    out: list[int] = ids[np.einsum("nk,nk->n", gap, gap) > distance**2].tolist()
    return out
