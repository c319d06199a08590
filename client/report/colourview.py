"""The worst frame by colour error as pictures: the client's picture, the full scene and a ΔE00 heat map.

:func:`write_colour_worst` writes ``truth/worst_colour.png`` (the three side by side
with the heat map's scale, and the viewer-scale (S-CIELAB) heat map fourth where it
was measured) and each alone (``worst_colour_client.png``,
``worst_colour_truth.png``, ``worst_colour_de.png``, ``worst_colour_de_scielab.png``) into a report folder and returns
the page's section.  The frame is :class:`~walkstream.client.truth.missing.ColourWorst`.
"""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from walkstream.client.report.files import atomic_open
from walkstream.client.report.plots import grid_figure, save_figure
from walkstream.client.truth.colour import PSNR_CAP_DB, VISIBLE_DE, heat_map
from walkstream.client.truth.missing import ColourWorst

__all__ = ["HEAT_TOP_DE", "write_colour_worst"]

#: ΔE00 at the top of the heat map's scale (white): a window drawn as wall is about 40.
HEAT_TOP_DE = 20.0

_NAMES = {
    "client": "worst_colour_client.png",
    "truth": "worst_colour_truth.png",
    "heat": "worst_colour_de.png",
    "scielab": "worst_colour_de_scielab.png",
}


def _save(path: Path, rgb: np.ndarray) -> None:
    from PIL import Image

    with atomic_open(path, "wb") as f:
        Image.fromarray(rgb, "RGB").save(f, format="PNG")


_CAPTIONS = {
    "client": "the client's picture: its objects at the LOD it drew them",
    "truth": "the full scene: every object within the view distance at LOD2",
    "heat": f"dE00 per pixel: black none, white {HEAT_TOP_DE:g} or more",
    "scielab": "dE00 of the pictures filtered as the eye sees them (S-CIELAB), same scale",
}


def write_colour_worst(out: Path, w: ColourWorst, plots: bool = True) -> str:
    """Write the worst colour frame's pictures into ``out/truth`` and return its HTML section.

    ``plots`` False: each picture alone, without the side-by-side figure with its scale
    (matplotlib's, most of the time this takes)."""
    folder = out / "truth"
    folder.mkdir(exist_ok=True)
    heat = heat_map(w.delta_e, HEAT_TOP_DE)
    pics = [("client", w.client), ("truth", w.truth), ("heat", heat)]
    if w.delta_e_scielab is not None:
        pics.append(("scielab", heat_map(w.delta_e_scielab, HEAT_TOP_DE)))
    for key, rgb in pics:
        _save(folder / _NAMES[key], rgb)
    psnr = "identical" if not np.isfinite(w.psnr_db) else f"PSNR {min(w.psnr_db, PSNR_CAP_DB):.1f} dB"
    head = (
        f"frame {w.frame} at {w.t:.2f} s: mean error {100.0 * w.mean_error:.2f} % of full scale (linear RGB), "
        f"{100.0 * w.visible:.2f} % of its pixels over dE00 {VISIBLE_DE:g}"
        + ("" if w.visible_scielab is None else
           f" ({100.0 * w.visible_scielab:.2f} % S-CIELAB at {w.viewer_ppd or 0:.1f} px/deg)")
        + f", {psnr}"
    )
    figs = "".join(
        f"<figure><a href='truth/{_NAMES[k]}'><img src='truth/{_NAMES[k]}' alt='{k}'></a>"
        f"<figcaption>{html.escape(_CAPTIONS[k])}</figcaption></figure>"
        for k, _ in pics
    )
    section = f"<h3>Worst compared frame by colour error: {html.escape(head)}</h3><div class='snaps'>{figs}</div>"
    if not plots:
        return section
    fig, axes = grid_figure(1, 3.4, cols=len(pics), sharex=False)
    for ax, img, cap in zip(
        axes, (w.client, w.truth), ("the client's picture (its LODs)", "the full scene (every object at LOD2)"), strict=False
    ):
        ax.imshow(img)
        ax.set_title(cap, fontsize=9)
    im = axes[2].imshow(w.delta_e, cmap="magma", vmin=0.0, vmax=HEAT_TOP_DE)
    axes[2].set_title(f"dE00 per pixel (visible above {VISIBLE_DE:g})", fontsize=9)
    bar = fig.colorbar(im, ax=axes[2], fraction=0.046, pad=0.03)
    bar.ax.axhline(VISIBLE_DE, color="#00c0ff", linewidth=1.5)
    if w.delta_e_scielab is not None:
        axes[3].imshow(w.delta_e_scielab, cmap="magma", vmin=0.0, vmax=HEAT_TOP_DE)
        axes[3].set_title(f"S-CIELAB dE00 at {w.viewer_ppd or 0:.1f} px/deg", fontsize=9)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
        ax.grid(False)
    fig.suptitle("Worst compared frame by colour error: " + head, fontsize=9)
    save_figure(fig, folder / "worst_colour.png")
    return section + "<p>Side by side with the scale: <a href='truth/worst_colour.png'>worst_colour.png</a></p>"
