"""``walkstream bench impostors``: the same walk with and without impostors on a scene baked with ``--impostors``.

Each walk (``--path``, default SE, at 56 kbit/s / 200 ms unless told) is replayed twice on
one database and one device: drawing the far buildings the cell records list as their
images, and geometry only (``ReplayConfig.impostors`` off: the same cell records, no
image asked for).  One table: frames within 10 % of the target rate, triangles per
frame, impostors per frame, bytes down (all, and the images' share), texture bytes
per frame, perfect frames, and with ``--truth-every`` the colour error against the full
scene (median and p95 of the mean linear-RGB error, the pixels over ΔE00 2.3, PSNR,
the share of pixels visibly wrong under ``impostor``).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from walkstream.shared.errors import WalkstreamError

__all__ = ["format_impostor_table", "run_impostor_bench"]

Replayer = Callable[[str, dict[str, Any], str], Any]


def run_impostor_bench(
    db: str,
    replay: Replayer,
    *,
    out: Path,
    paths: Sequence[str] = ("SE",),
    device: str = "pda",
    truth_every: int = 0,
    duration: str | None = None,
    link: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """Replay each of ``paths`` on ``db`` with and without impostors; one row (summary,
    ``scenario``, ``impostors``) per replay that ran; ``bench_impostors.json`` into ``out``."""
    rows = []
    runs = [(p, imp) for p in paths for imp in (True, False)]
    for k, (path, imp) in enumerate(runs, 1):
        name = f"{path} {'impostors' if imp else 'geometry'}"
        options: dict[str, Any] = {"device": device, "path": path, **(link or {}), "impostors": imp,
                                   "report": str(out / f"{k:02d}-{name.replace(' ', '-').lower()}")}
        if duration:
            options["duration"] = duration
        if truth_every:
            options["truth_every"] = truth_every
        print(f"[{k}/{len(runs)}] {name} ...", file=sys.stderr, flush=True)
        try:
            s = replay(db, options, name).summary
        except WalkstreamError as exc:
            print(f"  {name}: {exc}", file=sys.stderr)
            continue
        rows.append({"scenario": name, "with_impostors": imp, **s})
    if rows:
        out.mkdir(parents=True, exist_ok=True)
        (out / "bench_impostors.json").write_text(json.dumps(rows, indent=2, default=str))
    return rows


def _pct(v: Any, digits: int = 2) -> str:
    return "n/a" if v is None else f"{100 * v:.{digits}f}"


def format_impostor_table(rows: list[dict[str, Any]]) -> str:
    """One line per replay (see the module docstring)."""
    head = (
        f"{'walk':<18} {'device':<6} {'fps10%':>6} {'tri/fr':>6} {'imp/fr':>6} {'bytes down':>10} {'images B':>9} "
        f"{'tex kB max':>10} {'perfect%':>8} {'err% med':>8} {'err% p95':>8} {'vis% med':>8} {'PSNR med':>8} {'imp%':>6}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        imp = r.get("impostors") or {}
        c = (r.get("truth") or {}).get("colour") or {}
        err, vis, ps = c.get("mean_error") or {}, c.get("visible_pixels") or {}, (c.get("psnr_db") or {}).get("median")
        lines.append(
            f"{r['scenario']:<18} {r.get('device', '?'):<6} {_pct(r.get('fps_within_10pct_ratio'), 1):>6} "
            f"{r.get('triangles_mean') or 0:>6.0f} {imp.get('impostors_mean', 0.0):>6.1f} "
            f"{r.get('bytes_received') or 0:>10,} {imp.get('image_bytes', 0):>9,} "
            f"{imp.get('texture_bytes_max', 0) / 1e3:>10.1f} {_pct(r.get('perfect_frame_ratio')):>8} "
            f"{_pct(err.get('median')):>8} {_pct(err.get('p95')):>8} {_pct(vis.get('median')):>8} "
            f"{'n/a' if ps is None else f'{ps:.1f}':>8} {_pct((c.get('causes') or {}).get('impostor')):>6}"
        )
    return "\n".join(lines)
