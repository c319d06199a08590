"""What a replay is asked to do: the link, the path, the device, the clock and every knob of the walk.

One record that the frame loop (:mod:`walkstream.client.walk.loop`) and the replay's
wiring (:mod:`walkstream.client.replay`) read, typed instead of ``Any``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from walkstream.client.draw.impostors import MAX_IMAGE_DEG
from walkstream.client.net.link import LinkProfile
from walkstream.client.rewrite.pool import SHM_BYTES, RewriteOptions
from walkstream.client.truth.antialias import POINT, Sampling
from walkstream.shared.errors import InputError

__all__ = ["STREAM_FORMS", "ReplayConfig"]

STREAM_FORMS = {"params": "params", "meshes": "lod2"}
"""--stream choice -> the server's objects ``form``."""


@dataclass(frozen=True)
class ReplayConfig:
    """Everything a replay needs besides the server."""

    link: LinkProfile
    path: str = "SE"
    scene: str | None = None
    fps: float = 25.0
    target_fps: float | None = None
    """Minimum frame rate the budget holds (default: ``fps``)."""
    prefetch: bool = True
    stream: str = "params"
    cache_bytes: int = 64 << 20
    cache_dir: Path | None = None
    clock: str = "sim"
    device: str = "gl"
    size: tuple[int, int] = (640, 480)
    fov_deg: float = 60.0
    snapshot_every: int = 0
    duration_s: float | None = None
    workers: int = 2
    rewrite: str = "auto"
    """Real clock: rebuild in worker ``process``es or ``thread``s; ``auto``: see
    :func:`~walkstream.client.rewrite.pool.auto_mode`."""
    shm_bytes: int = SHM_BYTES
    """Bound on the shared memory the rewrite processes hand geometry back through."""
    lod_select: str = "ach"
    lod_greedy: bool = True
    """ACH selection: in descending ACH each object takes the best LOD that still fits
    (:func:`~walkstream.client.draw.allocate.allocate_ach` ``greedy``); False: the paper's shares."""
    lod_hold_s: float | None = None
    """The LOD hold's seconds (:mod:`~walkstream.client.walk.lodhold`; ``--lod-hold``): the
    allocation gets the least of the objects' budget over them and an object whose LOD
    changed within them may only go down; 0: no hold; None: 1 s on a simulated device
    (where the facade bake swings the objects' budget frame to frame), 0 on ``gl``."""
    lod_distances: tuple[float, float] = (40.0, 120.0)
    budget_frames: int = 4
    seed: int = 0
    cost_step_at_s: float | None = None
    """Walk time at which the device's per-triangle cost is multiplied (benchmarks)."""
    cost_step_factor: float = 10.0
    report_dir: Path | None = None
    setup_timeout_s: float = 60.0
    """Give up (an empty report saying why) when the path has not arrived by then."""
    kind: str | None = None
    """``city`` or ``interior`` when the caller knows the scene's kind (the CLI does);
    ``None``: wait for the manifest to tell (a city walk then starts a little later)."""
    fog_m: float = 40.0
    """Interiors: portals farther than this are not looked through."""
    culling: str = "portals"
    """Interiors: ``portals``, ``frustum`` or ``none`` (:mod:`walkstream.shared.portals`)."""
    triangle_cull: bool = True
    """Interiors, ``portals`` culling: the parts kept by their boxes are tested again by
    their triangles (:mod:`walkstream.shared.trianglecull`)."""
    fog_budget: bool = True
    """Interiors: the budget controller sets the fog distance (one LOD per part)."""
    rooms: dict[str, Any] = field(default_factory=dict)
    """Interiors: further :class:`~walkstream.client.stream.rooms.RoomStreamConfig` knobs."""
    start_bundle: bool = True
    """Start with the start bundle (one round trip); False: scene list, manifest, path."""
    start_contents: bool = True
    """Interiors: the start bundle brings the first view's contents too."""
    path_head_s: float | None = 10.0
    """Interiors, with :attr:`start_contents`: the start bundle brings only the path's
    first this many seconds; the whole path is fetched when the link is idle (the
    walker waits at the head's end if it is late); None: the whole path in the bundle."""
    start_heads: bool = True
    """Interiors, with :attr:`start_contents` and :attr:`path_head_s`: a cell the first
    pose sees in part comes first as its head (the pieces drawn, stand-ins for the
    others), whole after the other cells (:mod:`~walkstream.shared.codec.cellhead`).
    Cities, with :attr:`start_hold_s`: the start bundle brings the objects the first
    pose draws first, then the boxes of the first cell's others
    (:mod:`~walkstream.shared.codec.objectboxes`), and the walker holds (:attr:`street_hold`)."""
    start_pose: bool = True
    """Interiors, with :attr:`start_heads` and a walker that stands at its start
    (:attr:`start_hold_s`): the start bundle brings the path's first pose alone before
    the topology and the path's head once the first pose's view is in (the walker
    stands at that pose until then; :attr:`posed_start`): the first view about 170
    bytes sooner."""
    start_walls: bool = True
    """An interior baked with ``--virtual-walls`` (and :attr:`virtual_walls` on, with
    :attr:`start_contents`): the start bundle brings the wall sides and the first view's
    wall textures before its contents (:mod:`~walkstream.server.service.firstwalls`):
    the first frames show those walls closed and need only the cells before them."""
    start_hold_s: float = 3.0
    """Interiors: the walker stands at the path's start until the first frame there is
    perfect (every cell it shows in memory) and no contents are on the link (the start
    bundle's other cells, where the path leads in its first seconds, and the first
    prefetch), at most this many seconds, then walks on; 0: walks at once, whatever the
    first view holds (before, the walker was carried into cells still on the link: seed
    3's first 30 s 90.31 % perfect frames).  Cities (with :attr:`start_heads`, when the
    caller knows the scene is a city, as the CLI does): the same until the first frame
    is perfect and the start bundle is in."""
    gzip: bool = True
    """Ask for the streams gzip-compressed (``Accept-Encoding: gzip``)."""
    truth_every: int = 0
    """Compare every N-th frame with the ground truth after the walk (0: never)."""
    viewer_ppd: float | None = None
    """The display's pixels per degree for the truth's viewer-scale (S-CIELAB) colour
    figures (``--viewer-ppd``; None: not measured, as their filtering costs 0.1-1 s a
    compared frame; the view's own is its height over its field of view, 1.81 at 160x120)."""
    truth_samples: Sampling = POINT
    """How the truth's colour error samples a pixel of the full scene (``--truth-samples``:
    N x N supersampled or multisampled, :mod:`walkstream.client.truth.antialias`; by
    default one sample at its centre); the id comparison stays point-sampled."""
    picture_samples: Sampling = POINT
    """How the colour error samples a pixel of the client's picture (``--picture-samples``:
    a client drawing with a GPU's anti-aliasing); by default one, as the client draws."""
    frame_times: tuple[float, ...] | None = None
    """A recorded frame schedule (``--frame-times``): frame ``k`` takes ``frame_times[k]``
    seconds on the clock instead of the time measured (the ``gl`` device measures
    llvmpipe, whose times differ from run to run), so that a walk -- and the frames its
    ground truth compares -- repeats exactly; frames past its end are measured."""
    batched_draws: bool = True
    """One multi-draw call per frame (False: one draw call per object, as before)."""
    impostors: bool = True
    """Draw the far buildings a scene baked with ``--impostors`` lists as their images
    (False: geometry only, as a scene without impostors; :mod:`walkstream.client.walk.impostors`)."""
    virtual_walls: bool = True
    """Draw the virtual walls of an interior baked with ``--virtual-walls`` as their textures
    (False: every portal open, as a scene without walls; :mod:`walkstream.client.walk.walls`)."""
    texture_budget_bytes: int = 8 << 20
    """Bytes of impostor textures a frame may draw (the farthest dropped first)."""
    impostor_blend_m: float | None = None
    """Metres beyond the bake's ``D`` over which an impostor fades in over its geometry
    (``--impostor-blend``; None: a share of ``D``,
    :func:`~walkstream.client.draw.impostors.blend_length`; 0: no blend by distance)."""
    impostor_perspective: bool = False
    """Count the orthographic image's own parallax in the error an impostor is held to
    (``--impostor-perspective``; :func:`~walkstream.shared.impostors.orthographic_parallax`):
    where it and the direction's error together pass the bake's ``A`` the building fades
    to geometry.  Off: the bound counts the direction's error alone, as the bake does."""
    impostor_max_size_deg: float = MAX_IMAGE_DEG
    """The largest angular radius, degrees, at which a building's image stands in for it
    (``--impostor-max-size``; :data:`~walkstream.client.draw.impostors.MAX_IMAGE_DEG`;
    ``inf``: no limit): a building larger on the screen is drawn as geometry."""
    impostor_fade_s: float | None = None
    """Seconds the opacity drawn takes at least to go from 0 to 1 (``--impostor-fade``;
    None: :data:`~walkstream.client.draw.impostors.FADE_S`; 0: none, with
    ``impostor_blend_m`` 0 a hard switch)."""

    facades: bool | None = None
    """Draw a building left at its LOD0 box with facade textures of its LOD2 (rendered by
    the client from the geometry it rebuilt; :mod:`walkstream.client.walk.facades`):
    True always, False never (``--no-facades``: plain boxes), None (``--facades auto``)
    on a simulated device only (where the cost model's budget leaves the boxes; on
    ``gl`` the rendering's real time cost frames and LOD2 is drawn nearly everywhere)."""
    facade_lookalike: bool = True
    """Draw a building the allocation put at LOD2 as its box with facade textures where
    the two look alike from the eye (``--no-facade-lookalike``: only boxes get them;
    :mod:`walkstream.client.draw.lookalike`)."""
    facade_grazing_deg: float = 70.0
    """The look-alike boxes: the largest angle between a face's normal and the ray from
    its centre to the eye at which its picture stands for LOD2 (``--facade-grazing``;
    90: no limit, a third fewer triangles on ``gl`` at a higher pixel-level error;
    :data:`~walkstream.client.draw.lookalike.GRAZING_COS`)."""
    facade_parallax_px: float = 1.0
    """Largest parallax of a facade's relief, in pixels, at which a box with its pictures
    stands for LOD2 (``--facade-parallax``; :data:`~walkstream.client.draw.lookalike.PARALLAX_PX`)."""
    facade_filter: str = "point"
    """How a facade picture is read when drawn smaller than baked (``--facade-filter``; one
    of :data:`~walkstream.client.draw.quads.FACADE_FILTERS`): ``point`` (the closest to the
    point-sampled truth) or ``anisotropic`` (the closest to an anti-aliased one)."""
    facade_texels_per_m: float = 8.0
    """Texels per metre of a facade texture (``--facade-texels``)."""
    facade_budget_bytes: int = 8 << 20
    """Bytes of facade textures held and drawn (``--facade-budget``; the least recently drawn dropped first)."""
    facade_bake_share: float = 0.3
    """Share of the frame's triangle budget that baking facade textures may take on
    average (``--facade-bake-share``): a face's bake draws its LOD2 triangles, charged to its frame."""

    wall_zone_blend: float = 0.5
    """Width of the blend between two zones' textures of a virtual wall around their
    border, in zone widths (``--wall-zone-blend``; 0: a hard swap at the border;
    :func:`~walkstream.shared.walls.zone_mix`)."""
    wall_parallax: float = 0.5
    """How far a virtual wall's texture slides along the wall with the viewer's offset from
    its zone's sampling line, as a share of that offset, and is scaled for the viewer's
    distance against the sampling point's (``--wall-parallax``; 0: fixed on the wall;
    :func:`~walkstream.shared.walls.zone_warp`)."""

    def __post_init__(self) -> None:
        if self.stream not in STREAM_FORMS:
            raise InputError(f"--stream {self.stream!r}: choose one of {', '.join(STREAM_FORMS)}")
        if self.clock not in ("sim", "real"):
            raise InputError(f"--clock {self.clock!r}: choose sim or real")
        if self.lod_hold_s is not None and not (math.isfinite(self.lod_hold_s) and self.lod_hold_s >= 0):
            raise InputError(f"--lod-hold {self.lod_hold_s!r}: expected seconds >= 0")
        if self.lod_select not in ("ach", "distance"):
            raise InputError(f"--lod {self.lod_select!r}: choose ach or distance")
        if not (math.isfinite(self.fps) and 0 < self.fps <= 1000):
            raise InputError(f"--fps {self.fps!r}: expected a number in (0, 1000]")
        tf = self.target_fps
        if tf is not None and not (math.isfinite(tf) and 0 < tf <= 1000):
            raise InputError(f"--target-fps {tf!r}: expected a number in (0, 1000]")
        if not (math.isfinite(self.facade_parallax_px) and 0 < self.facade_parallax_px <= 8):
            raise InputError(f"--facade-parallax {self.facade_parallax_px!r}: expected pixels in (0, 8]")
        from walkstream.client.draw.quads import FACADE_FILTERS

        if self.facade_filter not in FACADE_FILTERS:
            raise InputError(f"--facade-filter {self.facade_filter!r}: expected one of {', '.join(FACADE_FILTERS)}")
        if not (math.isfinite(self.facade_texels_per_m) and 0 < self.facade_texels_per_m <= 64):
            raise InputError(f"--facade-texels {self.facade_texels_per_m!r}: expected texels per metre in (0, 64]")
        if not (math.isfinite(self.facade_grazing_deg) and 0 <= self.facade_grazing_deg <= 90):
            raise InputError(f"--facade-grazing {self.facade_grazing_deg!r}: expected degrees from 0 to 90")
        if self.facade_budget_bytes < 0:
            raise InputError(f"--facade-budget {self.facade_budget_bytes}: must not be negative")
        if not (math.isfinite(self.facade_bake_share) and 0 < self.facade_bake_share <= 1):
            raise InputError(f"--facade-bake-share {self.facade_bake_share!r}: expected a share in (0, 1]")
        if self.cache_bytes < 0:
            raise InputError(f"--cache {self.cache_bytes}: must not be negative")
        if self.duration_s is not None and not self.duration_s > 0:
            raise InputError(f"--duration {self.duration_s!r}: must be > 0")
        if self.workers < 1:
            raise InputError(f"--workers {self.workers}: at least 1")
        RewriteOptions(self.rewrite, self.shm_bytes)  # says what is wrong
        if self.snapshot_every < 0:
            raise InputError(f"--snapshot-every {self.snapshot_every}: must not be negative")
        if self.frame_times is not None and not all(math.isfinite(v) and v > 0 for v in self.frame_times):
            raise InputError("--frame-times: every frame time must be a positive number of seconds")
        ib = self.impostor_blend_m
        if ib is not None and not (math.isfinite(ib) and ib >= 0):
            raise InputError(f"--impostor-blend {ib!r}: expected metres >= 0")
        zb = self.wall_zone_blend
        if not (math.isfinite(zb) and 0 <= zb <= 1):
            raise InputError(f"--wall-zone-blend {zb!r}: expected zone widths from 0 to 1")
        wp = self.wall_parallax
        if not (math.isfinite(wp) and 0 <= wp <= 1):
            raise InputError(f"--wall-parallax {wp!r}: expected a share from 0 to 1")
        ms = self.impostor_max_size_deg
        if not (ms > 0 and (math.isinf(ms) or ms <= 90)):
            raise InputError(f"--impostor-max-size {ms!r}: expected degrees in (0, 90], or inf")
        fs = self.impostor_fade_s
        if fs is not None and not (math.isfinite(fs) and fs >= 0):
            raise InputError(f"--impostor-fade {fs!r}: expected seconds >= 0")
        if self.truth_every < 0:
            raise InputError(f"--truth-every {self.truth_every}: must not be negative")
        vp = self.viewer_ppd
        if vp is not None and not (math.isfinite(vp) and 0.1 <= vp <= 1000.0):
            raise InputError(f"--viewer-ppd {vp!r}: expected pixels per degree from 0.1 to 1000")
        w, h = self.size
        if not (16 <= w <= 8192 and 16 <= h <= 8192):
            raise InputError(f"--size {w}x{h}: each side from 16 to 8192 pixels")

    @property
    def street_hold(self) -> bool:
        """Whether a city walker stands at its start until its first view is complete
        (:attr:`start_hold_s`): with the start bundle and its first view
        (:attr:`start_heads`), which then brings that view's objects first."""
        return self.start_bundle and self.start_heads and self.start_hold_s > 0

    @property
    def posed_start(self) -> bool:
        """Whether an interior's start bundle is asked for the path's first pose alone
        before the topology, its head after the first pose's view (:attr:`start_pose`):
        only where the walker stands at its start until that view is in."""
        return self.start_pose and self.start_heads and self.start_contents and self.start_hold_s > 0

    @property
    def fps_target(self) -> float:
        """The budget's target frame rate."""
        return self.target_fps if self.target_fps is not None else self.fps
