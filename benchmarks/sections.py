"""The section-size trade, measured: ``walkstream bench sections``.

One city is baked with street cells (the default), grid cells and into sections for
every redundancy ``R``, minimum size ``M`` and cover asked for; the dense visibility field is
rendered once (the first sections bake) and reused by the others (their field
folders point at it), so the sweep costs one field.  Every database holds the same
default walks (sections take the walks of the street partition; the street database's
walks are written into the grid cells' database, whose own differ), and each walk is
replayed in each at 56 kbit/s, 200 ms round trip, under the simulated clock.  A row
gives the cells, their mean PVS, the redundancy (objects a section holds that the
field point where the walker stands does not see, averaged over every section and
field point in it), the bake seconds, and per walk the cells entered per km, the
bytes per km and the perfect frames.  A replay is run by the ``replay`` callable the
command line hands in.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from walkstream.server.bake import BakeSettings, bake
from walkstream.server.store import SceneReader, write_path
from walkstream.shared.errors import WalkstreamError
from walkstream.shared.paths import RecordedPath

__all__ = ["run_sections_bench", "format_sections_table", "plot_sections_trade", "trade_labels"]

Replayer = Callable[[str, Mapping[str, Any], str], Any]


# the bake's figures the database does not hold (the sections' redundancy, the field's
# size): kept beside the database so that ``--reuse`` shows them again
_BAKE_FIGURES = ("section_redundancy_mean", "sections", "section_pvs_mean", "field_points", "field_bytes", "redundancy")


def _figures_path(db: Path) -> Path:
    return db.with_name(db.name + ".figures.json")


def _stored_figures(db: Path, previous: Mapping[str, Any] | None) -> dict[str, Any]:
    """The bake figures kept for ``db``: its ``.figures.json``, else the row of the last
    run's ``bench_sections.json`` (``previous``) for the same database."""
    try:
        return {k: v for k, v in json.loads(_figures_path(db).read_text()).items() if k in _BAKE_FIGURES}
    except (OSError, ValueError, AttributeError):
        pass
    return {k: previous[k] for k in _BAKE_FIGURES if previous is not None and previous.get(k) is not None}


