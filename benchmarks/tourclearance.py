"""How near an interior's tour brings the eye to solid geometry, pose by pose
(``python -m walkstream.benchmarks.tourclearance SOURCE ... [--step S]``).

The truth refuses a compared frame whose eye comes within 0.15 m of a room surface
(:data:`~walkstream.client.truth.culled.SOLID_NEAR` near planes), but it sees only the
frames it compares (every 100th on a whole tour).  This measures the tour itself, with no
bake, replay or truth: the interior is planned as the bake plans it
(:func:`~walkstream.server.bake.interior.interior_parts`: cells, walking graph, tour), the
eye sampled every ``step`` seconds of the tour, and each sample's distance to the nearest
triangle of every element of the model (walls, slabs, stairs, railings, door leaves,
furniture) measured.  A walk that keeps its clearance (0.3 m, a person's half-width)
from what stands around it keeps the eye at least that far from every surface too,
except where a stair's treads or a ceiling are nearer than that above or below (none
on the generated stairs).

``SOURCE`` is a seed (a generated office of 3 storeys, ``walkstream generate interior
--storeys 3 --seed S``) or an interior file (IFC, ``walkstream-interior``).  Prints one
row per source: the tour's length, the samples, how many came within 0.15 m (what the
truth refuses) and within 0.25 m of a surface, the nearest, and the element kinds of the
poses within 0.15 m.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import trimesh

from walkstream.server.bake.interior import interior_parts
from walkstream.server.sources.interior import InteriorScene
from walkstream.server.sources.interiorfile import load_interior_dict
from walkstream.server.sources.interiorgen import InteriorPlan, generate_interior
from walkstream.server.sources.read import read_source
from walkstream.shared.arrays import F64
from walkstream.shared.errors import InputError, WalkstreamError

__all__ = ["REFUSED_M", "eye_clearance", "main"]

REFUSED_M = 0.15
"""An eye nearer than this to a surface is a pose the truth refuses (metres)."""
_REACH = 0.3
"""Only surfaces within this reach of an eye are measured (metres)."""


def _scene(source: str) -> tuple[InteriorScene, Path]:
    """The interior a source names: a seed's generated office, or a model file."""
    if source.isdigit():
        return load_interior_dict(generate_interior(InteriorPlan(storeys=3, seed=int(source)))), Path(f"seed{source}")
    scene = read_source(source)
    if not isinstance(scene, InteriorScene):
        raise InputError(f"{source} is not an interior (an IFC model or a walkstream-interior file)")
    return scene, Path(source)


def eye_clearance(scene: InteriorScene, eyes: F64) -> tuple[F64, list[str]]:
    """Each eye's ``(n, 3)`` distance to the nearest triangle of ``scene``'s elements
    (``inf`` beyond :data:`_REACH`) and that element's kind (``""`` beyond)."""
    soups = [e.soup for e in scene.elements if len(e.triangles)]
    kinds = np.concatenate([np.full(len(e.triangles), e.kind, object) for e in scene.elements if len(e.triangles)])
    tris = np.concatenate(soups)
    lo, hi = tris.min(axis=1), tris.max(axis=1)
    dist = np.full(len(eyes), np.inf)
    kind = [""] * len(eyes)
    for i, eye in enumerate(eyes):
        near = np.flatnonzero(np.all((lo <= eye + _REACH) & (hi >= eye - _REACH), axis=1))
        if not len(near):
            continue
        closest = trimesh.triangles.closest_point(tris[near], np.broadcast_to(eye, (len(near), 3)))
        d = np.linalg.norm(closest - eye, axis=1)
        k = int(np.argmin(d))
        dist[i], kind[i] = float(d[k]), str(kinds[near[k]])
    return dist, kind


def main(argv: list[str] | None = None) -> int:
    """Print the eye's clearance along the tour of each source (see the module docstring)."""
    ap = argparse.ArgumentParser(prog="python -m walkstream.benchmarks.tourclearance")
    ap.add_argument("sources", nargs="+", metavar="SOURCE", help="a seed (generated office, 3 storeys) or an interior file")
    ap.add_argument("--step", type=float, default=0.25, help="seconds of the tour between samples (default 0.25)")
    args = ap.parse_args(argv)
    if not args.step > 0:
        print("error: --step must be above 0 seconds", file=sys.stderr)
        return 2
    print("| source | tour | samples | eye < 0.15 m | eye < 0.25 m | nearest | kinds < 0.15 m |")
    print("|---|---:|---:|---:|---:|---:|---|")
    for source in args.sources:
        try:
            scene, src = _scene(source)
        except (WalkstreamError, OSError) as exc:
            print(f"error: {exc}" if source in str(exc) else f"error: {source}: {exc}", file=sys.stderr)
            return 2
        walk = interior_parts(scene, src).walk
        eyes = walk.sample(np.arange(0.0, walk.duration, args.step))[0]
        dist, kind = eye_clearance(scene, eyes)
        bad = dist < REFUSED_M
        kinds = Counter(k for k, b in zip(kind, bad, strict=True) if b)
        print(f"| {src.name} | {walk.duration:.0f} s | {len(eyes):,} | {int(bad.sum())} | {int((dist < 0.25).sum())} | "
              f"{min(float(dist.min()), _REACH):.3f} m | {', '.join(f'{k} {n}' for k, n in kinds.most_common()) or '-'} |",
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
