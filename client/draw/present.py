"""Showing a frame: its time on the device (a cost model, or the real draw) and its snapshot.

Every frame loop ends a frame the same way: a simulated device answers with the time
its cost model gives for the triangles and draws (drawing really only when a snapshot
is due), the ``gl`` device draws and answers with the real time; a due snapshot is
saved as ``frames/frame_NNNNNN.png`` in the report folder.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["present", "save_snapshot"]


def present(
    device: Any,
    renderer: Any,
    keys: Sequence[Hashable],
    view: NDArray[np.float32] | NDArray[np.float64],
    proj: NDArray[np.float32] | NDArray[np.float64],
    triangles: int,
    drawn: int,
    snap: bool,
) -> tuple[float, bool]:
    """Show one frame: ``(seconds it took on the device, whether the device stalled)``.

    ``keys`` are the renderer's meshes to draw, ``triangles`` and ``drawn`` what the
    cost model of a simulated device charges; ``snap`` draws on a simulated device too
    (for the snapshot).  A stall is the simulated device's occasional 2x spike.
    """
    if device.simulated:
        seconds = float(device.frame_time(triangles, drawn))
        if snap and renderer is not None:
            renderer.draw(keys, view, proj)
        return seconds, bool(getattr(device, "last_spike", False))
    return float(renderer.draw(keys, view, proj)), False


def save_snapshot(renderer: Any, report_dir: Path | None, frame: int) -> Path | None:
    """Save the frame just drawn as ``report_dir/frames/frame_NNNNNN.png`` (None: nothing to save)."""
    if renderer is None or report_dir is None:
        return None
    out = Path(report_dir) / "frames" / f"frame_{frame:06d}.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    renderer.save_png(out)
    return out