def _bake(src: Path, db: Path, st: BakeSettings, reuse: bool, workers: int,
          previous: Mapping[str, Any] | None = None) -> dict[str, Any]:
    if reuse and db.exists():
        with SceneReader.open(db) as reader:
            s = reader.summary()
        return s | _stored_figures(db, previous) | {"bake_seconds": float(s.get("bake_seconds") or 0.0)}
    print(f"  baking {db.name} ...", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    summary = bake(src, db, settings=st, workers=workers)
    summary["bake_seconds"] = time.perf_counter() - t0
    _figures_path(db).write_text(json.dumps({k: summary[k] for k in _BAKE_FIGURES if k in summary}))
    return summary


def _previous_rows(out: Path) -> dict[str, dict[str, Any]]:
    """The last run's rows by database name (``{}`` where there is none or it is unreadable)."""
    try:
        rows = json.loads((out / "bench_sections.json").read_text())
    except (OSError, ValueError):
        return {}
    return {_db_name(r): r for r in rows if isinstance(r, dict) and "cells_kind" in r} if isinstance(rows, list) else {}


def _db_name(row: Mapping[str, Any]) -> str:
    """The database file a row was measured in (the names :func:`run_sections_bench` gives)."""
    if row.get("database"):
        return str(row["database"])
    if row["cells_kind"] != "sections":
        return f"{row['cells_kind']}.db"
    cover = row.get("cover") or "walkable"
    return f"sections-R{row['redundancy']}-M{float(row['min_size']):g}" + ("" if cover == "walkable" else f"-{cover}") + ".db"


def run_sections_bench(
    replay: Replayer,
    *,
    source: Path,
    out: Path,
    redundancies: Sequence[int | None] = (32, 64, 96),
    min_sizes: Sequence[float] = (64.0,),
    field_spacing: float = 4.0,
    walks: Sequence[str] = ("SE", "drive"),
    covers: Sequence[str] = ("walkable",),
    reuse: bool = False,
    workers: int = 1,
    bbox: tuple[float, float, float, float] | None = None,
    bbox_crs: str = "local",
) -> list[dict[str, Any]]:
    """Bake ``source`` with street cells, grid cells and in sections for every ``(R, M)`` and cover
    (``--section-cover``; an ``R`` of None: the bake's default, ``R`` from the field); replay ``walks``.  With ``bbox`` (``bbox_crs``: ``local`` or
    ``lonlat``) every bake takes only that part of the source (``bake --bbox``).

    Returns one row per database; writes ``bench_sections.json`` and the replay
    reports into ``out``.
    """
    if not source.exists():
        raise WalkstreamError(f"{source}: no such source")
    out.mkdir(parents=True, exist_ok=True)
    clip: dict[str, Any] = {"bbox": bbox, "bbox_crs": bbox_crs} if bbox is not None else {}
    runs: list[tuple[str, Path, BakeSettings, int | None, float | None]] = [
        ("street", out / "street.db", BakeSettings(**clip), None, None),
        ("grid", out / "grid.db", BakeSettings(cells="grid", **clip), None, None),
    ]
    for cover in covers:
        for rr in redundancies:
            for mm in min_sizes:
                st = BakeSettings(cells="sections", field_spacing=field_spacing,
                                  redundancy=None if rr is None else int(rr),
                                  min_size=float(mm), section_cover=cover, **clip).check()
                name = f"sections-R{'auto' if rr is None else rr}-M{mm:g}" + ("" if cover == "walkable" else f"-{cover}")
                runs.append(("sections", out / f"{name}.db", st, None if rr is None else int(rr), float(mm)))
    # one field per cover (the walkable cover renders fewer points): the other bakes
    # of that cover point at the first one's folder
    first_field: dict[str, Path] = {}
    street_blobs: dict[str, bytes] = {}
    rows: list[dict[str, Any]] = []
    previous = _previous_rows(out) if reuse else {}
    for kind, db, st, r, m in runs:
        if kind == "sections":
            folder = Path(os.fspath(db) + ".field")
            first = first_field.setdefault(st.section_cover, folder)
            if first != folder and not folder.exists() and first.exists():
                folder.symlink_to(first.resolve(), target_is_directory=True)
        s = _bake(source, db, st, reuse, workers, previous.get(db.name))
        with SceneReader.open(db) as reader:
            blobs = {w: reader.path_blob(w) for w in walks if w in reader.path_names()}
        if kind == "street":
            street_blobs = blobs
        else:
            # the same walks in every database: grid cells get walks of their own
            for w, blob in street_blobs.items():
                if blobs.get(w) != blob:
                    write_path(db, w, blob)
                    blobs[w] = blob
        paths = {w: RecordedPath.from_msgpack(blob, w) for w, blob in blobs.items()}
        row: dict[str, Any] = {
            "database": db.name, "cells_kind": kind,
            # the R the sections were grown with (the field's choice where none was asked for)
            "redundancy": r if r is not None or kind != "sections" else s.get("redundancy"),
            "redundancy_from_field": kind == "sections" and r is None, "min_size": m, "cells": s["cells"], "pvs_mean": s["pvs_mean"],
            "cover": st.section_cover if kind == "sections" else None,
            "section_redundancy_mean": s.get("section_redundancy_mean"), "bake_seconds": s["bake_seconds"],
            "field_points": s.get("field_points"), "field_bytes": s.get("field_bytes"), "walks": {},
        }
        for w, path in paths.items():
            km = path.length_m() / 1000.0
            options = {"path": w, "bandwidth": "56kbit", "rtt": "200ms", "clock": "sim", "device": "desktop2003",
                       "report": str(out / f"{db.stem}-{w}")}
            print(f"  replaying {w} in {db.name} ...", file=sys.stderr, flush=True)
            res = replay(str(db), options, f"{db.stem} {w}")
            rs = res.summary
            row["walks"][w] = {
                "km": km, "perfect_frame_ratio": rs["perfect_frame_ratio"],
                "first_perfect_s": rs.get("time_to_first_perfect_frame_s"),
                "bytes_per_km": rs["bytes_received"] / km if km > 0 else None,
                "cells_per_km": rs["cells_entered"] / km if km > 0 else None,
                # where the bytes go: objects, cell records (PVS and ACH), index tiles
                **{f"{part}_bytes_per_km": (rs.get(f"{part}_bytes") or 0) / km if km > 0 else None
                   for part in ("object", "cell", "index")},
                "overfetch_ratio": rs.get("overfetch_ratio"),
            }
        rows.append(row)
    (out / "bench_sections.json").write_text(json.dumps(rows, indent=2, default=str))
    return rows


def format_sections_table(rows: list[dict[str, Any]]) -> str:
    """One line per database and walk."""
    head = (f"{'cells':<9} {'cover':<8} {'R':>4} {'M m2':>5} {'n cells':>7} {'PVS mean':>8} {'redund.':>7} "
            f"{'bake s':>7} {'walk':>6} {'cells/km':>8} {'bytes/km':>9} {'objects':>8} {'records':>8} {'index':>7} "
            f"{'overf.':>6} {'perfect%':>8} {'first s':>7}")
    lines = [head, "-" * len(head)]

    def n(v: float | None) -> str:
        return "-" if v is None else f"{v:,.0f}"

    for r in rows:
        red = "-" if r["section_redundancy_mean"] is None else f"{r['section_redundancy_mean']:.1f}"
        big = "-" if r["min_size"] is None else f"{r['min_size']:g}"
        rr = "-" if r["redundancy"] is None else f"{r['redundancy']}" + ("*" if r.get("redundancy_from_field") else "")
        for w, f in r["walks"].items():
            first = f["first_perfect_s"]
            over = f.get("overfetch_ratio")
            lines.append(
                f"{r['cells_kind']:<9} {r.get('cover') or '-':<8} {rr:>4} "
                f"{big:>5} {r['cells']:>7,} {r['pvs_mean']:>8.1f} "
                f"{red:>7} {r['bake_seconds']:>7.0f} {w:>6} {f['cells_per_km']:>8.1f} {f['bytes_per_km']:>9,.0f} "
                f"{n(f.get('object_bytes_per_km')):>8} {n(f.get('cell_bytes_per_km')):>8} "
                f"{n(f.get('index_bytes_per_km')):>7} {'-' if over is None else f'{over:.2f}':>6} "
                f"{100 * f['perfect_frame_ratio']:>8.2f} {'never' if first is None else f'{first:.2f}':>7}"
            )
    return "\n".join(lines)


def trade_labels(rows: Sequence[Mapping[str, Any]], walk: str) -> list[tuple[float, float, str]]:
    """The trade plot's labels for ``walk``: ``(mean PVS, kB per km, label)`` per spot.

    Sections rows whose points lie on one spot of the plot -- within 4 % of the points'
    kB range of each other and closer than 35 % of their PVS range (a label's width),
    e.g. ``R128`` and ``R256`` once the sections hold most of the scene -- share one label
    at the spot's first point: ``"R128, R256 M64 (redundancy 178, 214)"`` (one redundancy
    where they agree, ``"; "`` between whole labels where ``M`` or the cover differ).
    """
    pts = [(float(r["pvs_mean"]), r["walks"][walk]["bytes_per_km"] / 1000, r) for r in rows if walk in r["walks"]]
    if not pts:
        return []
    xs, ys = [p[0] for p in pts], [p[1] for p in pts]
    xr, yr = (max(xs) - min(xs)) or 1.0, (max(ys) - min(ys)) or 1.0
    groups: list[tuple[float, float, list[Mapping[str, Any]]]] = []
    for x, b, r in pts:
        for gx, gb, members in groups:
            if abs(b - gb) <= 0.04 * yr and abs(x - gx) <= 0.35 * xr:
                members.append(r)
                break
        else:
            groups.append((x, b, [r]))

    def tail(r: Mapping[str, Any]) -> str:
        return f" M{r['min_size']:g}" + ("" if r.get("cover") in (None, "walkable") else f" {r['cover']}")

    def red(r: Mapping[str, Any]) -> str | None:
        v = r.get("section_redundancy_mean")
        return None if v is None else f"{v:.0f}"

    out = []
    for x, b, members in groups:
        if len({tail(r) for r in members}) == 1:
            reds = list(dict.fromkeys(v for r in members if (v := red(r)) is not None))
            label = (", ".join(f"R{r['redundancy']}" for r in members) + tail(members[0])
                     + (f" (redundancy {', '.join(reds)})" if reds else ""))
        else:
            label = "; ".join(f"R{r['redundancy']}{tail(r)}" + ("" if red(r) is None else f" (redundancy {red(r)})")
                              for r in members)
        out.append((x, b, label))
    return out


def plot_sections_trade(rows: list[dict[str, Any]], path: str | os.PathLike[str]) -> None:
    """The paper's trade as a plot: per walk, bytes per km and cells entered per km against
    the sections' mean PVS (one point per ``(R, M)``, labelled with its redundancy where
    the bake measured it), street cells as dotted lines, grid cells as dash-dotted ones."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    secs = [r for r in rows if r["cells_kind"] == "sections"]
    others = [(r, {"street": ":", "grid": "-."}[r["cells_kind"]]) for r in rows if r["cells_kind"] in ("street", "grid")]
    walks = sorted({w for r in rows for w in r["walks"]})
    fig = Figure(figsize=(5.0 * max(1, len(walks)), 4.2), dpi=120)
    for k, w in enumerate(walks):
        ax = fig.add_subplot(1, max(1, len(walks)), k + 1)
        on = [r for r in secs if w in r["walks"]]
        if on:
            x = [r["pvs_mean"] for r in on]
            b = [r["walks"][w]["bytes_per_km"] / 1000 for r in on]
            c = [r["walks"][w]["cells_per_km"] for r in on]
            ax.plot(x, b, "o-", color="#1f77b4", label="sections: kB/km")
            mid = (min(x) + max(x)) / 2
            for xi, bi, li in trade_labels(on, w):
                # right of the middle a label ends at its point, so it stays inside the axes
                right = len(x) > 1 and xi > mid
                ax.annotate(li, (xi, bi), fontsize=7, xytext=(-3 if right else 3, 3), textcoords="offset points",
                            ha="right" if right else "left")
            ax2 = ax.twinx()
            ax2.plot(x, c, "s--", color="#d62728", label="sections: cells entered/km")
            ax2.set_ylabel("cells entered per km", color="#d62728")
            for other, ls in others:
                if w in other["walks"]:
                    ax.axhline(other["walks"][w]["bytes_per_km"] / 1000, color="#1f77b4", lw=0.8, ls=ls,
                               label=f"{other['cells_kind']} cells: kB/km")
                    ax2.axhline(other["walks"][w]["cells_per_km"], color="#d62728", lw=0.8, ls=ls)
        ax.set_xlabel("mean section PVS (objects; larger: more redundancy)")
        ax.set_ylabel("kB per km", color="#1f77b4")
        ax.set_title(f"{w}: the section-size trade (56 kbit/s)", fontsize=9)
        ax.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    fig.savefig(os.fspath(path))
