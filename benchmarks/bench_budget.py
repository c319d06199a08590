"""Budget controller on the simulated devices: frame rate held, recovery after a cost step.

For ``desktop2003`` at 25 and 40 fps and ``pda`` at 10 fps (on the default scene and on
a light one), runs a synthetic walk (:class:`client.budgetbench.PvsSupply`: a PVS of 50
objects with LODs of about 40 / 400 / 3,000 triangles, ACH allocation) for ``--frames``
frames per seed, once steady and once with a tenfold per-triangle cost step at the
middle frame, and prints one table: share of frames within 10 % of the target
(floor-limited frames left out), floor-limited share, frames to recover after the step,
the worst slowdown after recovery (device spikes left out), budget median/min/max.  The
figures to reach are printed under the table.

Run: ``.venv/bin/python benchmarks/bench_budget.py [--frames 3000] [--seeds 1 2 3]``
"""

from __future__ import annotations

import argparse
import time

from walkstream.client.budgetbench import format_table, run_budget_bench


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=3_000, help="frames per run")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3], help="noise/walk seeds")
    ap.add_argument("--step", type=float, default=10.0, help="per-triangle cost step factor")
    args = ap.parse_args()
    t0 = time.perf_counter()
    rows = run_budget_bench(frames=args.frames, seeds=args.seeds, step_factor=args.step)
    print(format_table(rows))
    print(
        f"{args.frames} frames x {len(args.seeds)} seeds x 2 runs per row, "
        f"step x{args.step:g} at frame {args.frames // 2}; {time.perf_counter() - t0:.1f} s"
    )


if __name__ == "__main__":
    main()
